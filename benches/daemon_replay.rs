//! Benchmark of the daemon's edges (`make bench-daemon`; not a test): real-time replay of a 30 fps
//! 640x384 recording through capture -> queue -> pipeline -> registers -> Modbus TCP (polled by an
//! in-process client), then a long as-fast-as-possible run for memory flatness.
//!
//! Reports: frames dropped after warm-up, frame-to-register latency p50/p99/max, CPU use, resident
//! memory. The recording is the bundled `tests/data/swarm20` (calibrated, 20 fish) and the pipeline is
//! `fme run`'s: bundled int8 detector at 10 Hz, depth at 5 Hz, tracker, eq. 1-5 (`config/fme.toml` defaults).
//!
//! Environment: `FME_BENCH_REALTIME_S` (default 20), `FME_BENCH_FAST_FRAMES` (default 20000),
//! `FME_BENCH_THREADS` (both networks' intra-op threads; default the config's 1), `FME_BENCH_SPIN=1`.
//! `FME_BENCH_RECORD=1`: the real-time phase alternately without and with the black box
//! (`[record]` defaults), `FME_BENCH_RECORD_ROUNDS` (default 2) times each, with the cost as ratios
//! and the disk use per hour (docs/recording.md); `FME_BENCH_FAST_FRAMES=0` skips the fast phase.
//! `FME_BENCH_TELEMETRY=1`: likewise without and with the fleet telemetry: `[output.mqtt]` publishing
//! to a Mosquitto this bench starts on a free loopback port (`make setup` installs it) and
//! `[output.metrics]` scraped once a second (docs/mqtt.md, docs/metrics.md).
//! Run without `--bench` (as `cargo test --all-targets` does) it only smoke-runs: 3 s and 300 frames.

use fme::capture::{FrameSource, RecordedSource};
use fme::config::{Config, ModbusMode};
use fme::service::{self, Daemon, RunOptions};
use std::path::Path;
use std::time::{Duration, Instant};
use tokio_modbus::prelude::*;

fn proc_status_kb(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse().ok()))
        .unwrap_or(0)
}

fn cpu_seconds() -> f64 {
    // utime + stime from /proc/self/stat, in clock ticks (100 Hz on Linux).
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let rest = s.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(0.0)
}

fn config(seq: &Path) -> Config {
    let mut c = Config::default();
    c.source.path = seq.to_path_buf();
    c.output.modbus.mode = ModbusMode::TcpServer;
    c.output.modbus.listen = "127.0.0.1:0".into();
    c.output.rate_hz = 10.0;
    c.service.systemd_notify = false;
    // FME_BENCH_THREADS / FME_BENCH_SPIN=1: both networks' intra-op threads and spinning (a board
    // profile's `threads = 2`, with or without `spin`).
    let threads = env_num("FME_BENCH_THREADS", c.detector.threads as u64) as usize;
    let spin = env_num("FME_BENCH_SPIN", 0) == 1;
    (c.detector.threads, c.depth.threads, c.detector.spin, c.depth.spin) = (threads, threads, spin, spin);
    c
}

fn env_num(key: &str, default: u64) -> u64 {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn mqtt_line(h: &fme::status::Health) -> String {
    let m = &h.mqtt;
    if m.broker.is_empty() {
        return "off".into();
    }
    format!(
        "{:?} published {} queued {} dropped {} reconnects {}",
        m.link, m.published, m.queued, m.dropped, m.reconnects
    )
}

/// One real-time run's figures.
struct Realtime {
    line: String,
    cpu_pct: f64,
    p50_ms: f64,
    p99_ms: f64,
    ring_bytes: u64,
    frames_in_ring: u64,
}

/// What a real-time run adds to the plain pipeline.
#[derive(Clone, Copy)]
enum Extra<'a> {
    None,
    /// Record into this state directory.
    Record(&'a Path),
    /// MQTT to this loopback port, and the metrics endpoint scraped once a second.
    Telemetry(u16),
}

#[path = "support/broker.rs"]
mod broker;
use broker::Broker;

/// One scrape of the metrics endpoint: the body's length, 0 on any failure.
async fn scrape(addr: std::net::SocketAddr) -> usize {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else { return 0 };
    if s.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").await.is_err() {
        return 0;
    }
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf).await;
    let text = String::from_utf8_lossy(&buf);
    if !text.starts_with("HTTP/1.1 200") {
        return 0;
    }
    text.split_once("\r\n\r\n").map_or(0, |(_, body)| body.len())
}

/// Phase 1: `secs` of real-time replay with a polling PLC, with `extra`.
async fn realtime(seq: &Path, secs: u64, extra: Extra<'_>) -> Realtime {
    let mut cfg = config(seq);
    match extra {
        Extra::Record(dir) => cfg.service.state_dir = dir.to_path_buf(),
        Extra::None => cfg.record.enabled = false,
        Extra::Telemetry(port) => {
            cfg.record.enabled = false;
            cfg.output.mqtt.enabled = true;
            cfg.output.mqtt.broker = format!("127.0.0.1:{port}");
            cfg.output.mqtt.box_id = "bench".into();
            cfg.output.metrics.listen = "127.0.0.1:0".into();
        }
    }
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(seq, true, true).expect("open"));
    let pipe = service::build_pipeline(&cfg).expect("pipeline");
    let daemon = Daemon::start(cfg, String::new(), src, pipe, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let mut plc = tcp::connect_slave(daemon.modbus_addr().expect("addr"), Slave(1)).await.expect("connect");
    let warmup = Duration::from_secs(2);
    let t0 = Instant::now();
    let mut warm: Option<(u64, u64, f64, Instant)> = None;
    let mut polls = 0u32;
    let (mut scrapes, mut scrape_bytes, mut next_scrape) = (0u32, 0usize, t0);
    let metrics = daemon.metrics_addr();
    while t0.elapsed() < Duration::from_secs(secs) {
        tokio::time::sleep(Duration::from_millis(100)).await;
        if plc.read_input_registers(0, 24).await.is_ok_and(|r| r.is_ok()) {
            polls += 1;
        }
        if let Some(addr) = metrics.filter(|_| Instant::now() >= next_scrape) {
            next_scrape += Duration::from_secs(1);
            let n = scrape(addr).await;
            scrapes += u32::from(n > 0);
            scrape_bytes = scrape_bytes.max(n);
        }
        if warm.is_none() && t0.elapsed() >= warmup {
            let hh = shared.health();
            warm = Some((hh.frames_dropped, hh.frames_processed, cpu_seconds(), Instant::now()));
        }
    }
    let hh = shared.health();
    let (d0, p0, c0, w0) = warm.expect("warm-up passed");
    let span = w0.elapsed().as_secs_f64();
    let cpu_pct = 100.0 * (cpu_seconds() - c0) / span;
    let line = format!(
        "realtime {secs} s: captured {} processed {} dropped after {}s warm-up: {} (total {}); processed {:.1} fps; \
         latency frame->register p50 {:?} ms p99 {:?} ms max {:.1} ms over {} updates; cpu {cpu_pct:.0}% of one core; \
         rss {} kB (peak {} kB); plc polls ok {polls}; recorder written {} dropped {} ring {} frames {} bytes; \
         metrics scrapes ok {scrapes} (body {scrape_bytes} B); mqtt {}",
        hh.frames_captured,
        hh.frames_processed,
        warmup.as_secs(),
        hh.frames_dropped - d0,
        hh.frames_dropped,
        (hh.frames_processed - p0) as f64 / span,
        hh.latency.quantile_ms(0.5),
        hh.latency.quantile_ms(0.99),
        hh.latency.max_ms(),
        hh.latency.count(),
        proc_status_kb("VmRSS:"),
        proc_status_kb("VmHWM:"),
        hh.record.frames_written,
        hh.record.frames_dropped,
        hh.record.ring_frames,
        hh.record.ring_bytes,
        mqtt_line(&hh),
    );
    daemon.shutdown().await;
    Realtime {
        line,
        cpu_pct,
        p50_ms: hh.latency.quantile_ms(0.5).unwrap_or(f64::NAN),
        p99_ms: hh.latency.quantile_ms(0.99).unwrap_or(f64::NAN),
        ring_bytes: hh.record.ring_bytes,
        frames_in_ring: hh.record.ring_frames,
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let seq = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/swarm20");
    println!("daemon bench: {} (120 frames, 640x384, 30 fps), pipeline = service::build_pipeline", seq.display());

    // Phase 1: real time, looping, PLC polling the registers every 100 ms. FME_BENCH_RECORD=1: the
    // same run alternately without and with the black box ([record] defaults, a temporary state
    // directory), FME_BENCH_RECORD_ROUNDS (default 2) times each, and the ratios.
    let bench_mode = std::env::args().any(|a| a == "--bench");
    let secs = env_num("FME_BENCH_REALTIME_S", if bench_mode { 20 } else { 3 });
    let record = env_num("FME_BENCH_RECORD", 0) == 1;
    let telemetry = env_num("FME_BENCH_TELEMETRY", 0) == 1;
    if record || telemetry {
        let what = if record { "record" } else { "telemetry" };
        let broker = telemetry.then(|| Broker::start("daemon_replay"));
        let rounds = env_num("FME_BENCH_RECORD_ROUNDS", 2);
        let mut sums = [[0.0f64; 3]; 2];
        let mut bytes_per_frame = 0.0;
        for round in 0..rounds {
            for (i, on) in [false, true].into_iter().enumerate() {
                let state = tempfile::tempdir().expect("tempdir");
                let extra = match (on, &broker) {
                    (false, _) => Extra::None,
                    (true, Some(b)) => Extra::Telemetry(b.port),
                    (true, None) => Extra::Record(state.path()),
                };
                let r = realtime(&seq, secs, extra).await;
                println!("round {round} {what} {on}: {}", r.line);
                for (k, v) in [r.cpu_pct, r.p50_ms, r.p99_ms].into_iter().enumerate() {
                    sums[i][k] += v;
                }
                if on && r.frames_in_ring > 0 {
                    bytes_per_frame = r.ring_bytes as f64 / r.frames_in_ring as f64;
                }
            }
        }
        let n = rounds.max(1) as f64;
        let [off, on] = sums.map(|s| s.map(|v| v / n));
        println!(
            "{what} cost over {rounds} rounds of {secs} s: cpu {:.1}% -> {:.1}% of one core (x{:.3}); latency p50 {:.0} -> {:.0} ms (x{:.3}), p99 {:.0} -> {:.0} ms (x{:.3})",
            off[0],
            on[0],
            on[0] / off[0],
            off[1],
            on[1],
            on[1] / off[1],
            off[2],
            on[2],
            on[2] / off[2]
        );
        if record {
            let d = fme::config::RecordConfig::default();
            println!(
                "disk: {bytes_per_frame:.0} bytes/frame; at 30 fps the ring writes {:.2} GB/hour and holds {:.0} MB (ring_s {} s, cap {} MB)",
                bytes_per_frame * 30.0 * 3600.0 / 1e9,
                (bytes_per_frame * 30.0 * d.ring_s / 1e6).min(d.max_disk_mb as f64),
                d.ring_s,
                d.max_disk_mb
            );
        }
    } else {
        println!("{}", realtime(&seq, secs, Extra::None).await.line);
    }

    // Phase 2: as fast as possible, many frames, memory sampled along the way.
    let n = env_num("FME_BENCH_FAST_FRAMES", if bench_mode { 20_000 } else { 300 });
    if n == 0 {
        return;
    }
    let mut cfg = config(&seq);
    cfg.source.realtime = false;
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(&seq, false, true).expect("open"));
    let pipe = service::build_pipeline(&cfg).expect("pipeline");
    let mut daemon =
        Daemon::start(cfg, String::new(), src, pipe, RunOptions { max_frames: Some(n), ..RunOptions::default() })
            .await
            .expect("start");
    let shared = daemon.shared().clone();
    let t0 = Instant::now();
    let mut rss = Vec::new();
    let step = (n / 10).max(1);
    let mut next = step;
    loop {
        let done = tokio::time::timeout(Duration::from_millis(200), daemon.finished()).await.is_ok_and(|ok| ok);
        let p = shared.health().frames_processed;
        if p >= next || done {
            rss.push((p, proc_status_kb("VmRSS:")));
            next += step;
        }
        if done {
            break;
        }
    }
    let el = t0.elapsed().as_secs_f64();
    let hh = shared.health();
    println!(
        "fast {n} frames: processed {} in {el:.1} s = {:.0} fps (captured {}, dropped by the queue {}); rss kB by frames: {:?}; peak {} kB",
        hh.frames_processed,
        hh.frames_processed as f64 / el,
        hh.frames_captured,
        hh.frames_dropped,
        rss,
        proc_status_kb("VmHWM:")
    );
    daemon.shutdown().await;
}
