//! A Mosquitto on a free loopback port for the benchmarks (`make setup` installs it), killed on drop.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn mosquitto(bench: &str) -> PathBuf {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join("mosquitto"))
        .chain(["/usr/sbin", "/usr/local/sbin", "/usr/bin"].map(|d| Path::new(d).join("mosquitto")))
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            eprintln!("{bench}: mosquitto not found on PATH or in /usr/sbin: run `make setup`");
            std::process::exit(2)
        })
}

/// The running broker.
pub struct Broker {
    pub child: Child,
    pub port: u16,
    _dir: tempfile::TempDir,
}

impl Broker {
    /// Starts it and waits (up to 10 s) until it accepts connections; `bench` names the caller in errors.
    pub fn start(bench: &str) -> Broker {
        let dir = tempfile::tempdir().expect("tempdir");
        let port =
            std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("port");
        let conf = dir.path().join("mosquitto.conf");
        std::fs::write(&conf, format!("listener {port} 127.0.0.1\nallow_anonymous true\nuser root\n")).expect("conf");
        let child = Command::new(mosquitto(bench))
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto");
        let end = Instant::now() + Duration::from_secs(10);
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(Instant::now() < end, "mosquitto did not start");
            std::thread::sleep(Duration::from_millis(20));
        }
        Broker { child, port, _dir: dir }
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
