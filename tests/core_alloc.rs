//! Zero heap allocations per frame in steady state: post-processing + motion for 100 tracks, with a
//! counting global allocator (its own test binary so no other test's allocations interfere).

use fme::geometry::{Camera, Intrinsics, PixelBox, Pose, WorldPoint};
use fme::motion::{ActivityEstimator, MotionConfig, Observation};
use fme::postprocess::PostprocessConfig;
use fme::units::{Metres, Seconds};

#[path = "common/counting_alloc.rs"]
mod counting_alloc;

#[test]
fn steady_state_update_allocates_nothing() {
    let k = Intrinsics::from_hfov(640, 384, 80.0).unwrap();
    let pose =
        Pose::look_at(WorldPoint::new(3.0, -0.5, 1.5), WorldPoint::new(3.0, 3.0, 1.2), nalgebra::Vector3::z()).unwrap();
    let cam = Camera { intrinsics: k, pose };
    let mut est = ActivityEstimator::new(cam, MotionConfig::default(), PostprocessConfig::paper());
    let mut obs: Vec<Observation> = Vec::with_capacity(100);
    let frame = |i: usize, obs: &mut Vec<Observation>| {
        obs.clear();
        let t = i as f64 / 30.0;
        for id in 0..100u32 {
            let ph = id as f64 * 0.37;
            // Wobbling sizes and occasional depth jumps so both detectors and their EWMAs run.
            let w = 40.0 + 6.0 * (t * 9.0 + ph).sin() + if (i + id as usize).is_multiple_of(17) { 25.0 } else { 0.0 };
            let d = 2.0 + (id % 5) as f64 * 0.4 + 0.2 * (t + ph).sin()
                - if (i + id as usize).is_multiple_of(23) { 1.0 } else { 0.0 };
            let u = 320.0 + 200.0 * (t * 0.5 + ph).sin();
            let v = 192.0 + 120.0 * (t * 0.3 + ph).cos();
            obs.push(Observation { id, bbox: PixelBox::new(u - w / 2.0, v - 8.0, w, 16.0), depth: Some(Metres(d)) });
        }
        Seconds(t)
    };
    let mut total = 0.0;
    // Warm-up: tracks are created (the table was allocated in `new`, so even this should be free).
    for i in 0..60 {
        let t = frame(i, &mut obs);
        total += est.update(t, &obs).mean.map_or(0.0, |m| m.0);
    }
    let mut corrected = 0;
    let mut min_fish = usize::MAX;
    let (allocs, ()) = counting_alloc::allocations_in(|| {
        for i in 60..360 {
            let t = frame(i, &mut obs);
            let s = est.update(t, &obs);
            corrected += s.boxes_corrected + s.depths_corrected;
            min_fish = min_fish.min(s.n_fish);
            total += s.mean.map_or(0.0, |m| m.0);
        }
    });
    assert!(min_fish >= 90, "{min_fish} fish in a frame");
    assert!(total.is_finite() && total > 0.0);
    assert!(corrected > 0, "the detectors must have run in the measured frames");
    assert_eq!(allocs, 0, "heap allocations during 300 steady-state frames of 100 tracks");
}
