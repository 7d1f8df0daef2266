//! The field console without a serial port: the socat line of README "Field console" links two
//! pseudo-terminals, fme opens one as `console.device`, the technician the other.

use crate::console_pty::{ask, greeting};
use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::service::{Daemon, RunOptions};
use serialport::SerialPort;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// socat, killed when the test ends however it ends.
struct Socat(Child);
impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The README's command, with the two links in `dir`.
fn socat_pair(dir: &Path) -> Socat {
    let pty = |name: &str| format!("pty,raw,echo=0,perm=0666,link={}", dir.join(name).display());
    let child = Command::new("socat")
        .args([pty("console"), pty("tech")])
        .stdin(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("socat: {e} (make setup installs it)"));
    let s = Socat(child);
    let end = Instant::now() + Duration::from_secs(5);
    while !(dir.join("console").exists() && dir.join("tech").exists()) {
        assert!(Instant::now() < end, "socat made no pty links in {}", dir.display());
        std::thread::sleep(Duration::from_millis(20));
    }
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_answers_through_a_socat_pty_pair() {
    let seq = tempfile::tempdir().expect("tempdir");
    support::write_sequence(seq.path(), 30, 96, 64, 30);
    let links = tempfile::tempdir().expect("tempdir");
    let _socat = socat_pair(links.path());
    let tech_path = links.path().join("tech");
    let mut tech = serialport::new(tech_path.to_string_lossy(), 115_200)
        .timeout(Duration::from_millis(100))
        .open()
        .expect("open the technician's end");

    let mut cfg = support::test_config(seq.path());
    cfg.console.enabled = true;
    cfg.console.device = links.path().join("console").to_string_lossy().into_owned();
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(seq.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, "[source]\nrealtime = true\n".into(), source, pipeline, RunOptions::default())
        .await
        .expect("start");

    let answered = tokio::task::spawn_blocking(move || {
        let port: &mut dyn SerialPort = tech.as_mut();
        let mut acc = String::new();
        greeting(port, &mut acc);
        let v = ask(port, &mut acc, "version");
        assert!(v.contains(env!("CARGO_PKG_VERSION")) && v.ends_with("OK\r\n"), "{v:?}");
        let s = ask(port, &mut acc, "status");
        assert!(s.contains("state running"), "{s:?}");
    })
    .await;
    daemon.shutdown().await;
    answered.expect("console session");
}
