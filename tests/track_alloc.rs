//! Proves that the tracker performs no heap allocation per frame in steady state (counting
//! global allocator; its own test binary so other tests do not disturb the count).

use fme::geometry::PixelBox;
use fme::track::{Detection, Tracker, TrackerConfig};
use fme::units::Seconds;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;

/// 60 moving objects, some flickering, plus clutter, so that tracks start, get lost and end.
fn frame(k: usize, out: &mut [Detection; 80]) -> usize {
    let mut n = 0;
    for i in 0..60 {
        if (i + k).is_multiple_of(11) {
            continue; // missed detection
        }
        let x = (i % 10) as f64 * 100.0 + k as f64 * 1.5;
        let y = (i / 10) as f64 * 90.0 + (k as f64 * 0.1 + i as f64).sin() * 5.0;
        let score = if (i + k).is_multiple_of(7) { 0.3 } else { 0.9 };
        out[n] = Detection::new(PixelBox::new(x, y, 40.0, 30.0), score);
        n += 1;
    }
    for c in 0..(k % 5) {
        out[n] = Detection::new(PixelBox::new(2000.0 + 300.0 * c as f64, (k * 37 % 500) as f64, 20.0, 20.0), 0.7);
        n += 1;
    }
    n
}

#[test]
fn no_heap_allocation_per_frame() {
    for cfg in [TrackerConfig::default_preset(), TrackerConfig::sort()] {
        let mut tracker = Tracker::new(cfg);
        let mut buf = [Detection::new(PixelBox::default(), 0.0); 80];
        // Warm-up frames (any lazy initialisation happens here).
        for k in 0..20 {
            let n = frame(k, &mut buf);
            tracker.update(Seconds(k as f64 / 30.0), &buf[..n]).expect("time increases");
        }
        let mut reported = 0;
        let (allocs, ()) = counting_alloc::allocations_in(|| {
            for k in 20..400 {
                let n = frame(k, &mut buf);
                reported += tracker.update(Seconds(k as f64 / 30.0), &buf[..n]).expect("time increases").len();
            }
        });
        assert!(reported > 380 * 40, "tracker must actually track ({reported})");
        assert!(tracker.stats().tracks_started > 60, "tracks must start and end");
        assert_eq!(allocs, 0, "{:?}: {allocs} allocations in 380 frames", cfg.mode);
    }
}
