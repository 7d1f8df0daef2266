//! Tracking quality on toy swarms (a measurement, not a test): `cargo bench --bench track_quality`.
//!
//! SORT vs `default`, the depth term (`depth_weight`) and detection every k-th frame, on seeded
//! [`toy_swarm`] sequences with [`synth_detections`] noise; metrics pooled over 3 seeds.

use fme::mot::MotMetrics;
use fme::track::TrackerConfig;
use fme::tune::{DetNoise, evaluate, pooled, synth_detections, toy_swarm};

fn run(cfg: TrackerConfig, fish: usize, noise: &DetNoise) -> MotMetrics {
    let ms: Vec<MotMetrics> = (1..=3u64)
        .map(|seed| {
            let seq = toy_swarm(fish, 300, seed);
            let dets = synth_detections(&seq, noise, seed);
            evaluate(cfg, &seq, &dets, noise.every)
        })
        .collect();
    pooled(&ms)
}

fn line(label: &str, m: &MotMetrics) {
    println!(
        "{label:44} IDF1 {:6.2}  MOTA {:6.2}  IDSW {:5}  FP {:5}  FN {:5}",
        m.idf1 * 100.0,
        m.mota * 100.0,
        m.num_switches,
        m.num_false_positives,
        m.num_misses
    );
}

fn main() {
    // `cargo test --all-targets` also runs bench targets: measure only under `cargo bench`.
    if !std::env::args().any(|a| a == "--bench") {
        println!("benchmark: run with `cargo bench --bench {}`", env!("CARGO_CRATE_NAME"));
        return;
    }
    let noise = DetNoise { miss: 0.1, jitter: 0.04, fp_per_frame: 1.0, ..DetNoise::default() };
    for fish in [10, 25, 50] {
        println!("toy swarm, {fish} fish, 300 frames x 3 seeds, miss 0.1, jitter 0.04, 1 FP/frame");
        line("  sort", &run(TrackerConfig::sort(), fish, &noise));
        line("  default", &run(TrackerConfig::default_preset(), fish, &noise));
        for w in [0.5, 1.0, 2.0] {
            let mut c = TrackerConfig::default_preset();
            c.depth_weight = w;
            line(&format!("  default + depth_weight {w} (5% depth noise)"), &run(c, fish, &noise));
        }
        for every in [2, 3] {
            let n = DetNoise { every, ..noise };
            line(&format!("  sort, detection every {every} frames"), &run(TrackerConfig::sort(), fish, &n));
            line(
                &format!("  default, detection every {every} frames"),
                &run(TrackerConfig::default_preset(), fish, &n),
            );
        }
    }
}
