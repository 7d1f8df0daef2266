//! `fme run` as a process: bad configuration exits with code 2 naming the key and line; a missing
//! recording is a clear error; an absent camera is reported and retried (the daemon keeps running);
//! SIGTERM stops it within 2 s.

#[path = "daemon_support.rs"]
mod support;

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn fme() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fme"));
    c.env_remove("NOTIFY_SOCKET").env_remove("WATCHDOG_USEC").env("RUST_LOG", "info");
    c
}

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write config");
    p
}

#[test]
fn bad_config_exit_code_2_names_key_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        ("[source]\nfps = 30\n[output]\nrate_hz = 0.0\n", "output.rate_hz", ":4:"),
        ("[source]\nwidht = 640\n", "source.widht", ":2:"),
        ("\n\n[output.modbus]\nmode = \"tcp\"\n", "output.modbus.mode", ":4:"),
        ("[feeding]\non_above_mps = 0.1\noff_below_mps = 0.5\n", "feeding.off_below_mps", ":3:"),
        ("[source\npath = 1\n", "", ":1:"),
    ];
    for (text, key, line) in cases {
        let cfg = write(dir.path(), "bad.toml", text);
        let out = fme().args(["run", "--config"]).arg(&cfg).output().expect("run fme");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text:?} -> {err}");
        assert!(err.contains(key), "{text:?}: message must name `{key}`: {err}");
        assert!(err.contains(&format!("bad.toml{line}")), "{text:?}: message must give the line {line}: {err}");
    }
    let out = fme().args(["run", "--config", "/nonexistent/fme.toml"]).output().expect("run fme");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/fme.toml"));
    let ok = write(dir.path(), "ok.toml", "");
    let out = fme().args(["run", "--config"]).arg(&ok).args(["--modbus-listen", "localhost"]).output().expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--modbus-listen"));
}

#[test]
fn missing_recording_is_a_clear_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = write(dir.path(), "ok.toml", "[output.modbus]\nmode = \"off\"\n");
    let out = fme().args(["run", "--config"]).arg(&cfg).args(["--source", "/nonexistent/seq"]).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("/nonexistent/seq") && err.contains("not found"), "{err}");
}

/// Runs `fme run` for `run_for`, sends SIGTERM, returns (exit status, stderr, ms from SIGTERM to exit).
fn run_then_term(args: &[&str], run_for: Duration) -> (Option<i32>, String, u128) {
    let mut child = fme().args(args).stderr(Stdio::piped()).stdout(Stdio::null()).spawn().expect("spawn");
    std::thread::sleep(run_for);
    let t0 = Instant::now();
    let st = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert!(st.success());
    let end = Instant::now() + Duration::from_secs(5);
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if Instant::now() > end {
            let _ = child.kill();
            panic!("fme did not exit within 5 s of SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let ms = t0.elapsed().as_millis();
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    (status.code(), err, ms)
}

#[test]
fn absent_camera_is_reported_and_retried_then_sigterm() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = write(
        dir.path(),
        "cam.toml",
        "[source]\npath = \"/dev/video-fme-absent\"\nreconnect_min_ms = 100\nreconnect_max_ms = 200\n[output.modbus]\nlisten = \"127.0.0.1:0\"\n",
    );
    let cfg = cfg.to_string_lossy().to_string();
    let (code, err, ms) = run_then_term(&["run", "--config", &cfg], Duration::from_millis(1200));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("/dev/video-fme-absent") && err.contains("not found"), "{err}");
    assert!(err.matches("camera reconnect failed").count() >= 2, "retried with backoff: {err}");
    assert!(ms < 2000, "shutdown took {ms} ms");
}

#[test]
fn recording_run_stops_cleanly_on_sigterm() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 20, 96, 64, 30);
    let cfg = write(dir.path(), "run.toml", "[output.modbus]\nlisten = \"127.0.0.1:0\"\n");
    let (cfg, seq) = (cfg.to_string_lossy().to_string(), dir.path().to_string_lossy().to_string());
    let (code, err, ms) = run_then_term(&["run", "--config", &cfg, "--source", &seq], Duration::from_millis(1500));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("SIGTERM: shutting down"), "{err}");
    assert!(err.contains("frames captured"), "summary printed: {err}");
    assert!(ms < 2000, "shutdown took {ms} ms");
}

/// systemd notify protocol without systemd: a datagram socket stands in for NOTIFY_SOCKET.
#[test]
fn systemd_ready_watchdog_and_stopping() {
    use std::os::unix::net::UnixDatagram;
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 10, 64, 48, 30);
    let sock_path = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind notify socket");
    sock.set_read_timeout(Some(Duration::from_millis(100))).expect("timeout");
    let cfg = write(dir.path(), "run.toml", "[output.modbus]\nlisten = \"127.0.0.1:0\"\n");
    let mut child = fme()
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--source")
        .arg(dir.path().join("seq"))
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", "400000")
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let mut msgs = Vec::new();
    let mut buf = [0u8; 512];
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(1500) {
        if let Ok(n) = sock.recv(&mut buf) {
            msgs.push(String::from_utf8_lossy(&buf[..n]).to_string());
        }
    }
    let st = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert!(st.success());
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        if let Ok(n) = sock.recv(&mut buf) {
            msgs.push(String::from_utf8_lossy(&buf[..n]).to_string());
        }
        if child.try_wait().expect("wait").is_some() {
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    while let Ok(n) = sock.recv(&mut buf) {
        msgs.push(String::from_utf8_lossy(&buf[..n]).to_string());
    }
    let all = msgs.join("|");
    assert!(all.contains("READY=1"), "{all}");
    // WATCHDOG_USEC = 0.4 s -> a ping every 0.2 s from the frame loop: at least 4 in 1.5 s.
    assert!(all.matches("WATCHDOG=1").count() >= 4, "{all}");
    assert!(all.contains("STOPPING=1"), "{all}");
}

#[test]
fn missing_model_or_onnx_runtime_is_named_at_start() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 5, 64, 48, 30);
    let seq = dir.path().join("seq");
    let cfg = write(
        dir.path(),
        "run.toml",
        "[detector]\nmodel = \"/nonexistent/fish-det.onnx\"\n[output.modbus]\nlisten = \"127.0.0.1:0\"\n",
    );
    let out = fme().args(["run", "--config"]).arg(&cfg).arg("--source").arg(&seq).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("detector.model") && err.contains("/nonexistent/fish-det.onnx"), "{err}");
    let ok = write(dir.path(), "ok.toml", "[output.modbus]\nlisten = \"127.0.0.1:0\"\n");
    let out = fme()
        .args(["run", "--config"])
        .arg(&ok)
        .arg("--source")
        .arg(&seq)
        .env("ORT_DYLIB_PATH", "/nonexistent/ort/libonnxruntime.so")
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("ONNX Runtime") && err.contains("/nonexistent/ort/libonnxruntime.so"), "{err}");
}
