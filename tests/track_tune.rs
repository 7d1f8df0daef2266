//! `fme tune` and the tuning library on a small in-memory swarm with crossings and occlusions.

use fme::cli::tune::{TuneArgs, TuneMetric, run};
use fme::geometry::PixelBox;
use fme::track::TrackerConfig;
use fme::track::tune::{DetNoise, GtObs, Rng, TuneSequence, evaluate, synth_detections};
use std::fmt::Write as _;

/// `n` fish swimming at 30 fps in a 960 x 540 image: wandering headings, bouncing off the edges,
/// nearer fish (larger) occlude farther ones; visibility is the uncovered fraction of the box.
fn swarm(n: usize, frames: u32, seed: u64) -> TuneSequence {
    let mut rng = Rng::new(seed);
    let (w_img, h_img) = (960.0, 540.0);
    let mut fish: Vec<[f64; 5]> = (0..n)
        .map(|_| {
            let depth = 1.0 + 3.0 * rng.uniform();
            [rng.uniform() * w_img, rng.uniform() * h_img, rng.uniform() * std::f64::consts::TAU, depth, 0.0]
        })
        .collect();
    let mut gt = Vec::new();
    for f in 1..=frames {
        let mut boxes = Vec::new();
        for (i, s) in fish.iter_mut().enumerate() {
            s[2] += 0.15 * rng.normal();
            let speed = 240.0 / s[3]; // px/s, nearer fish move faster on screen
            s[0] += speed / 30.0 * s[2].cos();
            s[1] += speed / 30.0 * s[2].sin();
            if s[0] < 0.0 || s[0] > w_img {
                s[2] = std::f64::consts::PI - s[2];
                s[0] = s[0].clamp(0.0, w_img);
            }
            if s[1] < 0.0 || s[1] > h_img {
                s[2] = -s[2];
                s[1] = s[1].clamp(0.0, h_img);
            }
            let (bw, bh) = (160.0 / s[3], 70.0 / s[3]);
            boxes.push((i, PixelBox::new(s[0] - bw / 2.0, s[1] - bh / 2.0, bw, bh), s[3]));
        }
        for &(i, b, z) in &boxes {
            // Covered fraction by nearer fish, approximated by the largest single overlap.
            let covered = boxes
                .iter()
                .filter(|o| o.2 < z)
                .map(|o| {
                    let iw = (b.right().min(o.1.right()) - b.x.max(o.1.x)).max(0.0);
                    let ih = (b.bottom().min(o.1.bottom()) - b.y.max(o.1.y)).max(0.0);
                    iw * ih / b.area()
                })
                .fold(0.0, f64::max);
            gt.push(GtObs { frame: f, id: i as i64 + 1, bbox: b, visibility: 1.0 - covered, depth: Some(z) });
        }
    }
    TuneSequence { name: format!("swarm{seed}"), fps: 30.0, frames, width: w_img, height: h_img, gt }
}

#[test]
fn default_beats_sort_on_synthetic_swarms() {
    let noise = DetNoise { miss: 0.1, jitter: 0.04, fp_per_frame: 1.0, ..DetNoise::default() };
    let (mut d_idf1, mut s_idf1, mut d_mota, mut s_mota) = (0.0, 0.0, 0.0, 0.0);
    for seed in 1..=3 {
        let seq = swarm(25, 150, seed);
        let dets = synth_detections(&seq, &noise, seed);
        let d = evaluate(TrackerConfig::default_preset(), &seq, &dets, 1);
        let s = evaluate(TrackerConfig::sort(), &seq, &dets, 1);
        d_idf1 += d.idf1;
        s_idf1 += s.idf1;
        d_mota += d.mota;
        s_mota += s.mota;
    }
    eprintln!("sum of 3 swarms: IDF1 default {d_idf1:.3} sort {s_idf1:.3}, MOTA default {d_mota:.3} sort {s_mota:.3}");
    assert!(d_idf1 > s_idf1 + 0.05, "IDF1 default {d_idf1:.3} vs sort {s_idf1:.3} (sum of 3)");
    assert!(d_mota > s_mota, "MOTA default {d_mota:.3} vs sort {s_mota:.3} (sum of 3)");
}

#[test]
fn synthetic_detections_are_seeded_and_noisy() {
    let seq = swarm(10, 50, 7);
    let noise = DetNoise::default();
    let a = synth_detections(&seq, &noise, 3);
    assert_eq!(a, synth_detections(&seq, &noise, 3));
    assert_ne!(a, synth_detections(&seq, &noise, 4));
    let n: usize = a.iter().map(Vec::len).sum();
    // 500 fish boxes, ~5% missed plus occlusion misses, ~25 false positives.
    assert!((380..=540).contains(&n), "{n}");
    let every3 = synth_detections(&seq, &DetNoise { every: 3, ..noise }, 3);
    assert!(every3.iter().enumerate().all(|(i, d)| i % 3 == 0 || d.is_empty()));
}

#[test]
fn tune_cli_runs_a_grid_on_sequence_folders() {
    let dir = tempfile::tempdir().expect("tempdir");
    let seq = swarm(8, 60, 11);
    let sdir = dir.path().join("swarm");
    std::fs::create_dir_all(sdir.join("gt")).expect("mkdir");
    std::fs::write(
        sdir.join("seqinfo.ini"),
        "[Sequence]\nname=swarm\nimDir=img1\nframeRate=30\nseqLength=60\nimWidth=960\nimHeight=540\nimExt=.jpg\n",
    )
    .expect("write");
    let mut gt = String::new();
    for g in &seq.gt {
        let b = g.bbox;
        writeln!(gt, "{},{},{},{},{},{},1,1,{}", g.frame, g.id, b.x, b.y, b.w, b.h, g.visibility).expect("fmt");
    }
    std::fs::write(sdir.join("gt").join("gt.txt"), gt).expect("write");
    let grid = dir.path().join("grid.toml");
    std::fs::write(&grid, "iou_thresh = [0.2, 0.5]\nmin_hits = [1, 3]\n").expect("write");
    let args = |grid: Option<std::path::PathBuf>| TuneArgs {
        sequences: vec![sdir.clone()],
        grid,
        metric: TuneMetric::Idf1,
        jobs: Some(2),
        preset: "default".into(),
        config: None,
        seed: 1,
        miss: 0.05,
        jitter: 0.05,
        fp_per_frame: 0.5,
        every: 1,
        min_visibility: 0.1,
        top: 4,
        quiet: true,
    };
    run(args(Some(grid))).expect("tune runs");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "iou = [0.2]\n").expect("write");
    let err = run(args(Some(bad))).expect_err("unknown key");
    assert!(format!("{err:#}").contains("unknown grid key `iou`"), "{err:#}");
    assert_eq!(fme::cli::exit_code(&err), 2);
    let mut a = args(None);
    a.sequences = vec![dir.path().join("nope")];
    let err = run(a).expect_err("missing folder");
    assert!(format!("{err:#}").contains("nope"), "{err:#}");
}
