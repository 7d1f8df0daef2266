//! Detector and depth-network latency per frame (preprocess + ONNX Runtime + decode), fp32 vs
//! int8, 1 vs 2 intra-op threads, idle worker threads sleeping (fme's setting: the tracker needs the
//! core) vs spinning (lower latency, more CPU). A benchmark, not a test: `make bench-infer` or
//! `cargo bench --bench infer`.
//!
//! Every row's session is opened first and the rows then take turns, `FME_BENCH_ROUNDS` rounds
//! (default 5) of `FME_BENCH_RUNS / FME_BENCH_ROUNDS` timed runs each (`FME_BENCH_RUNS`, default 50),
//! so a slow spell of a shared machine falls on all rows alike; the first run of every turn is not
//! timed (a spinning session's threads may still hold the cores when the next row starts).
//! Models: the bundled ones in models/; `FME_BENCH_MODELS` names another folder with the same file
//! names, or several separated by `:` to compare model files turn by turn. `FME_BENCH_FRAME` may
//! name a frame image (default: a synthetic 640x384 frame).

use std::path::{Path, PathBuf};
use std::time::Instant;

use fme::infer::{DepthConfig, DepthNet, Detector, DetectorConfig, RgbFrame, SessionOptions};
use fme::units::Seconds;

const MODELS: [&str; 4] = ["fish_det_fp32.onnx", "fish_det_int8.onnx", "fish_depth_fp32.onnx", "fish_depth_int8.onnx"];

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

fn env_count(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|s| s.parse().ok()).filter(|&n| n > 0).unwrap_or(default)
}

/// One network behind the call fme makes per frame.
enum Net {
    Det(Detector),
    Depth(DepthNet),
}

impl Net {
    fn open(path: &Path, opts: SessionOptions) -> Result<Self, String> {
        let is_det = path.file_name().is_some_and(|n| n.to_string_lossy().contains("_det_"));
        Ok(if is_det {
            let cfg = DetectorConfig { model: path.to_path_buf(), ..Default::default() };
            Net::Det(Detector::open(&cfg, opts).map_err(|e| e.to_string())?)
        } else {
            let cfg = DepthConfig { model: path.to_path_buf(), ..Default::default() };
            Net::Depth(DepthNet::open(&cfg, opts).map_err(|e| e.to_string())?)
        })
    }

    /// Milliseconds of one whole call (preprocess + inference + decode), then of preprocessing alone.
    fn run(&mut self, f: &RgbFrame<'_>, i: usize) -> Result<(f64, f64), String> {
        let t = Instant::now();
        match self {
            Net::Det(d) => d.detect(f, Seconds(i as f64)).map(|_| ()).map_err(|e| e.to_string())?,
            Net::Depth(d) => d.estimate(f, Seconds(i as f64)).map(|_| ()).map_err(|e| e.to_string())?,
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        match self {
            Net::Det(d) => {
                d.preprocess(f);
            }
            Net::Depth(d) => d.preprocess(f),
        }
        Ok((ms, t.elapsed().as_secs_f64() * 1e3))
    }
}

struct Row {
    label: String,
    threads: usize,
    spin: bool,
    net: Result<Net, String>,
    times: Vec<f64>,
    pre: Vec<f64>,
}

fn main() {
    // `cargo test --all-targets` also runs harness-less benches (without `--bench`): skip there.
    if !std::env::args().any(|a| a == "--bench") {
        println!("infer bench: skipped (run `cargo bench --bench infer` or `make bench-infer`)");
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let rounds = env_count("FME_BENCH_ROUNDS", 5);
    let per_turn = env_count("FME_BENCH_RUNS", 50).div_ceil(rounds);
    let dirs: Vec<PathBuf> = match std::env::var("FME_BENCH_MODELS") {
        Ok(v) => v.split(':').filter(|s| !s.is_empty()).map(PathBuf::from).collect(),
        Err(_) => vec![root.join("models")],
    };
    let img = frame();
    let f = RgbFrame::from(&img);
    println!(
        "infer bench: frame {}x{}, {} timed runs per row in {rounds} rounds (rows take turns), median / p90 ms",
        img.width(),
        img.height(),
        per_turn * rounds
    );
    let mut rows = Vec::new();
    for name in MODELS {
        for dir in &dirs {
            let path = dir.join(name);
            let label = if dirs.len() > 1 { format!("{}/{name}", dir.display()) } else { name.to_string() };
            if !path.exists() {
                println!("{label} (missing, skipped)");
                continue;
            }
            for threads in [1, 2] {
                for spin in [false, true] {
                    let mut net = Net::open(&path, SessionOptions { intra_threads: threads, spin });
                    if let Ok(n) = net.as_mut() {
                        for i in 0..5 {
                            if let Err(e) = n.run(&f, i) {
                                net = Err(e);
                                break;
                            }
                        }
                    }
                    rows.push(Row { label: label.clone(), threads, spin, net, times: Vec::new(), pre: Vec::new() });
                }
            }
        }
    }
    for _ in 0..rounds {
        for row in rows.iter_mut() {
            let Ok(net) = row.net.as_mut() else { continue };
            for i in 0..=per_turn {
                match net.run(&f, i) {
                    Ok((ms, pre)) if i > 0 => {
                        row.times.push(ms);
                        row.pre.push(pre);
                    }
                    Ok(_) => {}
                    Err(e) => {
                        row.net = Err(e);
                        break;
                    }
                }
            }
        }
    }
    let width = rows.iter().map(|r| r.label.len()).max().unwrap_or(0).max(28);
    println!("{:<width$} {:>7} {:>5} {:>10} {:>10} {:>14}", "model", "threads", "spin", "median", "p90", "preprocess");
    for row in rows {
        let on = if row.spin { "on" } else { "off" };
        let (label, threads) = (&row.label, row.threads);
        match row.net {
            Ok(_) => {
                let (m, p) = stats(row.times);
                let pre = stats(row.pre).0;
                println!("{label:<width$} {threads:>7} {on:>5} {m:>10.2} {p:>10.2} {pre:>14.3}");
            }
            Err(e) => println!("{label:<width$} {threads:>7} {on:>5} error: {e}"),
        }
    }
}
