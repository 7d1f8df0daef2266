//! Benchmark of `fme run` on an IP camera (`make bench-daemon`; not a test): the bundled recording
//! (`tests/data/swarm20`, 640x384) served as H.264 at 30 fps by GStreamer's RTSP server
//! (tests/rtsp_server.py; `make setup` installs it) and, beside it in the same run, the same recording
//! read from its folder at 30 fps. Both are the real daemon (this build's `fme run`, the default
//! config: bundled int8 models, ONNX Runtime in the default build, Modbus TCP polled by a PLC here),
//! so what RTSP costs (RTP over TCP, depacketising, H.264 decoding) is the difference of the two.
//!
//! Reports per run: the daemon's CPU in % of one core (utime + stime of its `/proc/<pid>/stat` over
//! the measured wall span, after a warm-up), the camera frame rate and the frames dropped the
//! registers show. The GStreamer server is another process: the camera's work is not counted.
//! Environment: `FME_BENCH_RTSP_S` (measured seconds per run, default 20), `FME_BENCH_ROUNDS`
//! (folder / RTSP pairs, default 2). Run without `--bench` (as `cargo test --all-targets` does) it
//! only smoke-runs: one pair of 3 s.

#[allow(dead_code)] // the tests' other servers
#[path = "../tests/rtsp/servers.rs"]
mod servers;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tokio_modbus::prelude::*;

const SEQ: &str = "tests/data/swarm20";

/// A child process killed when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Ends the bench with `message`; a panic, so that the children are killed on the way out.
fn fail(message: String) -> ! {
    panic!("daemon_rtsp: {message}")
}

/// utime + stime of process `pid`, s.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let f: Vec<&str> = s.rsplit_once(')')?.1.split_whitespace().collect();
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / hz)
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or_else(|e| fail(format!("no free port: {e}")))
}

/// The 24 input registers.
async fn read(plc: &mut tokio_modbus::client::Context, source: &str) -> Vec<u16> {
    match plc.read_input_registers(0, 24).await {
        Ok(Ok(r)) => r,
        _ => fail(format!("fme run --source {source}: Modbus read failed")),
    }
}

/// Polls the registers every 100 ms, as a PLC does, for `d`; the last read.
async fn poll_for(plc: &mut tokio_modbus::client::Context, source: &str, d: Duration) -> Vec<u16> {
    let end = Instant::now() + d;
    let mut last = read(plc, source).await;
    while Instant::now() < end {
        tokio::time::sleep(Duration::from_millis(100)).await;
        last = read(plc, source).await;
    }
    last
}

/// One run's figures.
struct Figures {
    cpu_pct: f64,
    fps: f64,
    dropped: u16,
}

/// `fme run --source source` for `warm` + `secs` s with a PLC polling every 100 ms.
async fn measure(source: &str, warm: u64, secs: u64) -> Figures {
    let port = free_port();
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .args(["run", "--source", source, "--modbus-listen", &format!("127.0.0.1:{port}")])
        .args(["--set", "service.systemd_notify=false"])
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("STATE_DIRECTORY")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| fail(format!("cannot start fme run: {e}")));
    let daemon = Killed(child);
    let pid = daemon.0.id();
    let addr = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let start = Instant::now();
    let mut plc = loop {
        if let Ok(c) = tcp::connect_slave(addr, Slave(1)).await {
            break c;
        }
        if start.elapsed() > Duration::from_secs(60) {
            fail(format!("fme run --source {source} served no Modbus within 60 s"));
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    while read(&mut plc, source).await[10] & 2 == 0 {
        if start.elapsed() > Duration::from_secs(60) {
            fail(format!("fme run --source {source}: camera not ok within 60 s"));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let r0 = poll_for(&mut plc, source, Duration::from_secs(warm)).await;
    let (c0, t0) = (cpu_seconds(pid), Instant::now());
    let r1 = poll_for(&mut plc, source, Duration::from_secs(secs)).await;
    let (c1, span) = (cpu_seconds(pid), t0.elapsed().as_secs_f64());
    let (Some(c0), Some(c1)) = (c0, c1) else { fail(format!("no /proc/{pid}/stat")) };
    Figures { cpu_pct: 100.0 * (c1 - c0) / span, fps: f64::from(r1[15]) / 10.0, dropped: r1[16].wrapping_sub(r0[16]) }
}

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let bench_mode = std::env::args().any(|a| a == "--bench");
    let env = |k: &str, d: u64| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let secs = env("FME_BENCH_RTSP_S", if bench_mode { 20 } else { 3 });
    let rounds = env("FME_BENCH_ROUNDS", if bench_mode { 2 } else { 1 });
    let warm = if bench_mode { 5 } else { 1 };
    let server = servers::GstServer::start(0);
    let url = server.url("/h264");
    println!("daemon_rtsp: fme run on {SEQ} (640x384, 30 fps) from its folder and as H.264 over RTSP ({url})");
    let mut sums = [0.0f64; 2];
    for round in 0..rounds {
        for (k, source) in [SEQ, url.as_str()].into_iter().enumerate() {
            let f = measure(source, warm, secs).await;
            let what = if k == 0 { "folder" } else { "rtsp  " };
            println!(
                "round {round} {what}: cpu {:.1}% of one core over {secs} s; camera {:.1} fps; dropped {}",
                f.cpu_pct, f.fps, f.dropped
            );
            sums[k] += f.cpu_pct;
        }
    }
    let n = rounds.max(1) as f64;
    let (folder, rtsp) = (sums[0] / n, sums[1] / n);
    println!(
        "mean over {rounds} rounds: folder {folder:.1}%, rtsp {rtsp:.1}% of one core; RTSP + H.264 decoding costs \
         {:.1} points (issue target: the daemon over RTSP under 25%)",
        rtsp - folder
    );
}
