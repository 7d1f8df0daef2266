//! The web server in process (docs/web.md): the JSON API reads the published update and the
//! history, the actions need the token, the pages and the picture are served, and a hostile client
//! (garbage, 10 KB headers, slowloris, a connection flood from one address) leaves a normal request
//! answered. A fake state: no pipeline, no camera.

use fme::history::{HistoryRow, format_row};
use fme::output::{StatusBits, Update};
use fme::status::FaultCode;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

#[path = "common/web_lan.rs"]
mod web_lan;

use web_lan::{connect_from, exchange, start_with_token};

const TOKEN: &str = "test-token-0123456789";

async fn start(token: Option<&str>, tweak: impl FnOnce(&mut fme::config::Config)) -> web_lan::Fixture {
    start_with_token(token, tweak).await.expect("serves")
}

/// `raw` on a new connection from 127.0.0.1, the answer read to the end.
async fn raw(addr: SocketAddr, raw: &[u8]) -> (u16, String, Vec<u8>) {
    let mut s = connect_from("127.0.0.1", addr).await.expect("connect");
    exchange(&mut s, raw).await
}

async fn request(addr: SocketAddr, method: &str, path: &str, auth: Option<&str>) -> (u16, String, Vec<u8>) {
    let auth = auth.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    let text = format!("{method} {path} HTTP/1.1\r\nHost: box\r\n{auth}Content-Length: 0\r\nConnection: close\r\n\r\n");
    raw(addr, text.as_bytes()).await
}

fn json(body: &[u8]) -> serde_json::Value {
    serde_json::from_slice(body).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(body)))
}

#[tokio::test]
async fn status_is_the_published_update_in_words() {
    let f = start(None, |_| {}).await;
    let u = Update {
        unix_ms: 1_700_000_000_000,
        mean_mps: 0.125,
        mean_bls: 0.5,
        smoothed_mps: 0.25,
        ci95_half_mps: f64::NAN,
        fish: 17,
        status: StatusBits::RUNNING | StatusBits::CAMERA_OK | StatusBits::TOO_FEW_FISH,
        fault: FaultCode::None,
        feeding: true,
        camera_fps: 29.5,
        ..Update::default()
    };
    f.bank.publish_update(&u, fme::config::WordOrder::default());
    let backend = fme::infer::Backend::DEFAULT;
    f.shared.with_health(|h| {
        h.networks.detector = Some(fme::pipeline::Network {
            path: "models/fish_det_int8.onnx".into(),
            form: fme::infer::ModelForm::Int8Qdq,
            backend,
        })
    });
    let (code, head, body) = request(f.addr, "GET", "/api/status", None).await;
    assert_eq!(code, 200, "{head}");
    assert!(head.contains("Content-Type: application/json"), "{head}");
    let s = json(&body);
    assert_eq!(s["activity_mps"], 0.125);
    assert_eq!(s["activity_bls"], 0.5);
    assert_eq!(s["smoothed_mps"], 0.25);
    assert!(s["ci95_mps"].is_null(), "NaN is null: {s}");
    assert_eq!(s["fish"], 17);
    assert_eq!(s["feeding"], true);
    assert_eq!(s["status"], "running camera_ok too_few_fish");
    assert_eq!(s["status_bits"]["too_few_fish"], true);
    assert_eq!(s["status_bits"]["stale"], false);
    assert_eq!(s["fault"], "none");
    assert_eq!(s["health"]["camera_fps"], 29.5);
    let det = &s["health"]["networks"]["detector"];
    assert_eq!(det["file"], "models/fish_det_int8.onnx");
    assert_eq!((det["form"].as_str(), det["backend"].as_str()), (Some("int8-qdq"), Some(backend.name())));
    assert!(s["health"]["networks"]["depth"].is_null(), "no depth network: null");
    assert_eq!(s["feeding_thresholds_mps"]["on_above"], 0.3);
    f.server.stop().await;
}

#[tokio::test]
async fn actions_need_the_token_and_do_what_the_console_does() {
    let f = start(Some(TOKEN), |_| {}).await;
    for auth in [None, Some("wrong-token-0123456789"), Some("")] {
        let (code, head, _) = request(f.addr, "POST", "/api/snapshot", auth).await;
        assert_eq!(code, 401, "{auth:?}: {head}");
        assert!(!f.shared.requests.take_snapshot(), "nothing done without the token");
        assert_eq!(request(f.addr, "POST", "/api/record?label=x", auth).await.0, 401);
        assert_eq!(f.shared.requests.take_save(), None);
    }
    assert_eq!(request(f.addr, "GET", "/api/snapshot", Some(TOKEN)).await.0, 405, "an action is a POST");
    assert_eq!(request(f.addr, "POST", "/api/snapshot", Some(TOKEN)).await.0, 202);
    assert!(f.shared.requests.take_snapshot(), "snapshot requested");
    let (code, _, body) = request(f.addr, "POST", "/api/record?label=net", Some(TOKEN)).await;
    assert_eq!(code, 409, "no black box: {}", String::from_utf8_lossy(&body));
    f.shared.with_health(|h| h.record.active = true);
    assert_eq!(request(f.addr, "POST", "/api/record?label=net%20check", Some(TOKEN)).await.0, 202);
    assert_eq!(f.shared.requests.take_save().as_deref(), Some("net check"));
    f.server.stop().await;

    let off = start(None, |_| {}).await;
    assert_eq!(request(off.addr, "POST", "/api/snapshot", Some(TOKEN)).await.0, 403, "no token configured");
    assert!(!off.shared.requests.take_snapshot());
    off.server.stop().await;
}

fn row(unix_ms: i64, v: f64, fish: u32) -> HistoryRow {
    HistoryRow {
        unix_ms,
        activity_mps: v,
        smoothed_mps: v,
        ci95_mps: 0.01,
        n_fish: fish,
        bls: v * 4.0,
        status: 1,
        fault: 0,
        feeding: false,
        scale: Default::default(),
        unlike_fish: false,
    }
}

#[tokio::test]
async fn activity_reads_the_day_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let day = fme::history::day_of(fme::history::now_unix_ms()) - 1;
    let t0 = day * 86_400_000 + 3_600_000;
    let mut text = format!("{}\n", fme::history::HEADER);
    for i in 0..100 {
        format_row(&row(t0 + i * 1000, 0.1 + i as f64 * 0.001, 10), &mut text);
    }
    std::fs::write(fme::history::day_path(dir.path(), day), text).expect("write day file");
    let f = start(None, |_| {}).await;
    f.shared.history.set_dir(dir.path());
    let path = format!("/api/activity?from={}&to={}", t0, t0 + 50_000);
    let (code, _, body) = request(f.addr, "GET", &path, None).await;
    assert_eq!(code, 200);
    let a = json(&body);
    let rows = a["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 50, "[from, to)");
    assert_eq!(rows[0]["t"], t0);
    assert_eq!(rows[0]["fish"], 10);
    assert_eq!(a["feeding_thresholds_mps"]["off_below"], 0.2);
    let thin = json(&request(f.addr, "GET", &format!("{path}&points=5"), None).await.2);
    assert_eq!(thin["rows"].as_array().map(Vec::len), Some(5), "thinned to 5 points");
    let (code, head, csv) = request(f.addr, "GET", &format!("{path}&format=csv"), None).await;
    assert!(code == 200 && head.contains("text/csv"), "{head}");
    assert_eq!(String::from_utf8_lossy(&csv).lines().count(), 51, "header and 50 rows");
    for bad in ["/api/activity?from=yesterday", "/api/activity?from=10&to=5", "/api/activity?format=xml"] {
        assert_eq!(request(f.addr, "GET", bad, None).await.0, 400, "{bad}");
    }
    f.server.stop().await;
}

fn jpeg_frame(w: u32, h: u32) -> fme::pipeline::Frame {
    let img = image::RgbImage::from_pixel(w, h, image::Rgb([40, 80, 120]));
    fme::pipeline::Frame {
        seq: 7,
        timestamp: fme::units::Seconds(1.0),
        arrived: std::time::Instant::now(),
        width: w,
        height: h,
        format: fme::pipeline::PixelFormat::Jpeg,
        data: fme::sequence::encode_jpeg(&img, 90).expect("encode"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pages_and_the_latest_picture_are_served() {
    let f = start(None, |_| {}).await;
    for (path, ctype, needle) in [
        ("/", "text/html", "fme · Live"),
        ("/history", "text/html", "Last 7 days"),
        ("/health", "text/html", "Health"),
        ("/assets/style.css", "text/css", "@media"),
        ("/assets/app.js", "text/javascript", "/api/status"),
    ] {
        let (code, head, body) = request(f.addr, "GET", path, None).await;
        assert!(code == 200 && head.contains(ctype), "{path}: {head}");
        assert!(String::from_utf8_lossy(&body).contains(needle), "{path}");
    }
    assert_eq!(request(f.addr, "GET", "/nothing", None).await.0, 404);
    // A stand-in for the pipeline: hands over a frame whenever one is wanted.
    let shared = f.shared.clone();
    let pipeline = std::thread::spawn(move || {
        for _ in 0..400 {
            shared.preview.offer(|| fme::web::preview::PreviewFrame {
                frame: jpeg_frame(320, 240),
                overlays: Default::default(),
                sample: None,
                jpeg: Default::default(),
            });
            std::thread::sleep(Duration::from_millis(5));
        }
    });
    let (code, head, body) = request(f.addr, "GET", "/api/latest.jpg", None).await;
    assert!(code == 200 && head.contains("image/jpeg"), "{head}");
    let img = image::load_from_memory(&body).expect("a JPEG");
    assert_eq!((img.width(), img.height()), (320, 240));
    let _ = pipeline.join();
    f.server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hostile_client_leaves_a_normal_request_answered() {
    let f = start(None, |c| {
        c.web.max_connections_per_peer = 4;
        c.web.header_timeout_ms = 1000;
    })
    .await;
    let ok = |addr| async move { request(addr, "GET", "/api/status", None).await.0 == 200 };
    // Garbage and a 10 KB head: answered with an error, nothing else.
    assert_eq!(raw(f.addr, b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\xff\r\n\r\n").await.0, 400);
    let mut huge = b"GET /api/status HTTP/1.1\r\nX-Filler: ".to_vec();
    huge.resize(10 * 1024, b'a');
    huge.extend_from_slice(b"\r\n\r\n");
    let (code, _, _) = raw(f.addr, &huge).await;
    assert!(code == 431 || code == 0, "10 KB head: {code}");
    assert!(ok(f.addr).await, "after garbage");
    // A slowloris connection and a flood from one address (more than it may hold).
    let mut slow = connect_from("127.0.0.2", f.addr).await.expect("connect");
    slow.write_all(b"GET /api/status HTTP/1.1\r\nX-Slow: ").await.expect("write");
    let mut flood = Vec::new();
    for _ in 0..20 {
        flood.push(connect_from("127.0.0.3", f.addr).await.expect("connect"));
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert!(ok(f.addr).await, "during the slowloris and the flood");
    let mut b = [0u8; 64];
    let _ = slow.write_all(b"a").await;
    let mut answer = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(3), slow.read_to_end(&mut answer)).await;
    assert!(answer.starts_with(b"HTTP/1.1 408"), "slowloris timed out: {:?}", String::from_utf8_lossy(&answer));
    let refused = flood
        .iter_mut()
        .map(|s| s.try_read(&mut b))
        .filter(|r| match r {
            Ok(n) => *n == 0,
            Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
        })
        .count();
    assert!(refused >= 16, "the flood beyond 4 from one address is closed: {refused}");
    assert!(ok(f.addr).await, "after");
    f.server.stop().await;
}
