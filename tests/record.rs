//! The black box end to end (docs/recording.md): a frozen recording replays to the identical series,
//! and a disk that refuses writes pauses recording while the PLC values keep updating.

use fme::capture::{FrameSource, RecordedSource};
use fme::config::Config;
use fme::output::registers::{StatusBits, decode_f32};
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
/// The daemon on the bundled recording once through with `cfg`, then `record save LABEL`: the
/// recordings in `state` once one appears (30 s at most) and the daemon's health at that time.
async fn run_and_save(
    cfg: Config,
    text: String,
    series: Option<PathBuf>,
    label: &str,
    state: &Path,
) -> (Vec<PathBuf>, fme::status::Health) {
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(Path::new(SEQ), false, false).expect("open"));
    let pipeline = fme::service::build_pipeline(&cfg).expect("real pipeline");
    let opts = RunOptions { max_frames: None, series, ring_writer: None };
    let mut daemon = Daemon::start(cfg, text, source, pipeline, opts).await.expect("start");
    assert!(tokio::time::timeout(Duration::from_secs(120), daemon.finished()).await.expect("ends"));
    daemon.shared().requests.request_save(label);
    let mut found = Vec::new();
    for _ in 0..300 {
        found = recordings(state);
        if !found.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let h = daemon.shared().health();
    daemon.shutdown().await;
    (found, h)
}

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
    let live = tmp.path().join("live.csv");
    let (found, h) = run_and_save(cfg, text, Some(live.clone()), "replay test", &state).await;
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

/// The commissioning path: the daemon runs on a calibration made by `fme calibrate` (the camera and
/// the references; none of the synthetic scene's fields), freezes its black box, and `fme eval`
/// opens the recording as it is: the activity in m/s and BL/s on the references' scale, with the
/// scores it cannot give named; once the boxes are labelled (`gt/gt.txt`), detection and tracking.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_frozen_on_an_fme_calibrate_calibration_opens_in_fme_eval() {
    std::env::set_current_dir(env!("CARGO_MANIFEST_DIR")).expect("cd");
    let tmp = tempfile::tempdir().expect("tempdir");
    let meta_path = Path::new(SEQ).join("meta.json");
    let m = fme::sequence::Meta::read(&meta_path).expect("swarm20 meta.json");
    let cam = m.camera(&meta_path).expect("camera");
    let mut points = String::from("name,x,y,z,u,v\n");
    for r in &m.reference_objects {
        let (w, px) = (r.front_face_center(), cam.world_to_pixel(&r.front_face_center()).expect("in view"));
        points += &format!("cube{},{},{},{},{:.3},{:.3}\n", r.id, w.0.x, w.0.y, w.0.z, px.u, px.v);
    }
    let csv = tmp.path().join("points.csv");
    std::fs::write(&csv, points).expect("points.csv");
    let calib = tmp.path().join("calib.json");
    let out = fme()
        .args(["calibrate", "--frame", "tests/data/swarm20/img1/000001.jpg", "--intrinsics"])
        .arg(&meta_path)
        .arg("--points")
        .arg(&csv)
        .arg("--out")
        .arg(&calib)
        .output()
        .expect("run fme calibrate");
    assert!(out.status.success(), "fme calibrate: {}", String::from_utf8_lossy(&out.stderr));

    let state = tmp.path().join("state");
    let sets: Vec<String> = [
        format!("source.path=\"{SEQ}\""),
        format!("camera.calibration=\"{}\"", calib.display()),
        "source.realtime=false".into(),
        "source.loop=false".into(),
        "output.modbus.mode=\"off\"".into(),
        "service.systemd_notify=false".into(),
        format!("service.state_dir=\"{}\"", state.display()),
        "record.ring_s=1000.0".into(),
    ]
    .into();
    let (cfg, text) = Config::load_with(Some(Path::new("config/fme.toml")), &sets).expect("config");
    let (found, h) = run_and_save(cfg, text, None, "commissioning", &state).await;
    assert_eq!(found.len(), 1, "one recording: {found:?} ({:?})", h.record);
    let rec = &found[0];
    // The recording carries the calibration as `fme calibrate` wrote it.
    let kept = std::fs::read_to_string(rec.join("meta.json")).expect("the recording's meta.json");
    assert_eq!(kept, std::fs::read_to_string(&calib).expect("calib.json"));
    assert!(!kept.contains("\"fps\"") && !kept.contains("\"generator\"") && kept.contains("\"calibrate\""));

    let eval = |args: &[&str]| -> serde_json::Value {
        let out = fme().args(["eval", "--json", "--sequence"]).arg(rec).args(args).output().expect("run fme eval");
        assert!(out.status.success(), "fme eval {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).expect("JSON")
    };
    let j = eval(&["--boxes", "model", "--depth", "model"]);
    assert_eq!(j["scale_source"], "references", "{j}");
    assert!(j["mean_activity_mps"].as_f64().is_some_and(|a| a > 0.0), "{j}");
    assert!(j["mean_activity_bls"].as_f64().is_some_and(|a| a > 0.0), "{j}");
    let absent = j["absent"].to_string();
    assert!(absent.contains("gt/gt.txt") && absent.contains("gt/world.csv"), "{absent}");
    assert!(j["detection"].is_null() && j["mota"].is_null(), "{j}");
    // Boxes labelled afterwards (MOTChallenge gt.txt): detection and tracking are scored too.
    std::fs::create_dir_all(rec.join("gt")).expect("gt/");
    std::fs::copy(Path::new(SEQ).join("gt/gt.txt"), rec.join("gt/gt.txt")).expect("label the boxes");
    let j = eval(&["--boxes", "model", "--depth", "model"]);
    assert!(j["detection"]["recall"].as_f64().is_some_and(|r| r > 0.9), "{j}");
    assert!(j["mota"].as_f64().is_some_and(|m| m > 0.8), "{j}");
    assert!(j["depth_consistency"].as_f64().is_some(), "{j}");
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
    assert_ne!(bits & StatusBits::RECORD_FAULT.bits(), 0, "status bit 7: {bits:#06x}\n{log}");
    assert_ne!(bits & StatusBits::CAMERA_OK.bits(), 0, "status {bits:#06x}");
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
