//! The black box end to end (docs/recording.md): a frozen recording replays to the identical series,
//! and a disk that refuses writes pauses recording while the PLC values keep updating.

use fme::capture::{FrameSource, RecordedSource};
use fme::config::Config;
use fme::output::registers::{decode_f32, status};
use fme::service::{Daemon, RunOptions};
use std::path::{Path, PathBuf};
use std::time::Duration;

const SEQ: &str = "tests/data/swarm20";

fn fme() -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_fme"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

fn recordings(state: &Path) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(state.join("recordings")) else { return Vec::new() };
    rd.flatten()
        .map(|e| e.path())
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')))
        .collect()
}

/// The whole bundled recording goes through the daemon with the black box on; `record save` (the
/// console's mailbox) freezes it; `fme run` on the frozen recording gives the recorded series row
/// for row, and the recorded series is the one the live run wrote with `--series`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frozen_recording_replays_to_the_recorded_series() {
    std::env::set_current_dir(env!("CARGO_MANIFEST_DIR")).expect("cd");
    let tmp = tempfile::tempdir().expect("tempdir");
    let state = tmp.path().join("state");
    let sets: Vec<String> = [
        format!("source.path=\"{SEQ}\""),
        "source.realtime=false".into(),
        "source.loop=false".into(),
        "output.modbus.mode=\"off\"".into(),
        "service.systemd_notify=false".into(),
        format!("service.state_dir=\"{}\"", state.display()),
        "record.ring_s=1000.0".into(),
        "record.snapshot_every_s=1.0".into(),
        "record.keep_snapshots=2".into(),
    ]
    .into();
    let (cfg, text) = Config::load_with(Some(Path::new("config/fme.toml")), &sets).expect("config");
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(Path::new(SEQ), false, false).expect("open"));
    let pipeline = fme::service::build_pipeline(&cfg).expect("real pipeline");
    let live = tmp.path().join("live.csv");
    let opts = RunOptions { max_frames: None, series: Some(live.clone()) };
    let mut daemon = Daemon::start(cfg, text, source, pipeline, opts).await.expect("start");
    assert!(tokio::time::timeout(Duration::from_secs(120), daemon.finished()).await.expect("ends"));
    daemon.shared().requests.request_save("replay test");
    let mut found = Vec::new();
    for _ in 0..300 {
        found = recordings(&state);
        if !found.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let h = daemon.shared().health();
    daemon.shutdown().await;
    assert_eq!(found.len(), 1, "one recording: {found:?} ({:?})", h.record);
    let rec = &found[0];
    assert!(rec.file_name().is_some_and(|n| n.to_string_lossy().ends_with("-replay-test")), "{rec:?}");
    assert_eq!((h.record.frames_written, h.record.frames_dropped), (120, 0), "{:?}", h.record);
    for f in ["seqinfo.ini", "img1/000001.jpg", "img1/000120.jpg", "det/det.txt", "tracks.txt", "meta.json", "fme.toml"]
    {
        assert!(rec.join(f).is_file(), "{f} missing in {}", rec.display());
    }
    assert!(!rec.join("img1/000121.jpg").exists());
    // A snapshot every second of frame time over 4 s, the newest 2 kept: a JPEG and a depth PNG each.
    assert!(h.record.snapshots >= 3, "{:?}", h.record);
    let mut snaps: Vec<String> = std::fs::read_dir(state.join("snapshots"))
        .expect("snapshots")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    snaps.sort();
    assert_eq!(snaps.len(), 4, "{snaps:?}");
    assert!(snaps[0].ends_with("-depth.png") && snaps[1].ends_with(".jpg"), "{snaps:?}");
    let recorded = std::fs::read_to_string(rec.join("series.csv")).expect("recorded series");
    assert_eq!(recorded, std::fs::read_to_string(&live).expect("live series"), "recorded = live --series");

    let out_csv = tmp.path().join("out.csv");
    let out = fme()
        .args(["run", "--source"])
        .arg(rec)
        .args(["--fast", "--no-loop", "--set", "output.modbus.mode=off", "--series"])
        .arg(&out_csv)
        .output()
        .expect("run fme run");
    assert!(out.status.success(), "fme run: {}", String::from_utf8_lossy(&out.stderr));
    let replay = std::fs::read_to_string(&out_csv).expect("replayed series");
    assert_eq!(recorded.lines().count(), 121, "a header and one row per frame");
    for (a, b) in recorded.lines().zip(replay.lines()) {
        assert_eq!(a, b, "the replay differs from the recorded series");
    }
    assert_eq!(recorded.lines().count(), replay.lines().count());
}

/// `fme run` in a child process whose files may not grow past 4 kB (RLIMIT_FSIZE, SIGXFSZ ignored:
/// every ring frame write fails with EFBIG, like a full disk): the PLC still sees the heartbeat
/// and the activity update, status bit 7 (recording fault) is set, and the error is logged once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn disk_full_pauses_recording_and_the_plc_values_keep_updating() {
    use std::os::unix::process::CommandExt as _;
    use tokio_modbus::prelude::*;
    let tmp = tempfile::tempdir().expect("tempdir");
    let port = std::net::TcpListener::bind("127.0.0.1:0").expect("bind").local_addr().expect("addr").port();
    let listen = format!("127.0.0.1:{port}");
    let mut cmd = fme();
    cmd.args(["run", "--source", SEQ, "--modbus-listen", &listen, "--set", "output.rate_hz=10.0"])
        .args(["--set", "service.systemd_notify=false", "--set"])
        .arg(format!("service.state_dir={}", tmp.path().display()))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    // SAFETY: only async-signal-safe calls (setrlimit, signal) between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit { rlim_cur: 4096, rlim_max: 4096 };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            Ok(())
        });
    }
    let child = cmd.spawn().expect("spawn fme run");
    let mut plc = None;
    for _ in 0..100 {
        if let Ok(c) = tcp::connect_slave(listen.parse().expect("addr"), Slave(1)).await {
            plc = Some(c);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let mut plc = plc.expect("fme serves Modbus");
    let (mut beats, mut means, mut bits) = (Vec::new(), Vec::new(), 0u16);
    for _ in 0..40 {
        tokio::time::sleep(Duration::from_millis(100)).await;
        let r = plc.read_input_registers(0, 24).await.expect("transport").expect("exception");
        beats.push(r[12]);
        let m = decode_f32([r[0], r[1]], fme::config::WordOrder::HighFirst);
        if m.is_finite() {
            means.push(m);
        }
        bits = r[10];
    }
    // SAFETY: plain kill(2) of our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = tokio::task::spawn_blocking(move || child.wait_with_output()).await.expect("join").expect("wait");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(beats.last() > beats.first() && beats.windows(2).all(|w| w[1] >= w[0]), "heartbeat {beats:?}");
    assert!(means.len() >= 10 && means.windows(2).any(|w| w[0] != w[1]), "activity updates: {means:?}");
    assert_ne!(bits & status::RECORD_FAULT, 0, "status bit 7: {bits:#06x}\n{log}");
    assert_ne!(bits & status::CAMERA_OK, 0, "status {bits:#06x}");
    assert_eq!(log.matches("recording paused").count(), 1, "logged once:\n{log}");
    assert!(out.status.success(), "clean exit on SIGTERM: {:?}\n{log}", out.status);
}

/// `fme snapshot` writes the overlay JPEG and the depth PNG once; without a folder it exits 2.
#[test]
fn fme_snapshot_writes_the_frame_and_the_depth_map() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = fme()
        .args(["snapshot", "--source", SEQ, "--frames", "60", "--out"])
        .arg(tmp.path())
        .output()
        .expect("run fme snapshot");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let jpg = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    assert!(jpg.starts_with(tmp.path()) && jpg.extension().is_some_and(|x| x == "jpg"), "{jpg:?}");
    let img = image::open(&jpg).expect("jpeg");
    assert_eq!((img.width(), img.height()), (640, 384));
    let png = PathBuf::from(jpg.to_string_lossy().replace(".jpg", "-depth.png"));
    let depth = image::open(&png).expect("depth png").to_rgb8();
    assert!(depth.pixels().any(|p| p.0[0] > 200) && depth.pixels().any(|p| p.0[2] > 200), "near and far");
    let out = fme().args(["snapshot", "--source", SEQ]).output().expect("run fme snapshot");
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("service.state_dir"));
}
