//! Detector and depth-network latency per frame (preprocess + ONNX Runtime + decode), fp32 vs
//! int8, 1 vs 2 intra-op threads, idle worker threads sleeping (fme's setting: the tracker needs the
//! core) vs spinning (lower latency, more CPU). A benchmark, not a test: `make bench-infer` or
//! `cargo bench --bench infer`. Models: the bundled ones in models/ (FME_BENCH_MODELS names another
//! folder with the same file names); FME_BENCH_FRAME may
//! name a frame image (default: a synthetic 640x384 frame); FME_BENCH_RUNS sets the timed runs.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fme::infer::{DepthConfig, DepthNet, Detector, DetectorConfig, RgbFrame, SessionOptions};
use fme::units::Seconds;

fn frame() -> image::RgbImage {
    if let Ok(p) = std::env::var("FME_BENCH_FRAME") {
        match image::open(&p) {
            Ok(img) => return img.to_rgb8(),
            Err(e) => eprintln!("FME_BENCH_FRAME {p}: {e}; using a synthetic frame"),
        }
    }
    image::RgbImage::from_fn(640, 384, |x, y| {
        let fish = ((x as i32 - 320).pow(2) / 900 + (y as i32 - 190).pow(2) / 100) < 1;
        if fish { image::Rgb([190, 185, 170]) } else { image::Rgb([20 + (y / 8) as u8, 80 + (x / 10) as u8, 120]) }
    })
}

fn stats(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[(v.len() * 9) / 10])
}

fn main() {
    // `cargo test --all-targets` also runs harness-less benches (without `--bench`): skip there.
    if !std::env::args().any(|a| a == "--bench") {
        println!("infer bench: skipped (run `cargo bench --bench infer` or `make bench-infer`)");
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let runs: usize = std::env::var("FME_BENCH_RUNS").ok().and_then(|s| s.parse().ok()).unwrap_or(50);
    let img = frame();
    let f = RgbFrame::from(&img);
    println!(
        "infer bench: frame {}x{}, {runs} timed runs after 5 warm-ups, median / p90 ms",
        img.width(),
        img.height()
    );
    println!("{:<28} {:>7} {:>5} {:>10} {:>10} {:>14}", "model", "threads", "spin", "median", "p90", "preprocess");
    for name in ["fish_det_fp32.onnx", "fish_det_int8.onnx", "fish_depth_fp32.onnx", "fish_depth_int8.onnx"] {
        let dir = std::env::var_os("FME_BENCH_MODELS").map(PathBuf::from).unwrap_or_else(|| root.join("models"));
        let path = dir.join(name);
        if !path.exists() {
            println!("{name:<28} (missing, skipped)");
            continue;
        }
        for threads in [1, 2] {
            for spin in [false, true] {
                let opts = SessionOptions { intra_threads: threads, spin };
                let on = if spin { "on" } else { "off" };
                match bench_one(&path, opts, runs, &f) {
                    Ok((m, p, pre)) => println!("{name:<28} {threads:>7} {on:>5} {m:>10.2} {p:>10.2} {pre:>14.3}"),
                    Err(e) => println!("{name:<28} {threads:>7} {on:>5} error: {e}"),
                }
            }
        }
    }
}

fn bench_one(path: &Path, opts: SessionOptions, runs: usize, f: &RgbFrame<'_>) -> Result<(f64, f64, f64), String> {
    let is_det = path.file_name().is_some_and(|n| n.to_string_lossy().contains("_det_"));
    let mut times = Vec::with_capacity(runs);
    let mut pre = Vec::with_capacity(runs);
    if is_det {
        let cfg = DetectorConfig { model: path.to_path_buf(), ..Default::default() };
        let mut d = Detector::open(&cfg, opts).map_err(|e| e.to_string())?;
        for i in 0..runs + 5 {
            let t = Instant::now();
            d.detect(f, Seconds(i as f64)).map_err(|e| e.to_string())?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            d.preprocess(f);
            let p = t.elapsed().as_secs_f64() * 1e3;
            if i >= 5 {
                times.push(ms);
                pre.push(p);
            }
        }
    } else {
        let cfg = DepthConfig { model: path.to_path_buf(), ..Default::default() };
        let mut d = DepthNet::open(&cfg, opts).map_err(|e| e.to_string())?;
        for i in 0..runs + 5 {
            let t = Instant::now();
            d.estimate(f, Seconds(i as f64)).map_err(|e| e.to_string())?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            d.preprocess(f);
            let p = t.elapsed().as_secs_f64() * 1e3;
            if i >= 5 {
                times.push(ms);
                pre.push(p);
            }
        }
    }
    let (m, p90) = stats(times);
    Ok((m, p90, stats(pre).0))
}
