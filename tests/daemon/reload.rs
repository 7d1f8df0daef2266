//! Apply-on-reload: `fme run` on the bundled recording with an old calibration (the true one's
//! camera moved 0.3 m); a bad file written over it and SIGHUP are refused (logged, the old one
//! keeps running); the true file and SIGHUP are applied: `/api/calibration` shows the new camera.

use crate::support::{Running, free_port, get_json};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const META: &str = "tests/data/swarm20/meta.json";

/// The x of the camera centre the daemon uses, and how many calibrations it has taken.
fn in_use(port: u16) -> Option<(f64, u64)> {
    let c = get_json(port, "/api/calibration")?;
    Some((c["camera"]["center_w"][0].as_f64()?, c["applied"].as_u64()?))
}

fn wait_for(what: &str, secs: u64, mut f: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs(secs);
    while !f() {
        assert!(Instant::now() < end, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn hup(child: &std::process::Child) {
    let st = Command::new("kill").args(["-HUP", &child.id().to_string()]).status().expect("kill");
    assert!(st.success());
}

fn log_of(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("fme.log")).unwrap_or_default()
}

#[test]
fn sighup_applies_a_new_calibration_and_refuses_a_bad_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(META).expect("meta.json")).expect("json");
    let true_x = -truth["camera"]["world_to_camera"]["translation"][0].as_f64().expect("tx");
    // Moving the camera 0.3 m along world x (rotation about x only: x stays x) lowers t_x by 0.3.
    let mut old = truth.clone();
    old["camera"]["world_to_camera"]["translation"][0] = Value::from(-true_x - 0.3);
    let calib = dir.path().join("calib.json");
    std::fs::write(&calib, old.to_string()).expect("write the old calibration");
    let web = free_port();
    let log = std::fs::File::create(dir.path().join("fme.log")).expect("log file");
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env("STATE_DIRECTORY", dir.path())
        .args(["run", "--source", "tests/data/swarm20", "--modbus-listen", &format!("127.0.0.1:{}", free_port())])
        .args(["--set", &format!("web.listen=\"127.0.0.1:{web}\"")])
        .args(["--set", &format!("camera.calibration=\"{}\"", calib.display())])
        .args(["--set", "record.enabled=false"])
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("spawn fme run");
    let child = Running(child);
    let mut now = None;
    wait_for("the web page", 30, || {
        now = in_use(web);
        now.is_some()
    });
    let (x0, taken0) = now.expect("in use");
    assert!((x0 - (true_x + 0.3)).abs() < 1e-6, "the old calibration at start: camera x {x0}, want {}", true_x + 0.3);

    std::fs::write(&calib, "{\"camera\": 3}").expect("write a bad file");
    hup(&child.0);
    wait_for("the refusal in the log", 10, || log_of(dir.path()).contains("calibration refused"));
    let l = log_of(dir.path());
    assert!(l.contains("calib.json") && l.contains("the calibration in use is kept"), "{l}");
    assert_eq!(in_use(web).map(|c| c.0), Some(x0), "a bad file must leave the calibration in use");

    std::fs::write(&calib, truth.to_string()).expect("write the true calibration");
    hup(&child.0);
    wait_for("the new calibration in use", 10, || in_use(web).is_some_and(|(_, n)| n > taken0));
    let (x1, _) = in_use(web).expect("in use");
    assert!((x1 - true_x).abs() < 1e-6, "after SIGHUP: camera x {x1}, want the new file's {true_x}");
    assert!(log_of(dir.path()).contains("applied (10 reference objects)"), "{}", log_of(dir.path()));
    assert!(child.0.id() > 0);
}
