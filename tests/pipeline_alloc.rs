//! The real pipeline allocates nothing on frames without inference (tracker prediction, eq. 3-5 on
//! every camera frame), and a bounded number on detector/depth frames (JPEG decode and the runtime's
//! outputs), not growing over time. Counting global allocator, on this test's thread only. Both
//! backends: ONNX Runtime allocates little on the caller's thread; tract allocates its tensors on
//! every run (its bound is looser, but it must not grow either).

use fme::capture::{Frame, FrameSource, RecordedSource};
use fme::config::Config;
use fme::pipeline::FishPipeline;
use fme::pipeline::Pipeline;
use fme::units::Seconds;
use std::path::Path;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;

#[test]
fn prediction_frames_allocate_nothing_and_inference_frames_a_bounded_amount() {
    let seq = Path::new("tests/data/swarm20");
    let mut cfg = Config::default();
    cfg.source.path = seq.into();
    let cal = fme::calibration::load(&seq.join("meta.json")).expect("calibration");
    let mut p = FishPipeline::new(&cfg.pipeline(), Some(cal)).expect("pipeline");
    let mut src = RecordedSource::open(seq, false, false).expect("open");
    let mut frames: Vec<Frame> = Vec::new();
    while let Ok(f) = src.next_frame(Vec::new()) {
        frames.push(f);
    }
    // Warm-up: two passes (the second with shifted timestamps) fill every buffer and track table.
    for f in &frames {
        p.process(f).expect("frame");
    }
    let shift = frames.len() as f64 / 30.0;
    let mut per_kind = [(0u64, 0u64); 2]; // (frames, allocations): [prediction only, with inference]
    let mut per_pass = [0u64; 2]; // allocations on inference frames, per pass
    for pass in 1..=2u32 {
        for (i, f) in frames.iter().enumerate() {
            let mut f = f.clone();
            f.timestamp = Seconds(f.timestamp.0 + shift * f64::from(pass));
            // 30 fps, detector 10 Hz and depth 5 Hz: every 3rd frame runs inference.
            let inference = i % 3 == 0;
            let (n, r) = counting_alloc::allocations_in(|| p.process(&f));
            r.expect("frame");
            let k = &mut per_kind[usize::from(inference)];
            k.0 += 1;
            k.1 += n;
            if inference {
                per_pass[pass as usize - 1] += n;
            }
        }
    }
    assert!(per_kind[0].0 >= 150 && per_kind[1].0 >= 75, "{per_kind:?}");
    assert_eq!(per_kind[0].1, 0, "prediction-only frames must not allocate ({} frames)", per_kind[0].0);
    let per_inference = per_kind[1].1 as f64 / per_kind[1].0 as f64;
    let backend = fme::infer::Backend::DEFAULT;
    let bound = if backend.name() == "tract" { TRACT_BOUND } else { 200.0 };
    assert!(per_inference < bound, "allocations per inference frame with {backend}: {per_inference}");
    assert!(per_pass[1] <= per_pass[0] + per_pass[0] / 20, "allocations grow from pass to pass: {per_pass:?}");
    println!("allocations per inference frame (JPEG decode + {backend}): {per_inference:.1}");
}

/// tract's allocations per inference frame, with room: it builds its output tensors on every run.
const TRACT_BOUND: f64 = 1000.0;
