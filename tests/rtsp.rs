//! IP cameras against real servers on loopback: GStreamer's RTSP server (tests/rtsp_server.py)
//! serving the bundled recording as H.264 (with or without a Basic or Digest login, or answering and
//! then sending no picture), a listener that never answers, a fake RTSP server that refuses the
//! login, and an MJPEG-over-HTTP camera written here; `fme run` through a server outage
//! (rtsp/daemon_outage.rs).

#[path = "mqtt/broker.rs"]
mod broker;
#[path = "rtsp/daemon_outage.rs"]
mod daemon_outage;
#[path = "rtsp/servers.rs"]
mod servers;
#[path = "daemon/support.rs"]
mod support;

use fme::capture::{CaptureError, Frame, FrameSource, PixelFormat, RecordedSource, RtspSource};
use fme::config::{Config, SourceConfig, SourceKind};
use fme::output::registers::{FaultCode, StatusBits};
use fme::pipeline::{FishPipeline, Pipeline};
use fme::service::{Daemon, RunOptions};
use servers::{GstServer, SilentListener};
use std::path::Path;
use std::time::{Duration, Instant};
use support::wait_until;

const SEQ: &str = "tests/data/swarm20";

fn rtsp_source(url: &str, timeout_ms: u64) -> SourceConfig {
    SourceConfig { kind: SourceKind::Rtsp, url: url.into(), timeout_ms, ..SourceConfig::default() }
}

fn open_err(src: &mut RtspSource) -> String {
    match src.reopen() {
        Ok(()) => panic!("{} opened", src.describe()),
        Err(e) => e.to_string(),
    }
}

/// The activity series of `frames` through the real pipeline (bundled models, the recording's
/// calibration).
fn series(frames: &[Frame]) -> Vec<f64> {
    let mut cfg = Config::default();
    cfg.source.path = SEQ.into();
    cfg.motion.smoothing_s = fme::units::Seconds(2.0);
    let cal = fme::calibration::load(&Path::new(SEQ).join("meta.json")).expect("calibration");
    let mut p = FishPipeline::new(&cfg.pipeline(), Some(cal)).expect("pipeline with the bundled models");
    frames.iter().map(|f| p.process(f).ok().and_then(|o| o.sample).map_or(f64::NAN, |s| s.mean.0)).collect()
}

#[test]
fn rtsp_stream_gives_the_recordings_frames_times_and_activity() {
    let server = GstServer::start(0);
    let mut src = RtspSource::new(rtsp_source(&server.url("/h264"), 5000)).expect("source");
    src.reopen().expect("connect to the RTSP server");
    let streamed: Vec<Frame> = (0..120).map(|_| src.next_frame(Vec::new()).expect("frame")).collect();
    drop(server);
    let f0 = &streamed[0];
    assert_eq!((f0.width, f0.height, f0.format), (640, 384, PixelFormat::I420));
    assert!(src.describe().contains("H.264 640x384"), "{}", src.describe());
    // Frame time is the RTP clock: 1/30 s apart to one 90 kHz tick (arrival times jitter), from 0.
    for (k, f) in streamed.iter().enumerate() {
        assert!((f.timestamp.get() - k as f64 / 30.0).abs() < 1.5 / 90_000.0, "frame {k}: {}", f.timestamp.get());
    }
    let mut rec = RecordedSource::open(Path::new(SEQ), false, false).expect("recording");
    let recorded: Vec<Frame> = std::iter::from_fn(|| rec.next_frame(Vec::new()).ok()).collect();
    // The stream starts at the recording's first frame: its picture matches frame 1 best (limited-range
    // H.264 luma against full-range JPEG luma, and the compression, leave a few grey levels).
    let luma = |f: &Frame| f.to_luma().expect("luma").into_raw();
    let diff =
        |a: &[u8], b: &[u8]| a.iter().zip(b).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>() / a.len() as f64;
    let first = luma(f0);
    let d: Vec<f64> = recorded[..5].iter().map(|r| diff(&first, &luma(r))).collect();
    assert!(d[0] < 8.0 && d[1..].iter().all(|x| *x > d[0]), "mean abs luma difference to frames 1..5: {d:?}");
    // The activity series of the H.264 stream is the recording's (after the 1.5 s the mean needs).
    let (a, b) = (series(&streamed), series(&recorded));
    let pairs: Vec<(f64, f64)> =
        a[45..].iter().zip(&b[45..]).filter(|(x, y)| x.is_finite() && y.is_finite()).map(|(x, y)| (*x, *y)).collect();
    assert!(pairs.len() > 60, "values on most frames: {}", pairs.len());
    let (x, y): (Vec<f64>, Vec<f64>) = pairs.into_iter().unzip();
    let (mx, my) = (x.iter().sum::<f64>() / x.len() as f64, y.iter().sum::<f64>() / y.len() as f64);
    let dc = fme::eval::metrics::distance_correlation(&x, &y).expect("DistCorr");
    eprintln!("stream mean {mx:.4} m/s, recording mean {my:.4} m/s, DistCorr {dc:.3}");
    assert!((mx - my).abs() <= 0.03 * my, "means: stream {mx:.4} vs recording {my:.4} m/s");
    assert!(dc >= 0.95, "DistCorr {dc:.3}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn server_down_is_a_camera_fault_and_the_stream_comes_back() {
    let server = GstServer::start(0);
    let port = server.port;
    let mut cfg = support::test_config(Path::new(SEQ));
    cfg.source =
        SourceConfig { reconnect_min_ms: 100, reconnect_max_ms: 400, ..rtsp_source(&server.url("/h264"), 1000) };
    let mut src = RtspSource::new(cfg.source.clone()).expect("source");
    src.reopen().expect("connect");
    let pipeline = support::edge_pipeline(&cfg);
    let daemon =
        Daemon::start(cfg, String::new(), Box::new(src), pipeline, RunOptions::default()).await.expect("start");
    let (shared, bank) = (daemon.shared().clone(), daemon.bank().clone());
    let camera_ok = |b: &[u16]| b[10] & StatusBits::CAMERA_OK.bits() != 0;
    wait_until("frames over RTSP", 10, || shared.health().frames_captured >= 30 && camera_ok(&bank.block())).await;
    drop(server);
    wait_until("the camera fault", 10, || {
        let b = bank.block();
        !camera_ok(&b) && b[11] == FaultCode::Camera as u16
    })
    .await;
    let hb = bank.block()[12];
    tokio::time::sleep(Duration::from_millis(400)).await;
    assert_ne!(bank.block()[12], hb, "the heartbeat goes on while the camera is down");
    assert!(!shared.health().camera_ok);
    let before = shared.health().frames_captured;
    let _server = GstServer::start(port);
    wait_until("frames again", 15, || shared.health().frames_captured >= before + 30 && camera_ok(&bank.block())).await;
    let h = shared.health();
    assert!(h.reconnects >= 1 && h.capture_errors >= 1, "{} reconnects, {} errors", h.reconnects, h.capture_errors);
    assert_ne!(bank.block()[11], FaultCode::Camera as u16);
    daemon.shutdown().await;
}

#[test]
fn wrong_path_silent_server_wrong_login_and_h265_are_clear_errors() {
    let server = GstServer::start(0);
    let e = open_err(&mut RtspSource::new(rtsp_source(&server.url("/nope"), 3000)).expect("source"));
    assert!(e.contains("404") && e.contains("source.url"), "{e}");
    assert!(
        server.has_h265,
        "x265enc (gstreamer1.0-plugins-bad) is not installed: run `make setup`, which installs it"
    );
    let e = open_err(&mut RtspSource::new(rtsp_source(&server.url("/h265"), 5000)).expect("source"));
    assert!(e.contains("H265") && e.contains("H.264"), "{e}");
    drop(server);
    // A server that accepts the connection and never answers: an error after source.timeout_ms.
    let silent = SilentListener::start(false);
    let t0 = Instant::now();
    let e = open_err(&mut RtspSource::new(rtsp_source(&silent.url(), 300)).expect("source"));
    assert!(e.contains("no answer") && e.contains("source.timeout_ms"), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
    // A server that refuses the login.
    let refusing = SilentListener::start(true);
    let dir = tempfile::tempdir().expect("tempdir");
    let creds = dir.path().join("camera.login");
    std::fs::write(&creds, "admin:hunter2\n").expect("write");
    let cfg = SourceConfig { credentials_file: creds, ..rtsp_source(&refusing.url(), 2000) };
    let e = open_err(&mut RtspSource::new(cfg).expect("source"));
    assert!(e.contains("401") && e.contains("credentials_file") && !e.contains("hunter2"), "{e}");
}

#[test]
fn real_server_basic_and_digest_logins_and_a_wrong_one_named_without_its_password() {
    let dir = tempfile::tempdir().expect("tempdir");
    let login = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("write");
        p
    };
    let (right, wrong) = (login("right", "viewer:s3cret\n"), login("wrong", "admin:hunter2\n"));
    for method in ["basic", "digest"] {
        let server = GstServer::start_with(0, &["--auth", method, "--login", "viewer:s3cret"]);
        let cfg = |creds: &Path| SourceConfig {
            credentials_file: creds.to_path_buf(),
            ..rtsp_source(&server.url("/h264"), 5000)
        };
        let e = open_err(&mut RtspSource::new(cfg(&wrong)).expect("source"));
        let named = e.contains("401") && e.contains("\"admin\"") && e.contains("source.credentials_file");
        assert!(named && !e.contains("hunter2"), "{method}: {e}");
        let e = open_err(&mut RtspSource::new(cfg(Path::new(""))).expect("source"));
        assert!(e.contains("asks for a login") && e.contains("source.credentials_file"), "{method}: {e}");
        let mut src = RtspSource::new(cfg(&right)).expect("source");
        src.reopen().unwrap_or_else(|e| panic!("{method} login refused: {e}"));
        let f = src.next_frame(Vec::new()).unwrap_or_else(|e| panic!("{method}: no picture: {e}"));
        assert_eq!((f.width, f.height, f.format), (640, 384, PixelFormat::I420), "{method}");
    }
}

/// A server that answers DESCRIBE, SETUP and PLAY and then sends no picture: a camera fault after
/// `source.timeout_ms`, tried again with backoff, without a busy loop.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_without_pictures_is_a_camera_fault_not_a_hang() {
    let server = GstServer::start(0);
    let mut cfg = support::test_config(Path::new(SEQ));
    cfg.source =
        SourceConfig { reconnect_min_ms: 200, reconnect_max_ms: 800, ..rtsp_source(&server.url("/stall"), 500) };
    let mut src = RtspSource::new(cfg.source.clone()).expect("source");
    src.reopen().expect("the server answers DESCRIBE, SETUP and PLAY");
    let pipeline = support::edge_pipeline(&cfg);
    let daemon =
        Daemon::start(cfg, String::new(), Box::new(src), pipeline, RunOptions::default()).await.expect("start");
    let (shared, bank) = (daemon.shared().clone(), daemon.bank().clone());
    wait_until("the camera fault", 15, || bank.block()[11] == FaultCode::Camera as u16).await;
    let cpu0 = process_cpu_s();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let cpu = process_cpu_s() - cpu0;
    let h = shared.health();
    assert_eq!(bank.block()[11], FaultCode::Camera as u16);
    daemon.shutdown().await;
    assert_eq!(h.frames_captured, 0);
    assert!(h.capture_errors >= 1 && h.reconnects >= 1, "{} errors, {} reconnects", h.capture_errors, h.reconnects);
    assert!(cpu < 0.5, "{cpu:.2} s of CPU in 3 s while the camera sends nothing");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_camera_is_retried_with_backoff_not_in_a_busy_loop() {
    let silent = SilentListener::start(false);
    let mut cfg = support::test_config(Path::new(SEQ));
    cfg.source = SourceConfig { reconnect_min_ms: 200, reconnect_max_ms: 800, ..rtsp_source(&silent.url(), 300) };
    let src = RtspSource::new(cfg.source.clone()).expect("source");
    let pipeline = support::edge_pipeline(&cfg);
    let cpu0 = process_cpu_s();
    let daemon =
        Daemon::start(cfg, String::new(), Box::new(src), pipeline, RunOptions::default()).await.expect("start");
    let bank = daemon.bank().clone();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let tries = silent.connections();
    let cpu = process_cpu_s() - cpu0;
    assert_eq!(bank.block()[11], FaultCode::Camera as u16);
    daemon.shutdown().await;
    // Each try waits 300 ms for an answer, then 200, 400, 800, 800 ms: about 5 tries in 3 s.
    assert!((2..=8).contains(&tries), "{tries} connection attempts in 3 s");
    assert!(cpu < 0.5, "{cpu:.2} s of CPU in 3 s while the camera is down");
}

/// CPU time (user + system) of this process, s.
fn process_cpu_s() -> f64 {
    // SAFETY: getrusage writes into the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

#[test]
fn mjpeg_camera_frames_arrive_decoded_with_part_timestamps() {
    let jpegs: Vec<Vec<u8>> =
        (1..=4).map(|k| std::fs::read(format!("{SEQ}/img1/{k:06}.jpg")).expect("recorded frame")).collect();
    let camera = servers::MjpegCamera::start(jpegs.clone(), Some("viewer:pw"));
    let dir = tempfile::tempdir().expect("tempdir");
    let creds = dir.path().join("login");
    std::fs::write(&creds, "viewer:pw\n").expect("write");
    let cfg = SourceConfig {
        kind: SourceKind::Mjpeg,
        url: camera.url("/video"),
        credentials_file: creds,
        timeout_ms: 2000,
        ..SourceConfig::default()
    };
    let mut src = fme::capture::MjpegSource::new(cfg.clone());
    src.reopen().expect("connect");
    let frames: Vec<Frame> = (0..4).map(|_| src.next_frame(Vec::new()).expect("frame")).collect();
    for (f, jpeg) in frames.iter().zip(&jpegs) {
        assert_eq!((f.format, f.width, f.height), (PixelFormat::Jpeg, 640, 384));
        assert_eq!(&f.data, jpeg, "frame {} is the JPEG sent", f.seq);
        assert_eq!(f.to_luma().expect("decodes").dimensions(), (640, 384));
    }
    // X-Timestamp headers (100.0, 100.1, ...) are the frame times, from 0.
    let t: Vec<f64> = frames.iter().map(|f| f.timestamp.get()).collect();
    assert!(t.iter().enumerate().all(|(k, t)| (t - 0.1 * k as f64).abs() < 1e-9), "{t:?}");
    // The camera closes after its frames: an error the capture loop reconnects on.
    assert!(matches!(src.next_frame(Vec::new()), Err(CaptureError::Read { .. })));
    // Without the login: a clear 401.
    let mut anon = fme::capture::MjpegSource::new(SourceConfig { credentials_file: "".into(), ..cfg });
    let e = anon.reopen().expect_err("401").to_string();
    assert!(e.contains("401") && e.contains("credentials_file"), "{e}");
}

#[test]
fn snapshot_of_an_rtsp_camera_and_its_error_on_a_wrong_path() {
    let server = GstServer::start(0);
    let out = tempfile::tempdir().expect("tempdir");
    let snapshot = |url: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_fme"))
            .args(["snapshot", "--source", url, "--frames", "10", "--out"])
            .arg(out.path())
            .output()
            .expect("run fme snapshot")
    };
    let ok = snapshot(&server.url("/h264"));
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let jpeg = String::from_utf8_lossy(&ok.stdout).trim().to_string();
    let img = image::open(&jpeg).expect("the snapshot JPEG");
    assert_eq!((img.width(), img.height()), (640, 384));
    let bad = snapshot(&server.url("/nope"));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(2), "{err}");
    assert!(err.contains("404") && err.contains("source.url"), "{err}");
}

#[test]
fn udp_transport_gives_frames_on_the_rtp_clock() {
    let server = GstServer::start(0);
    let cfg = SourceConfig { transport: fme::config::RtspTransport::Udp, ..rtsp_source(&server.url("/h264"), 5000) };
    let mut src = RtspSource::new(cfg).expect("source");
    src.reopen().expect("connect over UDP");
    assert!(src.describe().contains("udp"), "{}", src.describe());
    let t: Vec<f64> = (0..15).map(|_| src.next_frame(Vec::new()).expect("frame").timestamp.get()).collect();
    // Loopback loses nothing: consecutive frames 1/30 s apart on the RTP clock.
    assert!(t.windows(2).all(|w| (w[1] - w[0] - 1.0 / 30.0).abs() < 1.5 / 90_000.0), "{t:?}");
}

#[test]
fn config_check_reads_the_login_file_and_shows_only_its_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let login = dir.path().join("camera.login");
    std::fs::write(&login, "admin:hunter2\n").expect("write");
    let run = |args: &[&str], toml: &str| {
        let cfg = dir.path().join("fme.toml");
        std::fs::write(&cfg, toml).expect("write config");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_fme")).args(args).arg(&cfg).output().expect("fme");
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(!text.contains("hunter2"), "{text}");
        (out.status.code(), text)
    };
    let section = |url: &str, file: &Path| {
        format!("[source]\nkind = \"rtsp\"\nurl = \"{url}\"\ncredentials_file = \"{}\"\n", file.display())
    };
    let (code, text) = run(&["config", "show"], &section("rtsp://cam/live", &login));
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains(&format!("credentials_file = \"{}\"", login.display())), "{text}");
    assert_eq!(run(&["config", "check"], &section("rtsp://cam/live", &login)).0, Some(0));
    let (code, text) = run(&["config", "check"], &section("rtsp://cam/live", &dir.path().join("none")));
    assert!(code == Some(2) && text.contains("source.credentials_file"), "{text}");
    let (code, text) = run(&["config", "check"], &section("rtsp://admin:hunter2@cam/live", &login));
    assert!(code == Some(2) && text.contains("source.url"), "{text}");
}
