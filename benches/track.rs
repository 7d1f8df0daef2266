//! Tracker speed (a benchmark, not a test): `cargo bench --bench track` or `make bench-track`.
//!
//! 1. Update time per frame with 10, 50 and 200 moving objects (steady state, both presets).
//! 2. Frames per second over every mot15 `det.txt` (directory from `FME_MOT15`, default
//!    `../shared/benchmarks/mot15` beside the repository; skipped when absent), parsing excluded, median of 5 runs.

use fme::geometry::PixelBox;
use fme::sequence::mot_text::{self, ReadOptions};
use fme::track::{Detection, Tracker, TrackerConfig};
use fme::units::Seconds;
use std::time::Instant;

fn objects(n: usize, k: usize, out: &mut Vec<Detection>) {
    out.clear();
    for i in 0..n {
        let (row, col) = (i / 20, i % 20);
        let x = col as f64 * 60.0 + (k as f64 * 0.05 + i as f64).sin() * 20.0;
        let y = row as f64 * 50.0 + (k as f64 * 0.03 + i as f64).cos() * 15.0;
        out.push(Detection::new(PixelBox::new(x, y, 40.0, 30.0), 0.6 + 0.3 * ((i + k) % 3) as f64 / 2.0));
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // `cargo test --all-targets` also runs bench targets: measure only under `cargo bench`.
    if !std::env::args().any(|a| a == "--bench") {
        println!("benchmark: run with `cargo bench --bench {}`", env!("CARGO_CRATE_NAME"));
        return;
    }
    println!("update time per frame (steady state, 2000 frames after 100 warm-up, median of 5):");
    for (name, cfg) in [("sort", TrackerConfig::sort()), ("default", TrackerConfig::default_preset())] {
        for n in [10usize, 50, 200] {
            let mut runs = Vec::new();
            let mut buf = Vec::with_capacity(256);
            for _ in 0..5 {
                let mut t = Tracker::new(cfg);
                for k in 0..100 {
                    objects(n, k, &mut buf);
                    let _ = t.update(Seconds(k as f64 / 30.0), &buf);
                }
                let start = Instant::now();
                for k in 100..2100 {
                    objects(n, k, &mut buf);
                    let _ = t.update(Seconds(k as f64 / 30.0), &buf);
                }
                runs.push(start.elapsed().as_secs_f64() / 2000.0);
            }
            println!("  {name:8} {n:4} detections: {:8.2} us/frame", median(runs) * 1e6);
        }
    }
    let dir = std::env::var("FME_MOT15")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/benchmarks/mot15").into());
    let mut seqs = Vec::new();
    if let Ok(rd) = std::fs::read_dir(&dir) {
        let mut paths: Vec<_> =
            rd.filter_map(|e| e.ok()).map(|e| e.path().join("det.txt")).filter(|p| p.is_file()).collect();
        paths.sort();
        for p in paths {
            match mot_text::read_file(&p, ReadOptions { require_sorted: true }) {
                Ok(mut rows) => {
                    // Every frame 1..=last, empty ones included (as SORT's loop runs them).
                    let last = rows.iter().map(|r| r.frame).max().unwrap_or(0) as usize;
                    let mut dets: Vec<Vec<Detection>> = vec![Vec::new(); last];
                    for (f, r) in mot_text::group_by_frame(&mut rows) {
                        dets[f as usize - 1] = rows[r].iter().map(|d| Detection::new(d.bbox, d.score)).collect();
                    }
                    seqs.push(dets);
                }
                Err(e) => eprintln!("skipping: {e}"),
            }
        }
    }
    if seqs.is_empty() {
        println!("mot15: no det.txt under {dir}; set FME_MOT15");
        return;
    }
    let total: usize = seqs.iter().map(Vec::len).sum();
    for (name, cfg) in [("sort", TrackerConfig::sort()), ("default", TrackerConfig::default_preset())] {
        let mut runs = Vec::new();
        let mut out = 0usize;
        for _ in 0..5 {
            let start = Instant::now();
            for s in &seqs {
                let mut t = Tracker::new(cfg);
                for (k, d) in s.iter().enumerate() {
                    out += t.update(Seconds(k as f64 / 30.0), d).map_or(0, <[_]>::len);
                }
            }
            runs.push(start.elapsed().as_secs_f64());
        }
        let s = median(runs);
        println!(
            "mot15 {name:8}: {} sequences, {total} frames in {:.4} s = {:.0} frames/s ({} track boxes)",
            seqs.len(),
            s,
            total as f64 / s,
            out / 5
        );
    }
}
