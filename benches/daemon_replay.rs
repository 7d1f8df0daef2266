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

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let seq = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/swarm20");
    println!("daemon bench: {} (120 frames, 640x384, 30 fps), pipeline = service::build_pipeline", seq.display());

    // Phase 1: real time, looping, PLC polling the registers every 100 ms.
    let bench_mode = std::env::args().any(|a| a == "--bench");
    let secs = env_num("FME_BENCH_REALTIME_S", if bench_mode { 20 } else { 3 });
    let cfg = config(&seq);
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(&seq, true, true).expect("open"));
    let pipe = service::build_pipeline(&cfg).expect("pipeline");
    let daemon = Daemon::start(cfg, String::new(), src, pipe, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let mut plc = tcp::connect_slave(daemon.modbus_addr().expect("addr"), Slave(1)).await.expect("connect");
    let warmup = Duration::from_secs(2);
    let t0 = Instant::now();
    let mut warm: Option<(u64, u64, f64, Instant)> = None;
    let mut polls = 0u32;
    while t0.elapsed() < Duration::from_secs(secs) {
        tokio::time::sleep(Duration::from_millis(100)).await;
        if plc.read_input_registers(0, 24).await.is_ok_and(|r| r.is_ok()) {
            polls += 1;
        }
        if warm.is_none() && t0.elapsed() >= warmup {
            let hh = shared.health();
            warm = Some((hh.frames_dropped, hh.frames_processed, cpu_seconds(), Instant::now()));
        }
    }
    let hh = shared.health();
    let (d0, p0, c0, w0) = warm.expect("warm-up passed");
    let span = w0.elapsed().as_secs_f64();
    println!(
        "realtime {secs} s: captured {} processed {} dropped after {}s warm-up: {} (total {}); processed {:.1} fps; \
         latency frame->register p50 {:?} ms p99 {:?} ms max {:.1} ms over {} updates; cpu {:.0}% of one core; \
         rss {} kB (peak {} kB); plc polls ok {polls}",
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
        100.0 * (cpu_seconds() - c0) / span,
        proc_status_kb("VmRSS:"),
        proc_status_kb("VmHWM:"),
    );
    daemon.shutdown().await;

    // Phase 2: as fast as possible, many frames, memory sampled along the way.
    let n = env_num("FME_BENCH_FAST_FRAMES", if bench_mode { 20_000 } else { 300 });
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
