//! `fme tune` and the tuning library on a small in-memory swarm with crossings and occlusions.

use fme::cli::tune::{TuneArgs, TuneMetric, run};
use fme::track::TrackerConfig;
use fme::tune::{DetNoise, evaluate, synth_detections, toy_swarm};
use std::fmt::Write as _;

#[test]
fn default_beats_sort_on_synthetic_swarms() {
    let noise = DetNoise { miss: 0.1, jitter: 0.04, fp_per_frame: 1.0, ..DetNoise::default() };
    let (mut d_idf1, mut s_idf1, mut d_mota, mut s_mota) = (0.0, 0.0, 0.0, 0.0);
    for seed in 1..=3 {
        let seq = toy_swarm(25, 150, seed);
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
    let seq = toy_swarm(10, 50, 7);
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
    let seq = toy_swarm(8, 60, 11);
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
    std::fs::write(&grid, "iou_threshold = [0.2, 0.5]\nmin_hits = [1, 3]\n").expect("write");
    let args = |grid: Option<std::path::PathBuf>| TuneArgs {
        sequences: vec![sdir.clone()],
        grid,
        metric: TuneMetric::Idf1,
        jobs: Some(2),
        preset: None,
        config: fme::cli::ConfigArgs::default(),
        seed: 1,
        miss: 0.05,
        jitter: 0.05,
        fp_per_frame: 0.5,
        depth_noise: 0.05,
        every: 1,
        min_visibility: 0.1,
        top: 4,
        quiet: true,
        detections: None,
    };
    run(args(Some(grid.clone()))).expect("tune runs");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "iou = [0.2]\n").expect("write");
    let err = run(args(Some(bad))).expect_err("unknown key");
    assert!(format!("{err:#}").contains("unknown grid key `iou`"), "{err:#}");
    assert_eq!(fme::cli::exit_code(&err), 2);
    // Real detections from a file in the sequence folder.
    std::fs::create_dir_all(sdir.join("det")).expect("mkdir");
    let mut det = String::new();
    for g in &seq.gt {
        let b = g.bbox;
        writeln!(det, "{},-1,{},{},{},{},0.9,-1,-1,-1", g.frame, b.x, b.y, b.w, b.h).expect("fmt");
    }
    std::fs::write(sdir.join("det").join("det.txt"), &det).expect("write");
    let mut a = args(None);
    a.grid = Some(grid.clone());
    a.detections = Some("det/det.txt".into());
    run(a).expect("tune on real detections");
    let d = fme::cli::tune::read_detections(&sdir.join("det").join("det.txt"), 60).expect("reads");
    assert_eq!(d.iter().map(Vec::len).sum::<usize>(), seq.gt.len());
    std::fs::write(sdir.join("det").join("det.txt"), format!("{det}61,-1,1,1,5,5,0.9\n")).expect("write");
    let err = fme::cli::tune::read_detections(&sdir.join("det").join("det.txt"), 60).expect_err("beyond");
    assert!(format!("{err:#}").contains("frame 61 is beyond"), "{err:#}");
    let mut a = args(None);
    a.sequences = vec![dir.path().join("nope")];
    let err = run(a).expect_err("missing folder");
    assert!(format!("{err:#}").contains("nope"), "{err:#}");
}
