//! A camera back after an outage longer than `service.stall_after_s` is no pipeline stall: while
//! its first frame is still in the pipeline, the keepalive's updates say the camera is back, not
//! that the pipeline stopped.

use crate::support;

use fme::capture::{CaptureError, Frame, FrameSource, RecordedSource};
use fme::output::registers::FaultCode;
use fme::pipeline::{FrameOutcome, Pipeline, PipelineError, StageHealth};
use fme::service::{Daemon, RunOptions};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// A recording that goes away for `gap` after `before` frames, as a camera does.
struct Outage {
    inner: RecordedSource,
    before: u64,
    gap: Duration,
    gap_end: Option<Instant>,
}

impl Outage {
    fn away(&self) -> bool {
        self.gap_end.is_some_and(|t| Instant::now() < t)
    }
}

impl FrameSource for Outage {
    fn next_frame(&mut self, buf: Vec<u8>) -> Result<Frame, CaptureError> {
        if self.gap_end.is_none() && self.before == 0 {
            self.gap_end = Some(Instant::now() + self.gap);
        }
        if self.away() {
            std::thread::sleep(Duration::from_millis(50));
            return Err(CaptureError::Timeout { path: PathBuf::from("outage"), timeout_ms: 50 });
        }
        self.before = self.before.saturating_sub(1);
        self.inner.next_frame(buf)
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        if self.away() {
            return Err(CaptureError::Open { path: PathBuf::from("outage"), message: "unreachable".into() });
        }
        Ok(())
    }

    fn describe(&self) -> String {
        "camera with an outage".into()
    }
}

/// The frame-difference double, slow (300 ms) on the first frame after a second without frames.
struct SlowAfterGap {
    inner: Box<dyn Pipeline>,
    last: Option<Instant>,
}

impl Pipeline for SlowAfterGap {
    fn process(&mut self, frame: &Frame) -> Result<FrameOutcome<'_>, PipelineError> {
        if self.last.is_some_and(|t| t.elapsed() > Duration::from_secs(1)) {
            std::thread::sleep(Duration::from_millis(300));
        }
        self.last = Some(Instant::now());
        self.inner.process(frame)
    }

    fn health(&self) -> StageHealth {
        self.inner.health()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_camera_back_after_an_outage_is_no_pipeline_stall() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 30, 64, 48, 30);
    let mut cfg = support::test_config(dir.path());
    cfg.service.stall_after_s = 0.5;
    cfg.source.reconnect_min_ms = 50;
    cfg.source.reconnect_max_ms = 100;
    let inner = RecordedSource::open(dir.path(), true, true).expect("open");
    let source = Box::new(Outage { inner, before: 15, gap: Duration::from_millis(1500), gap_end: None });
    let pipeline = Box::new(SlowAfterGap { inner: support::edge_pipeline(&cfg), last: None });
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let (shared, bank) = (daemon.shared().clone(), daemon.bank().clone());
    let mut faults = Vec::new();
    let end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < end && !(shared.health().reconnects >= 1 && shared.health().frames_processed >= 25) {
        let f = bank.block()[11];
        if faults.last() != Some(&f) {
            faults.push(f);
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    daemon.shutdown().await;
    let camera = FaultCode::Camera as u16;
    assert!(faults.contains(&camera), "the outage is a camera fault: {faults:?}");
    assert!(!faults.contains(&(FaultCode::PipelineStalled as u16)), "no stall after the camera's return: {faults:?}");
    assert_eq!(faults.last(), Some(&0), "{faults:?}");
}
