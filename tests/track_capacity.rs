//! Capacity limits: overflow keeps the highest scores, is counted, and never panics.

use fme::geometry::PixelBox;
use fme::track::{Detection, MAX_DETS, MAX_TRACKS, Tracker, TrackerConfig};
use fme::units::Seconds;

fn grid(n: usize, score: impl Fn(usize) -> f64) -> Vec<Detection> {
    (0..n)
        .map(|i| Detection::new(PixelBox::new((i % 40) as f64 * 50.0, (i / 40) as f64 * 50.0, 30.0, 30.0), score(i)))
        .collect()
}

#[test]
fn detection_overflow_keeps_highest_scores() {
    const { assert!(MAX_DETS >= 256 && MAX_TRACKS >= 128) };
    let mut cfg = TrackerConfig::default_preset();
    cfg.min_hits = 1;
    cfg.new_track_threshold = 0.0;
    cfg.track_threshold = 0.0;
    let mut t = Tracker::new(cfg);
    // 300 detections; scores rise with the index, so the best are the last ones.
    let dets = grid(300, |i| 0.1 + i as f64 / 1000.0);
    let out = t.update(Seconds(0.0), &dets).expect("ok").to_vec();
    assert_eq!(t.stats().det_overflow, 300 - MAX_DETS as u64);
    // Tracks are capped too: the best-scoring detections got them.
    assert_eq!(out.len(), MAX_TRACKS);
    let lowest_kept = 0.1 + (300 - MAX_DETS) as f64 / 1000.0;
    assert!(out.iter().all(|o| o.score >= lowest_kept - 1e-12));
    assert!(t.stats().track_overflow > 0);
    assert_eq!(t.live_tracks(), MAX_TRACKS);
    // Keeps running with the same load.
    for k in 1..5 {
        let out = t.update(Seconds(k as f64 / 30.0), &dets).expect("ok");
        assert_eq!(out.len(), MAX_TRACKS);
    }
}

#[test]
fn sort_preset_overflow_does_not_panic() {
    let mut t = Tracker::new(TrackerConfig::sort());
    let dets = grid(1000, |i| (i % 100) as f64 / 100.0);
    for k in 0..5 {
        t.update(Seconds(k as f64), &dets).expect("ok");
    }
    assert!(t.live_tracks() <= MAX_TRACKS);
    assert_eq!(t.stats().det_overflow, 5 * (1000 - MAX_DETS as u64));
}

#[test]
fn configured_max_tracks_caps_below_capacity() {
    let mut cfg = TrackerConfig::default_preset();
    cfg.max_tracks = 10;
    cfg.min_hits = 1;
    cfg.new_track_threshold = 0.0;
    let mut t = Tracker::new(cfg);
    let dets = grid(30, |i| 0.9 - i as f64 / 100.0);
    let out = t.update(Seconds(0.0), &dets).expect("ok").to_vec();
    assert_eq!(out.len(), 10);
    assert_eq!(t.live_tracks(), 10);
    assert_eq!(t.stats().track_overflow, 20);
}
