//! A stuck pipeline stops the systemd watchdog pings (so systemd restarts the service) and raises
//! fault code 4 "pipeline stalled" in the registers, while the rest of the daemon keeps running.
//! Alone in its test binary because it sets NOTIFY_SOCKET / WATCHDOG_USEC for the process.

#[path = "daemon/support.rs"]
mod support;

use fme::capture::{Frame, FrameSource, RecordedSource};
use fme::output::registers::FaultCode;
use fme::pipeline::{FrameOutcome, Pipeline, PipelineError, StageHealth};
use fme::service::{Daemon, RunOptions};
use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

/// Works for `ok_frames` frames, then blocks for a long time in one call (a hung stage).
struct StuckAfter {
    ok_frames: u32,
    seen: u32,
}

impl Pipeline for StuckAfter {
    fn process(&mut self, _frame: &Frame) -> Result<FrameOutcome<'_>, PipelineError> {
        self.seen += 1;
        if self.seen == self.ok_frames {
            std::thread::sleep(Duration::from_secs(4));
        }
        Ok(FrameOutcome::sample_only(None, self.health()))
    }
    fn health(&self) -> StageHealth {
        StageHealth { detector_ok: true, depth_ok: true, ..StageHealth::default() }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stuck_pipeline_stops_watchdog_and_raises_fault() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 10, 64, 48, 30);
    let sock_path = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind");
    sock.set_read_timeout(Some(Duration::from_millis(50))).expect("timeout");
    // SAFETY: this test binary has a single test and sets the variables before any other thread
    // of ours reads the environment.
    unsafe {
        std::env::set_var("NOTIFY_SOCKET", &sock_path);
        std::env::set_var("WATCHDOG_USEC", "200000");
    }
    let mut cfg = support::test_config(&dir.path().join("seq"));
    cfg.service.systemd_notify = true;
    cfg.service.stall_after_s = 0.5;
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(&dir.path().join("seq"), true, true).expect("open"));
    let daemon =
        Daemon::start(cfg, String::new(), src, Box::new(StuckAfter { ok_frames: 30, seen: 0 }), RunOptions::default())
            .await
            .expect("start");
    let bank = daemon.bank().clone();
    let mut pings: Vec<Instant> = Vec::new();
    let t0 = Instant::now();
    let mut buf = [0u8; 256];
    while t0.elapsed() < Duration::from_millis(2600) {
        if let Ok(n) = sock.recv(&mut buf)
            && String::from_utf8_lossy(&buf[..n]).contains("WATCHDOG=1")
        {
            pings.push(Instant::now());
        }
    }
    // 30 frames at 30 fps = 1 s of pings every 0.1 s, then nothing while the stage hangs (4 s).
    let early = pings.iter().filter(|p| p.duration_since(t0) < Duration::from_millis(1000)).count();
    let late = pings.iter().filter(|p| p.duration_since(t0) > Duration::from_millis(1600)).count();
    assert!(early >= 3, "pings while healthy: {early}");
    assert_eq!(late, 0, "no pings while the pipeline is stuck");
    let blk = bank.block();
    assert_eq!(blk[11], FaultCode::PipelineStalled as u16, "fault 4 published while stuck: {blk:?}");
    let hb = blk[12];
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_ne!(bank.block()[12], hb, "heartbeat still advances: the PLC sees a live box with a fault");
    daemon.shutdown().await;
}
