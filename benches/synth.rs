//! Benchmark of `fme synth` (not a test): frames/s at 640x384 writing a full sequence (render,
//! JPEG, depth PNG, ground truth), with 20 and 100 fish, and render-only speed on one thread.
//!
//! Run: `cargo bench --bench synth` (or `make bench-synth`). Optional args: frames (default 150).

use fme::rng::Rng;
use fme::synth::motion::{self, Activity};
use fme::synth::render::{FrameBuffers, Renderer};
use fme::synth::scene::{self, Layout, Pond};
use fme::synth::{Preset, SynthConfig, WaterType, generate};
use std::time::Instant;

/// CPU seconds (user + system) this process has used so far, from `/proc/self/stat` (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15 (1-based).
    let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0 // USER_HZ is 100 on Linux
}

fn main() {
    // `cargo test --all-targets` (make test) runs bench targets without `--bench`: do nothing then,
    // benchmarks are not tests.
    if !std::env::args().any(|a| a == "--bench") {
        println!("synth benchmark skipped (run it with `cargo bench --bench synth`)");
        return;
    }
    let frames: u32 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(150);
    let tmp = std::env::temp_dir().join(format!("fme-synth-bench-{}", std::process::id()));
    println!("fme synth benchmark: 640x384, {frames} frames, {} rayon threads", rayon::current_num_threads());
    for fish in [20usize, 100] {
        let cfg = SynthConfig { preset: Preset::Swarm, fish, frames, seed: 7, ..SynthConfig::default() };
        let out = tmp.join(format!("swarm{fish}"));
        let t0 = Instant::now();
        let c0 = cpu_seconds();
        if let Err(e) = generate(&cfg, &out, true, &|_| {}) {
            eprintln!("generate failed: {e}");
            std::process::exit(1);
        }
        let s = t0.elapsed().as_secs_f64();
        let cpu_ms = (cpu_seconds() - c0) * 1000.0 / f64::from(frames);
        println!(
            "swarm {fish:>3} fish, full pipeline to disk: {:.1} frames/s ({s:.2} s wall; {cpu_ms:.1} CPU ms/frame, \
             i.e. {:.0} frames/s if {} cores were free)",
            f64::from(frames) / s,
            rayon::current_num_threads() as f64 * 1000.0 / cpu_ms.max(1e-9),
            rayon::current_num_threads()
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);

    // Render only (no encoding, no disk), single thread.
    let pond = Pond::default();
    let camera = scene::default_camera(&pond, 640, 384).expect("camera");
    let cubes = scene::reference_cubes(Layout::F, &pond, &camera);
    let r = Renderer::new(camera, 640, 384, pond, WaterType::C3, &cubes, 7);
    for fish in [20usize, 100] {
        let mut rng = Rng::new(7);
        let act = Activity::swarm(&mut rng);
        let m = motion::swarm(fish, frames as usize, 30.0, &pond, &act, fme::synth::fish::Cohort::default(), &mut rng);
        let mut buf = FrameBuffers::new(640, 384);
        let t0 = Instant::now();
        for (f, st) in m.states.iter().enumerate() {
            std::hint::black_box(r.render(f as u32 + 1, f as f64 / 30.0, &m.bodies, st, &mut buf));
        }
        let s = t0.elapsed().as_secs_f64();
        println!("swarm {fish:>3} fish, render only, 1 thread: {:.1} frames/s", f64::from(frames) / s);
        let rgb = image::RgbImage::from_raw(640, 384, buf.rgb.clone()).expect("rgb");
        let t0 = Instant::now();
        for _ in 0..frames {
            std::hint::black_box(fme::sequence::encode_jpeg(&rgb, fme::synth::generate::JPEG_QUALITY).expect("jpeg"));
        }
        let jpeg_ms = t0.elapsed().as_secs_f64() * 1000.0 / f64::from(frames);
        let depth = buf.depth_map(640, 384);
        let p = std::env::temp_dir().join(format!("fme-synth-bench-{}.png", std::process::id()));
        let t0 = Instant::now();
        for _ in 0..frames {
            fme::sequence::write_depth_png(&p, &depth).expect("png");
        }
        let png_ms = t0.elapsed().as_secs_f64() * 1000.0 / f64::from(frames);
        let _ = std::fs::remove_file(&p);
        println!("  per frame, 1 thread: JPEG encode {jpeg_ms:.2} ms, depth PNG write {png_ms:.2} ms");
    }
}
