//! Frames far larger than the source's size are bad frames: dropped from their JPEG header before
//! anything decodes them, counted, logged, and the daemon goes on with the next frame.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::service::{Daemon, RunOptions};
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversized_frame_is_dropped_before_decoding() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 10, 64, 48, 30);
    // Frame 5 is 640x480: 100 x the recording's 64x48, over the default limit (4 x the larger of
    // the configured and the source's size: 4 x 640x384 would pass it, so configure 64x48).
    let big = image::GrayImage::from_pixel(640, 480, image::Luma([30]));
    big.save(dir.path().join("img1").join("000005.jpg")).expect("write big frame");
    let mut cfg = support::test_config(dir.path());
    cfg.source.width = 64;
    cfg.source.height = 48;
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), false, false).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let mut daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let ended = tokio::time::timeout(Duration::from_secs(10), daemon.finished()).await;
    assert_eq!(ended.ok(), Some(true), "the recording plays to its end");
    let shared = daemon.shared().clone();
    let h = shared.health();
    assert_eq!((h.frames_captured, h.capture_errors, h.frames_processed), (9, 1, 9), "one bad frame of ten");
    let logs = shared.last_logs(50).join("\n");
    assert!(logs.contains("640x480") && logs.contains("source.max_pixels"), "{logs}");
    daemon.shutdown().await;
}
