//! ONNX Runtime against tract, in one run so that the ratios do not depend on how fast
//! the shared machine is today: per-inference time of the detector and the depth network
//! (preprocess + runtime + decode, one thread, a frame of the bundled recording), int8 and fp32;
//! and the pipeline's CPU at 30 fps (detector 10 Hz, depth 5 Hz, tracker, metric fit, eq. 1-5 over
//! the bundled recording, the daemon's defaults; capture and outputs excluded), as process CPU time
//! per second of video. Rows take turns (`FME_BENCH_ROUNDS`, default 3) so that a slow spell falls
//! on all of them. Needs both backends: `make bench-backends` (`cargo bench --features tract
//! --bench backends`).

#[path = "../tests/common/backend_outputs.rs"]
mod backend_outputs;

use std::time::Instant;

use backend_outputs::{ModelSet, frames};
use fme::capture::Frame;
use fme::infer::{Backend, DepthConfig, DepthNet, Detector, DetectorConfig, RgbFrame};
use fme::pipeline::{FishPipeline, Pipeline};
use fme::units::Seconds;

fn env_count(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|s| s.parse().ok()).filter(|&n| n > 0).unwrap_or(default)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// User + system CPU time of this process, seconds (all threads: ONNX Runtime's workers too).
fn process_cpu_s() -> f64 {
    let mut ru = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes a rusage into the valid, zeroed buffer.
    let ru = unsafe {
        if libc::getrusage(libc::RUSAGE_SELF, ru.as_mut_ptr()) != 0 {
            return f64::NAN;
        }
        ru.assume_init()
    };
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
    t(ru.ru_utime) + t(ru.ru_stime)
}

struct Nets {
    backend: Backend,
    set: ModelSet,
    det: Detector,
    depth: DepthNet,
    det_ms: Vec<f64>,
    depth_ms: Vec<f64>,
    cpu_pct: Vec<f64>,
}

fn open(backend: Backend, set: ModelSet) -> Nets {
    let cfg = set.config();
    let d = DetectorConfig { model: set.detector(), ..cfg.detector.clone() };
    let z = DepthConfig { model: set.depth(), ..cfg.depth.clone() };
    let det = Detector::open_with(&d, d.session(), backend).unwrap_or_else(|e| panic!("{backend} detector: {e}"));
    let depth = DepthNet::open_with(&z, z.session(), backend).unwrap_or_else(|e| panic!("{backend} depth: {e}"));
    Nets { backend, set, det, depth, det_ms: Vec::new(), depth_ms: Vec::new(), cpu_pct: Vec::new() }
}

fn pipeline_cpu_pct(backend: Backend, set: ModelSet, frames: &[Frame]) -> f64 {
    let cal =
        fme::calibration::load(&std::path::Path::new(backend_outputs::SEQ).join("meta.json")).expect("calibration");
    let mut p = FishPipeline::with_backend(&set.config().pipeline(), Some(cal), backend).expect("pipeline");
    let c0 = process_cpu_s();
    for f in frames {
        p.process(f).expect("frame processed");
    }
    let video_s = frames.len() as f64 / 30.0;
    100.0 * (process_cpu_s() - c0) / video_s
}

fn main() {
    // `cargo test --all-targets` also runs harness-less benches (without `--bench`): skip there.
    if !std::env::args().any(|a| a == "--bench") {
        println!("backends bench: skipped (run `make bench-backends`)");
        return;
    }
    let rounds = env_count("FME_BENCH_ROUNDS", 3);
    let runs = env_count("FME_BENCH_RUNS", 10);
    let frames = frames();
    let mut rgb = Vec::new();
    let (w, h) = frames[60].to_rgb_into(&mut rgb).expect("frame decodes");
    let frame = RgbFrame::new(w, h, &rgb).expect("rgb frame");
    let mut rows: Vec<Nets> = [ModelSet::Int8, ModelSet::Fp32]
        .into_iter()
        .flat_map(|set| [Backend::Ort, Backend::Tract].map(|b| open(b, set)))
        .collect();
    println!(
        "backends bench: frame {w}x{h} of tests/data/swarm20, {rounds} rounds of {runs} timed runs per network and \
         one pass of the 120-frame recording per row (rows take turns); one thread per network"
    );
    for _ in 0..rounds {
        for r in rows.iter_mut() {
            // One untimed run first (caches, lazily built plans).
            for i in 0..=runs {
                let t0 = Instant::now();
                r.det.detect(&frame, Seconds(i as f64)).expect("detector runs");
                let t1 = Instant::now();
                r.depth.estimate(&frame, Seconds(i as f64)).expect("depth runs");
                let t2 = Instant::now();
                if i > 0 {
                    r.det_ms.push((t1 - t0).as_secs_f64() * 1e3);
                    r.depth_ms.push((t2 - t1).as_secs_f64() * 1e3);
                }
            }
            r.cpu_pct.push(pipeline_cpu_pct(r.backend, r.set, &frames));
        }
    }
    println!("{:<6} {:<12} {:>12} {:>12} {:>16}", "models", "backend", "detector ms", "depth ms", "CPU % at 30 fps");
    let mut summary = Vec::new();
    for r in &rows {
        let (d, z, c) = (median(r.det_ms.clone()), median(r.depth_ms.clone()), median(r.cpu_pct.clone()));
        println!("{:<6} {:<12} {d:>12.2} {z:>12.2} {c:>16.1}", r.set.name(), r.backend.name());
        summary.push((r.set, r.backend, d, z, c));
    }
    println!("ratios tract / onnxruntime (same run):");
    for set in [ModelSet::Int8, ModelSet::Fp32] {
        let get = |b: Backend| summary.iter().find(|s| s.0 == set && s.1 == b).copied();
        if let (Some(o), Some(t)) = (get(Backend::Ort), get(Backend::Tract)) {
            println!(
                "{:<6} detector {:.2}x, depth {:.2}x, pipeline CPU {:.2}x",
                set.name(),
                t.2 / o.2,
                t.3 / o.3,
                t.4 / o.4
            );
        }
    }
    let get = |set, b| summary.iter().find(|s| s.0 == set && s.1 == b).map_or(f64::NAN, |s| s.4);
    println!(
        "tract fp32 / tract int8 pipeline CPU: {:.2}x; tract fp32 / onnxruntime int8: {:.2}x",
        get(ModelSet::Fp32, Backend::Tract) / get(ModelSet::Int8, Backend::Tract),
        get(ModelSet::Fp32, Backend::Tract) / get(ModelSet::Int8, Backend::Ort)
    );
}
