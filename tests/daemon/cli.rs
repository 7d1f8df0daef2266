//! `fme run` as a process: bad configuration exits with code 2 naming the key and line; a missing
//! recording is a clear error; an absent camera is reported and retried (the daemon keeps running);
//! SIGTERM stops it within 2 s.

use crate::support::{self, free_port};

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn fme() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fme"));
    c.env_remove("NOTIFY_SOCKET").env_remove("WATCHDOG_USEC").env("RUST_LOG", "info");
    c
}

/// The bundled recording's calibration with only its first `keep` reference objects, written to `dir/name`.
fn calibration_with_refs(dir: &std::path::Path, name: &str, keep: usize) -> std::path::PathBuf {
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string("tests/data/swarm20/meta.json").expect("meta")).expect("json");
    let refs = meta["reference_objects"].as_array().map(|a| a[..keep].to_vec()).unwrap_or_default();
    meta["reference_objects"] = serde_json::Value::Array(refs);
    write(dir, name, &meta.to_string())
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
    assert_eq!(out.status.code(), Some(2), "a missing model is a start-up (usage) error: {err}");
    assert!(err.contains("detector.model") && err.contains("/nonexistent/fish-det.onnx"), "{err}");
    if !cfg!(feature = "ort") {
        return; // tract: no library to miss.
    }
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
    assert_eq!(out.status.code(), Some(2), "a missing ONNX Runtime is a start-up error: {err}");
    assert!(err.contains("ONNX Runtime") && err.contains("/nonexistent/ort/libonnxruntime.so"), "{err}");
}

/// `fme --version` names the inference backend and whether the models are inside the executable.
#[test]
fn version_names_the_backend() {
    let out = fme().arg("--version").output().expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert_eq!(text.trim(), format!("fme {}", fme::infer::backend::VERSION));
    #[cfg(all(feature = "ort", not(feature = "embed-models")))]
    assert_eq!(
        text.trim(),
        format!("fme {} (backend onnxruntime, default models int8-qdq)", env!("CARGO_PKG_VERSION"))
    );
}

/// One FC04 read of the heartbeat (register 12) over raw Modbus TCP; `None` if not served.
fn heartbeat(port: u16) -> Option<u16> {
    use std::io::Write as _;
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(2))).ok()?;
    s.write_all(&[0, 7, 0, 0, 0, 6, 1, 4, 0, 12, 0, 1]).ok()?;
    let mut ans = [0u8; 11];
    s.read_exact(&mut ans).ok()?;
    (ans[7] == 4).then(|| u16::from_be_bytes([ans[9], ans[10]]))
}

fn wait_exit(child: &mut std::process::Child, within: Duration) -> Option<std::process::ExitStatus> {
    let end = Instant::now() + within;
    while Instant::now() < end {
        if let Ok(Some(s)) = child.try_wait() {
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

fn stderr_of(child: &mut std::process::Child) -> String {
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    err
}

fn spawn_recording(dir: &std::path::Path, port: u16) -> std::process::Child {
    support::write_sequence(&dir.join("seq"), 20, 64, 48, 30);
    let cfg = write(dir, "run.toml", "[output]\nrate_hz = 10.0\n");
    fme()
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--source")
        .arg(dir.join("seq"))
        .args(["--modbus-listen", &format!("127.0.0.1:{port}")])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn")
}

fn served(port: u16) -> Option<u16> {
    let end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < end {
        if let Some(hb) = heartbeat(port) {
            return Some(hb);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    None
}

#[test]
fn sighup_keeps_the_daemon_serving() {
    let dir = tempfile::tempdir().expect("tempdir");
    let port = free_port();
    let mut child = spawn_recording(dir.path(), port);
    let before = served(port);
    assert!(before.is_some(), "daemon never served Modbus");
    let st = Command::new("kill").args(["-HUP", &child.id().to_string()]).status().expect("kill");
    assert!(st.success());
    std::thread::sleep(Duration::from_millis(500));
    assert!(child.try_wait().expect("wait").is_none(), "SIGHUP must not stop fme");
    let after = heartbeat(port);
    assert!(after.is_some() && after != before, "still serving, heartbeat moving: {before:?} -> {after:?}");
    let st = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert!(st.success());
    let status = wait_exit(&mut child, Duration::from_secs(5));
    let err = stderr_of(&mut child);
    assert_eq!(status.and_then(|s| s.code()), Some(0), "{err}");
    assert!(err.contains("SIGHUP: not stopping"), "{err}");
}

#[test]
fn unexpected_signals_stop_cleanly_with_a_failure_exit_code() {
    for sig in ["USR1", "USR2", "QUIT"] {
        let dir = tempfile::tempdir().expect("tempdir");
        let port = free_port();
        let mut child = spawn_recording(dir.path(), port);
        assert!(served(port).is_some(), "daemon never served Modbus");
        let st = Command::new("kill").args([&format!("-{sig}"), &child.id().to_string()]).status().expect("kill");
        assert!(st.success());
        let status = wait_exit(&mut child, Duration::from_secs(5));
        let err = stderr_of(&mut child);
        assert_eq!(status.and_then(|s| s.code()), Some(1), "SIG{sig}: exit 1 so systemd restarts fme: {err}");
        assert!(err.contains(&format!("SIG{sig}: shutting down")), "{err}");
        assert!(err.contains("stopped in") && err.contains("frames captured"), "the SIGTERM way: {err}");
    }
}

#[test]
fn each_broken_startup_input_exits_2_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let seq = dir.path().join("seq");
    support::write_sequence(&seq, 5, 64, 48, 30);
    let one_ref = calibration_with_refs(dir.path(), "one-ref.json", 1);
    let no_ref = calibration_with_refs(dir.path(), "no-ref.json", 0);
    let corrupt = write(dir.path(), "corrupt.onnx", "not an onnx model");
    let no_ini = dir.path().join("no-ini");
    std::fs::create_dir_all(no_ini.join("img1")).expect("mkdir");
    let l = "[output.modbus]\nlisten = \"127.0.0.1:0\"\n";
    let refs_only = "[depth]\nscale = \"references\"\n";
    let cases: Vec<(String, Option<&std::path::Path>, String)> = vec![
        // Too few references is an error where they are the only ruler (`auto` takes the fish).
        (
            format!("[camera]\ncalibration = \"{}\"\n{refs_only}{l}", one_ref.display()),
            None,
            one_ref.display().to_string(),
        ),
        (
            format!("[camera]\ncalibration = \"{}\"\n{refs_only}{l}", no_ref.display()),
            None,
            no_ref.display().to_string(),
        ),
        (format!("[camera]\ncalibration = \"/nonexistent/calib.json\"\n{l}"), None, "/nonexistent/calib.json".into()),
        (format!("[detector]\nmodel = \"{}\"\n{l}", corrupt.display()), None, corrupt.display().to_string()),
        (format!("[detector]\nmodel = \"/nonexistent/det.onnx\"\n{l}"), None, "/nonexistent/det.onnx".into()),
        (format!("[detector]\nmodel = \"\"\n{l}"), None, "detector.model".into()),
        (l.to_string(), Some(no_ini.as_path()), no_ini.join("seqinfo.ini").display().to_string()),
        ("[output.modbus]\nlisten = \"256.256.256.256:502\"\n".into(), None, "output.modbus.listen".into()),
        ("[sourcee]\nwidth = 1\n".into(), None, "key `sourcee`".into()),
    ];
    for (text, source, named) in cases {
        let cfg = write(dir.path(), "bad.toml", &text);
        let out = fme()
            .args(["run", "--config"])
            .arg(&cfg)
            .arg("--source")
            .arg(source.unwrap_or(&seq))
            .output()
            .expect("run fme");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text:?} -> {err}");
        assert!(err.contains(&named), "{text:?}: the message must name {named}: {err}");
        assert!(!err.contains("target/") && !err.contains("sourcee.sourcee"), "{text:?}: {err}");
    }
}

#[test]
fn port_in_use_is_a_runtime_fault_reported_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 5, 64, 48, 30);
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let cfg = write(dir.path(), "run.toml", &format!("[output.modbus]\nlisten = \"127.0.0.1:{port}\"\n"));
    let out =
        fme().args(["run", "--config"]).arg(&cfg).arg("--source").arg(dir.path().join("seq")).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.matches("in use").count(), 1, "printed once: {err}");
    assert!(err.contains("output.modbus.listen"), "{err}");
    assert!(err.contains("--modbus-listen 127.0.0.1:0") && err.contains("output.modbus.mode=off"), "a hint: {err}");
}

#[test]
fn one_reference_says_the_fish_set_the_scale() {
    let dir = tempfile::tempdir().expect("tempdir");
    let seq = dir.path().join("seq");
    support::write_sequence(&seq, 5, 64, 48, 30);
    let one_ref = calibration_with_refs(dir.path(), "one-ref.json", 1);
    let cfg = write(
        dir.path(),
        "run.toml",
        &format!("[camera]\ncalibration = \"{}\"\n[output.modbus]\nmode = \"off\"\n", one_ref.display()),
    );
    let out = fme()
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--source")
        .arg(&seq)
        .args(["--fast", "--no-loop"])
        .output()
        .expect("run fme");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("WARN") && err.contains("1 reference object(s)") && err.contains("the fish set the scale"),
        "{err}"
    );
}

#[test]
fn a_flag_does_not_hide_a_bad_file_value() {
    // `config check` refuses the file; `fme run` with the same file must too, whatever the flags replace.
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = write(dir.path(), "bad.toml", "[output.modbus]\nmode = \"udp\"\n");
    let check = fme().args(["config", "check"]).arg(&cfg).output().expect("run fme");
    assert_eq!(check.status.code(), Some(2));
    let out = fme()
        .args(["run", "--config"])
        .arg(&cfg)
        .args(["--modbus-listen", "127.0.0.1:0", "--source", "/nonexistent/seq"])
        .output()
        .expect("run fme");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("output.modbus.mode") && err.contains("bad.toml:2:"), "{err}");
}

#[test]
fn a_replay_needs_no_privileged_port() {
    // The built-in default serves this box only, on an unprivileged port (boards/*.toml set 502).
    let out = fme().args(["config", "show", "--set", "source.path=/dev/video1"]).output().expect("run fme");
    let shown = String::from_utf8_lossy(&out.stdout);
    let listen = shown.lines().find(|l| l.starts_with("listen = \"1")).unwrap_or_default();
    assert_eq!(listen, "listen = \"127.0.0.1:5020\"", "{shown}");
    for board in ["raspberry-pi-5", "jetson-orin-nano", "rk3588", "x86-64"] {
        let text = std::fs::read_to_string(format!("boards/{board}.toml")).expect("board config");
        assert!(text.contains("listen = \"0.0.0.0:502\""), "{board} must serve the PLC on 502");
    }
}
