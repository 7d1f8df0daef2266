//! Benchmark (not a test): per-frame cost of post-processing + motion for 100 tracks, the core step
//! the daemon runs on every frame. `cargo bench --bench core` (or `make bench-core`).

use fme::geometry::{Camera, Intrinsics, PixelBox, Pose, WorldPoint};
use fme::motion::{ActivityEstimator, AlongRay, MotionConfig, Observation};
use fme::postprocess::PostprocessConfig;
use fme::units::{Metres, Seconds};
use std::hint::black_box;
use std::time::Instant;

fn frame(i: usize, n: u32, obs: &mut Vec<Observation>) -> Seconds {
    obs.clear();
    let t = i as f64 / 30.0;
    for id in 0..n {
        let ph = id as f64 * 0.37;
        let w = 40.0 + 6.0 * (t * 9.0 + ph).sin() + if (i + id as usize).is_multiple_of(17) { 25.0 } else { 0.0 };
        let d = 2.0 + (id % 5) as f64 * 0.4 + 0.2 * (t + ph).sin()
            - if (i + id as usize).is_multiple_of(23) { 1.0 } else { 0.0 };
        let u = 320.0 + 200.0 * (t * 0.5 + ph).sin();
        let v = 192.0 + 120.0 * (t * 0.3 + ph).cos();
        obs.push(Observation { id, bbox: PixelBox::new(u - w / 2.0, v - 8.0, w, 16.0), depth: Some(Metres(d)) });
    }
    Seconds(t)
}

fn run(label: &str, n: u32, post: PostprocessConfig, along_ray: AlongRay) {
    let motion = MotionConfig { along_ray, ..MotionConfig::default() };
    let k = Intrinsics::from_hfov(640, 384, 80.0).expect("valid intrinsics");
    let pose = Pose::look_at(WorldPoint::new(3.0, -0.5, 1.5), WorldPoint::new(3.0, 3.0, 1.2), nalgebra::Vector3::z())
        .expect("valid pose");
    let mut est = ActivityEstimator::new(Camera { intrinsics: k, pose }, motion, post);
    let frames = 3000;
    // Pre-build the inputs so only the estimator is timed.
    let mut inputs: Vec<(Seconds, Vec<Observation>)> = Vec::with_capacity(frames);
    for i in 0..frames {
        let mut obs = Vec::with_capacity(n as usize);
        let t = frame(i, n, &mut obs);
        inputs.push((t, obs));
    }
    for (t, obs) in inputs.iter().take(100) {
        black_box(est.update(*t, obs));
    }
    let mut best = f64::INFINITY;
    let mut total = 0.0;
    let reps = 5;
    for rep in 0..reps {
        // Fresh estimator per repetition, warmed on 100 frames; time the remaining frames.
        let mut e = ActivityEstimator::new(*est.camera(), motion, post);
        for (t, obs) in inputs.iter().take(100) {
            black_box(e.update(*t, obs));
        }
        let start = Instant::now();
        for (t, obs) in inputs.iter().skip(100) {
            black_box(e.update(*t, obs));
        }
        let per = start.elapsed().as_secs_f64() / (frames - 100) as f64;
        best = best.min(per);
        total += per;
        let _ = rep;
    }
    println!(
        "{label:38} {n:4} tracks: {:8.2} us/frame best, {:8.2} us/frame mean of {reps} ({:.0} ns/track)",
        best * 1e6,
        total / reps as f64 * 1e6,
        best * 1e9 / n as f64
    );
}

fn main() {
    // `cargo test --all-targets` (make test) also runs harness-less benches: only measure under
    // `cargo bench`, which passes `--bench`.
    if !std::env::args().any(|a| a == "--bench") {
        println!("core benchmark: run it with `cargo bench --bench core` (make bench-core)");
        return;
    }
    // Each line twice: the speed along the line of sight from the depth change (the paper) and from
    // the heading (the default), so their costs compare on one machine in one run.
    for (name, along_ray) in [("depth", AlongRay::Depth), ("heading", AlongRay::Heading)] {
        let label = |what: &str| format!("{what}, {name}");
        run(&label("postprocess (eq. 3+4) + motion"), 100, PostprocessConfig::paper(), along_ray);
        run(&label("postprocess (eq. 4) + motion"), 100, PostprocessConfig::default(), along_ray);
        run(&label("motion only"), 100, PostprocessConfig::off(), along_ray);
        run(&label("postprocess (eq. 3+4) + motion"), 20, PostprocessConfig::paper(), along_ray);
        run(&label("postprocess (eq. 3+4) + motion"), 250, PostprocessConfig::paper(), along_ray);
    }
}
