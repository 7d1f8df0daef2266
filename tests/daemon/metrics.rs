//! The Prometheus endpoint (`[output.metrics]`, `docs/metrics.md`) of a real `fme run` on the bundled
//! recording: the exposition parses with a strict parser of the text format (and as `curl` fetches
//! it, when curl is installed), has the documented families and types, its counters grow between
//! scrapes, its histogram is cumulative with `+Inf` = `_count`, fish are counted; wrong paths,
//! methods, oversized, garbage and unfinished requests get their error status, extra connections
//! are refused, and the daemon keeps serving throughout. A port already taken is logged and shown,
//! and the daemon runs on.

use crate::support::{self, Running, free_port};

use fme::capture::{FrameSource, RecordedSource};
use fme::service::{Daemon, RunOptions};
use openmetrics_parser::{MetricFamily, PrometheusType, PrometheusValue};
use std::collections::HashMap;
use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

type Families = HashMap<String, MetricFamily<PrometheusType, PrometheusValue>>;

/// One request on a fresh connection: (status code, head, body). A closed or reset connection
/// before any answer is `Err`.
fn http(port: u16, request: &[u8]) -> std::io::Result<(u16, String, String)> {
    let mut s = TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    s.write_all(request)?;
    let mut raw = Vec::new();
    s.read_to_end(&mut raw)?;
    parse_response(&raw)
}

fn parse_response(raw: &[u8]) -> std::io::Result<(u16, String, String)> {
    let text = String::from_utf8_lossy(raw);
    let bad = || std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not an HTTP answer: {text:?}"));
    let (head, body) = text.split_once("\r\n\r\n").ok_or_else(bad)?;
    let code = head.strip_prefix("HTTP/1.1 ").and_then(|r| r.get(..3)).and_then(|c| c.parse().ok()).ok_or_else(bad)?;
    Ok((code, head.to_string(), body.to_string()))
}

fn get(port: u16, path: &str) -> std::io::Result<(u16, String, String)> {
    http(port, format!("GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: */*\r\n\r\n").as_bytes())
}

/// Parses an exposition strictly; panics with the text on any error.
fn parse(body: &str) -> Families {
    openmetrics_parser::prometheus::parse_prometheus(body).unwrap_or_else(|e| panic!("{e:?} in\n{body}")).families
}

/// The single value of a family without labels (gauge or counter).
fn value(f: &Families, name: &str) -> f64 {
    let fam = f.get(name).unwrap_or_else(|| panic!("no family {name}"));
    let s = fam.iter_samples().next().unwrap_or_else(|| panic!("{name}: no sample"));
    match &s.value {
        PrometheusValue::Gauge(n) => n.as_f64(),
        PrometheusValue::Counter(c) => c.value.as_f64(),
        other => panic!("{name}: {other:?}"),
    }
}

fn labelled(f: &Families, name: &str, label_value: &str) -> f64 {
    let fam = f.get(name).unwrap_or_else(|| panic!("no family {name}"));
    let s = fam
        .get_sample_by_label_values(&[label_value.to_string()])
        .unwrap_or_else(|| panic!("{name}: no sample {label_value}"));
    match &s.value {
        PrometheusValue::Gauge(n) => n.as_f64(),
        PrometheusValue::Counter(c) => c.value.as_f64(),
        other => panic!("{name}: {other:?}"),
    }
}

/// The latency histogram's buckets (bound, count), `_count` and `_sum`.
fn histogram(f: &Families) -> (Vec<(f64, f64)>, u64, f64) {
    let fam = f.get("fme_frame_to_register_latency_seconds").expect("latency histogram");
    let s = fam.iter_samples().next().expect("one histogram");
    let PrometheusValue::Histogram(h) = &s.value else { panic!("not a histogram: {:?}", s.value) };
    let buckets = h.buckets.iter().map(|b| (b.upper_bound, b.count.as_f64())).collect();
    (buckets, h.count.expect("_count"), h.sum.map(|x| x.as_f64()).expect("_sum"))
}

/// (family, type) of the documented families this test pins (docs/metrics.md lists them all).
const EXPECTED: &[(&str, &str)] = &[
    ("fme_build_info", "gauge"),
    ("fme_uptime_seconds", "gauge"),
    ("fme_activity_mean_meters_per_second", "gauge"),
    ("fme_activity_smoothed_meters_per_second", "gauge"),
    ("fme_activity_ci95_half_width_meters_per_second", "gauge"),
    ("fme_activity_mean_body_lengths_per_second", "gauge"),
    ("fme_activity_age_seconds", "gauge"),
    ("fme_fish", "gauge"),
    ("fme_tracks", "gauge"),
    ("fme_status_word", "gauge"),
    ("fme_status_bit", "gauge"),
    ("fme_fault_code", "gauge"),
    ("fme_fault_active", "gauge"),
    ("fme_feeding_recommended", "gauge"),
    ("fme_frames_captured_total", "counter"),
    ("fme_frames_processed_total", "counter"),
    ("fme_frames_dropped_total", "counter"),
    ("fme_capture_errors_total", "counter"),
    ("fme_camera_reconnects_total", "counter"),
    ("fme_pipeline_errors_total", "counter"),
    ("fme_updates_total", "counter"),
    ("fme_detector_runs_total", "counter"),
    ("fme_depth_runs_total", "counter"),
    ("fme_frame_to_register_latency_seconds", "histogram"),
    ("fme_modbus_requests_total", "counter"),
    ("fme_modbus_exceptions_total", "counter"),
    ("fme_modbus_tcp_connections", "gauge"),
    ("fme_modbus_tcp_closed_total", "counter"),
    ("fme_plc_writes_total", "counter"),
    ("fme_history_rows_written_total", "counter"),
    ("fme_record_frames_written_total", "counter"),
    ("fme_metrics_http_responses_total", "counter"),
    ("fme_metrics_connections_refused_total", "counter"),
    ("fme_mqtt_link", "gauge"),
    ("fme_mqtt_queued_messages", "gauge"),
    ("fme_mqtt_published_total", "counter"),
    ("fme_mqtt_dropped_total", "counter"),
    ("fme_mqtt_reconnects_total", "counter"),
];

/// One FC04 read of 24 registers over raw Modbus TCP; whether it was answered.
fn modbus_read(port: u16) -> bool {
    let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else { return false };
    let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
    let mut ans = [0u8; 9 + 48];
    s.write_all(&[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 24]).is_ok() && s.read_exact(&mut ans).is_ok() && ans[7] == 4
}

#[test]
fn fme_run_serves_parseable_metrics_and_survives_hostile_requests() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (port, modbus_port) = (free_port(), free_port());
    let log = dir.path().join("stderr.log");
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("STATE_DIRECTORY")
        .args(["run", "--source", "tests/data/swarm20", "--set"])
        .arg(format!("output.metrics.listen=\"127.0.0.1:{port}\""))
        .args(["--modbus-listen", &format!("127.0.0.1:{modbus_port}"), "--set", "output.rate_hz=10"])
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).expect("log file"))
        .spawn()
        .expect("spawn fme run");
    let mut run = Running(child);
    let log_text = || std::fs::read_to_string(&log).unwrap_or_default();

    // Start-up loads the models; then wait for tracked fish in the exposition.
    let deadline = Instant::now() + Duration::from_secs(60);
    let first = loop {
        if let Ok((200, _, body)) = get(port, "/metrics") {
            let f = parse(&body);
            if value(&f, "fme_fish") > 0.0 && histogram(&f).1 > 0 {
                break f;
            }
        }
        assert!(Instant::now() < deadline, "no fish in the metrics within 60 s:\n{}", log_text());
        assert!(run.0.try_wait().ok().flatten().is_none(), "fme run exited:\n{}", log_text());
        std::thread::sleep(Duration::from_millis(200));
    };
    // An unfinished request, answered 408 after its timeout (read at the end).
    let mut slow = TcpStream::connect(("127.0.0.1", port)).expect("connect");
    slow.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\n").expect("write");

    for (name, kind) in EXPECTED {
        let fam = first.get(*name).unwrap_or_else(|| panic!("no family {name}"));
        assert_eq!(fam.family_type.to_string(), *kind, "{name}");
    }
    assert!(first.keys().all(|k| k.starts_with("fme_")), "{:?}", first.keys());
    assert_eq!(labelled(&first, "fme_status_bit", "running"), 1.0);
    assert_eq!(labelled(&first, "fme_status_bit", "camera_ok"), 1.0);
    assert_eq!(labelled(&first, "fme_status_bit", "depth_calibrated"), 1.0, "swarm20 is calibrated");
    assert_eq!(value(&first, "fme_status_word") as u16 & 0b1011, 0b1011, "bits 0, 1, 3 in the raw word");
    let mean = value(&first, "fme_activity_mean_meters_per_second");
    assert!(mean.is_finite() && mean > 0.0, "activity {mean}");
    assert_eq!(value(&first, "fme_fault_code"), 0.0);

    // The head of a good answer, and HEAD.
    let (code, head, body) = get(port, "/metrics").expect("scrape");
    assert_eq!(code, 200);
    assert!(head.contains("\r\nContent-Type: text/plain; version=0.0.4"), "{head}");
    assert!(head.contains(&format!("\r\nContent-Length: {}\r\n", body.len())), "{head}");
    let (code, head, body) = http(port, b"HEAD /metrics HTTP/1.1\r\n\r\n").expect("HEAD");
    assert!(code == 200 && body.is_empty() && head.contains("Content-Length: "), "{head}");

    // Wrong path, wrong method, garbage, an oversized head: error answers, nothing else.
    assert_eq!(get(port, "/").expect("GET /").0, 404);
    assert_eq!(get(port, "/metrics/../etc/passwd").expect("GET traversal").0, 404);
    let (code, head, _) = http(port, b"POST /metrics HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello").expect("POST");
    assert!(code == 405 && head.contains("Allow: GET, HEAD"), "{head}");
    let garbage = b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\xff\r\n\r\n";
    assert_eq!(http(port, garbage).expect("garbage").0, 400);
    let mut huge = b"GET /metrics HTTP/1.1\r\nX-Filler: ".to_vec();
    huge.resize(64 * 1024, b'a');
    match http(port, &huge) {
        Ok((code, _, _)) => assert_eq!(code, 431, "oversized head"),
        Err(e) => assert!(
            matches!(e.kind(), std::io::ErrorKind::ConnectionReset | std::io::ErrorKind::BrokenPipe),
            "oversized head: {e}"
        ),
    }
    assert!(modbus_read(modbus_port), "modbus served");

    // Counters grow between scrapes; the histogram stays cumulative with +Inf = _count.
    std::thread::sleep(Duration::from_millis(1500));
    let (code, _, body) = get(port, "/metrics").expect("second scrape");
    assert_eq!(code, 200);
    let second = parse(&body);
    for c in ["fme_frames_captured_total", "fme_frames_processed_total", "fme_updates_total"] {
        assert!(value(&second, c) > value(&first, c), "{c} grows: {} -> {}", value(&first, c), value(&second, c));
    }
    assert!(value(&second, "fme_modbus_requests_total") >= 1.0);
    assert!(value(&second, "fme_uptime_seconds") > value(&first, "fme_uptime_seconds"));
    let (buckets, count, sum) = histogram(&second);
    assert!(count > histogram(&first).1, "latency samples grow");
    assert!(buckets.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 <= w[1].1), "cumulative: {buckets:?}");
    assert_eq!(buckets.last().map(|b| (b.0, b.1)), Some((f64::INFINITY, count as f64)), "+Inf = _count");
    assert!(sum > 0.0 && sum.is_finite(), "_sum {sum}");

    // The unfinished request: 408 once its timeout passed.
    slow.set_read_timeout(Some(Duration::from_secs(15))).expect("timeout");
    let mut raw = Vec::new();
    let _ = slow.read_to_end(&mut raw);
    assert_eq!(parse_response(&raw).map(|r| r.0).ok(), Some(408), "{:?}", String::from_utf8_lossy(&raw));

    // More connections from one address than the endpoint serves: the extra one is closed unanswered.
    std::thread::sleep(Duration::from_millis(300)); // the answered connections above finish
    let idle: Vec<TcpStream> = (0..fme::config::MetricsConfig::default().max_connections_per_peer)
        .map(|_| TcpStream::connect(("127.0.0.1", port)).expect("connect"))
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let refused = get(port, "/metrics");
    assert!(refused.is_err(), "over the limit: closed without an answer, got {refused:?}");
    drop(idle);
    std::thread::sleep(Duration::from_millis(200));

    // Still serving, and it counted all of the above.
    let (code, _, body) = get(port, "/metrics").expect("scrape after the abuse");
    assert_eq!(code, 200);
    let last = parse(&body);
    for (code, at_least) in [("200", 4.0), ("400", 1.0), ("404", 2.0), ("405", 1.0), ("408", 1.0)] {
        let n = labelled(&last, "fme_metrics_http_responses_total", code);
        assert!(n >= at_least, "{code}: {n}");
    }
    assert!(value(&last, "fme_metrics_connections_refused_total") >= 1.0);
    assert!(value(&last, "fme_metrics_connections_aborted_total") >= 1.0, "the idle connections");

    // curl, when installed, reads the same format.
    if let Ok(out) = Command::new("curl").args(["-sf", &format!("http://127.0.0.1:{port}/metrics")]).output() {
        assert!(out.status.success(), "curl: {}", String::from_utf8_lossy(&out.stderr));
        let f = parse(&String::from_utf8_lossy(&out.stdout));
        assert!(value(&f, "fme_frames_processed_total") >= value(&last, "fme_frames_processed_total"));
    }

    let st = Command::new("kill").args(["-TERM", &run.0.id().to_string()]).status().expect("kill");
    assert!(st.success());
    let end = Instant::now() + Duration::from_secs(5);
    while run.0.try_wait().ok().flatten().is_none() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = run.0.try_wait().ok().flatten();
    assert_eq!(status.and_then(|s| s.code()), Some(0), "clean stop:\n{}", log_text());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_metrics_port_in_use_is_logged_and_the_daemon_runs_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 10, 64, 48, 30);
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = taken.local_addr().expect("addr");
    let mut cfg = support::test_config(dir.path());
    cfg.output.metrics.listen = addr.to_string();
    cfg.web.listen = addr.to_string();
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), src, pipeline, RunOptions::default()).await.expect("starts");
    assert_eq!(daemon.metrics_addr(), None);
    let shared = daemon.shared().clone();
    let state = shared.metrics.describe().to_string();
    assert!(state.starts_with("failed: ") && state.contains("output.metrics.listen"), "{state}");
    assert!(
        shared.last_logs(50).iter().any(|l| l.contains("ERROR") && l.contains(&addr.to_string())),
        "{:?}",
        shared.last_logs(50)
    );
    let mut status = String::new();
    fme::console::Session::default().command("status", &shared, daemon.bank(), &mut status);
    assert!(status.contains("\r\nmetrics failed: cannot listen on"), "console status: {status}");
    assert!(status.contains("\r\nweb failed: cannot listen on") && status.contains("(web.listen)"), "{status}");
    // The rest runs: frames are processed and the registers update.
    let before = daemon.bank().block()[12];
    let end = Instant::now() + Duration::from_secs(10);
    while daemon.bank().block()[12] == before && Instant::now() < end {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_ne!(daemon.bank().block()[12], before, "heartbeat moves");
    assert!(shared.health().frames_processed > 0);
    assert!(daemon.modbus_addr().is_some(), "modbus serves");
    daemon.shutdown().await;
}
