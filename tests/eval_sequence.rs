//! `fme eval` end to end on a small sequence written here: known trajectories rendered into exact
//! depth maps, so the expected speeds are known; and bad input (missing files, malformed rows, NaN)
//! that must fail with the file and line named and a non-zero exit.

use fme::config::Config;
use fme::eval::{DepthChoice, EvalOptions, evaluate};
use fme::geometry::{Camera, Intrinsics, PixelBox, Pose, WorldPoint};
use fme::metric::{DepthSample, FitMethod};
use fme::sequence::{
    CameraMeta, DepthMap, GeneratorMeta, GtBox, Meta, ReferenceObject, SeqInfo, Sequence, SequenceWriter, StagedDir,
    WaterMeta, WorldRow,
};
use fme::units::Metres;
use fme::units::Seconds;
use nalgebra::Vector3;
use std::path::Path;
use std::process::Command;

const W: u32 = 320;
const H: u32 = 192;
const N: u32 = 60;
const FPS: f64 = 30.0;

fn camera() -> Camera {
    let intrinsics = Intrinsics::from_hfov(W, H, 80.0).unwrap();
    let pose = Pose::look_at(WorldPoint::new(3.0, -0.5, 1.5), WorldPoint::new(3.0, 3.0, 1.5), Vector3::z()).unwrap();
    Camera { intrinsics, pose }
}

/// Fish `i`'s body centre at time `t`: constant velocity, and its velocity. Fish 3 (only in
/// [`write_sequence_hidden`]) swims 1 m behind fish 0 (3 m deep against 2 m), 0.25 m to the right of
/// its line of sight and 1.5 times as fast, so it stays in the same place relative to fish 0 in the
/// image: fish 0's box covers about half of fish 3's box core all the time.
fn fish(i: u32, t: f64) -> (WorldPoint, Vector3<f64>) {
    let v = [
        Vector3::new(0.4, 0.0, 0.0),
        Vector3::new(-0.2, 0.3, 0.1),
        Vector3::new(0.1, -0.25, 0.0),
        Vector3::new(0.6, 0.0, 0.0),
    ][i as usize];
    let p0 = [
        Vector3::new(2.0, 1.5, 1.4),
        Vector3::new(3.8, 0.8, 1.2),
        Vector3::new(3.0, 2.5, 1.8),
        Vector3::new(1.75, 2.5, 1.4),
    ][i as usize];
    (WorldPoint(p0 + v * t), v)
}

fn references() -> Vec<ReferenceObject> {
    let spots = [[1.4, 2.0, 0.6], [4.2, 1.4, 0.9], [2.2, 3.2, 2.2], [3.9, 2.8, 1.0], [2.9, 0.9, 2.1], [3.5, 3.4, 1.6]];
    spots
        .iter()
        .enumerate()
        .map(|(i, c)| ReferenceObject {
            id: i as u32 + 1,
            size_m: 0.1,
            center_w: *c,
            front_face_center_w: [c[0], c[1] - 0.05, c[2]],
        })
        .collect()
}

/// Writes the sequence: background wall at 4.5 m depth, reference squares and fish boxes painted
/// at their depths (fish as flat rectangles: the box centre's depth is the body's camera z).
fn write_sequence(target: &Path) {
    write_sequence_with(target, false, 3)
}

/// The sequence plus fish 3, half hidden behind fish 0.
fn write_sequence_hidden(target: &Path) {
    write_sequence_with(target, false, 4)
}

/// `flick`: every fourth frame each fish's box grows by 40% to the right for one frame (a tail swing),
/// the box-centre fluctuation eq. 3 exists for.
fn write_sequence_with(target: &Path, flick: bool, n_fish: u32) {
    let cam = camera();
    let stage = StagedDir::create(target, false).unwrap();
    let w = SequenceWriter::new(stage.path()).unwrap();
    let (mut gt, mut world) = (Vec::new(), Vec::new());
    let refs = references();
    for f in 1..=N {
        let t = f64::from(f - 1) / FPS;
        let img = image::RgbImage::from_pixel(W, H, image::Rgb([10, 80, 90]));
        w.write_frame(f, &img, 80).unwrap();
        let mut d = DepthMap::new(W, H);
        d.mm.fill(4500);
        let mut paint = |b: PixelBox, z: f64| {
            for v in b.y.max(0.0) as u32..(b.bottom().min(H as f64)) as u32 {
                for u in b.x.max(0.0) as u32..(b.right().min(W as f64)) as u32 {
                    d.mm[(v * W + u) as usize] = DepthMap::encode(z);
                }
            }
        };
        // Paint far fish first so nearer ones cover them.
        let mut fishes: Vec<(u32, WorldPoint, Vector3<f64>, f64)> = (0..n_fish)
            .map(|i| {
                let (p, v) = fish(i, t);
                (i, p, v, cam.pose.to_camera(&p).depth().0)
            })
            .collect();
        fishes.sort_by(|a, b| b.3.total_cmp(&a.3));
        for (i, p, v, z) in fishes {
            let px = cam.world_to_pixel(&p).unwrap();
            let size = 0.35 * cam.intrinsics.fx / z;
            let mut bbox = PixelBox::from_center(px, size, size * 0.4);
            paint(bbox, z);
            if flick && (f + i) % 4 == 0 {
                bbox.w *= 1.4;
            }
            gt.push(GtBox { frame: f, id: i + 1, bbox, visibility: 1.0 });
            world.push(WorldRow {
                frame: f,
                id: i + 1,
                position: p,
                velocity: v,
                length: Metres(0.35),
                visibility: 1.0,
            });
        }
        // References last, so a fish never hides one (hidden references are the robust fit's job).
        for r in &refs {
            let p = WorldPoint(Vector3::from(r.front_face_center_w));
            let px = cam.world_to_pixel(&p).unwrap();
            paint(PixelBox::from_center(px, 7.0, 7.0), cam.pose.to_camera(&p).depth().0);
        }
        w.write_depth(f, &d).unwrap();
    }
    gt.sort_by_key(|g| (g.frame, g.id));
    world.sort_by_key(|g| (g.frame, g.id));
    let meta = Meta {
        fps: FPS,
        width: W,
        height: H,
        frames: N,
        seed: 3,
        preset: "test".into(),
        generator: GeneratorMeta { name: "eval-test".into(), version: "0".into() },
        camera: CameraMeta::from_camera(&cam),
        water: WaterMeta { kind: "3C".into(), attenuation_per_m: [0.342, 0.198, 0.223], backscatter: [0.1, 0.4, 0.4] },
        reference_objects: refs,
        layout: Some("F".into()),
        pond_size_m: Some([6.0, 4.0, 3.0]),
        fish: Some(n_fish),
    };
    let info = SeqInfo {
        name: "evaltest".into(),
        im_dir: "img1".into(),
        frame_rate: FPS,
        seq_length: N,
        im_width: W,
        im_height: H,
        im_ext: ".jpg".into(),
    };
    w.finish(&info, &meta, &gt, &world).unwrap();
    stage.commit().unwrap();
}

fn summary(r: &fme::eval::EvalReport) -> String {
    let mut j = serde_json::to_value(r).unwrap();
    j.as_object_mut().unwrap().remove("series");
    j.to_string()
}

fn fme() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fme"))
}

/// The boxes written here keep one size whatever way the fish swims (they are not drawn as swimming
/// fish), so tests that check exact speeds take the speed along the line of sight from the depth, as
/// the paper does (`motion.along_ray = "depth"`); `tests/eval_recorded.rs` checks the heading method
/// on rendered fish. They check the estimator's arithmetic, so the inputs are read on every frame,
/// at the box centre, without the depth smoothing a depth network needs.
fn depth_chord() -> Config {
    let mut c = Config::default();
    c.motion.along_ray = fme::motion::AlongRay::Depth;
    c.detector.rate_hz = 0.0;
    c.depth.rate_hz = 0.0;
    c.depth.sample = DepthSample::Centre;
    c.postprocess.depth_smoothing_s = Seconds(0.0);
    c
}

/// `depth_chord()` on the command line.
const EXACT: [&str; 10] = [
    "--every-frame",
    "--along-ray",
    "depth",
    "--depth-sample",
    "centre",
    "--set",
    "postprocess.depth_smoothing_s=0",
    "--set",
    "motion.smoothing_s=2",
    "--json",
];

#[test]
fn gt_boxes_and_gt_depth_recover_known_speeds() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    let seq = Sequence::open(&dir).unwrap();
    let r = evaluate(&seq, &depth_chord(), &EvalOptions::default()).unwrap();
    // Each fish enters the mean once tracked `min_age` (1 s = 30 frames): frames 31-60 are scored.
    assert_eq!(r.frames, (N - 30) as usize);
    // True mean speed: (0.4 + |(-0.2, 0.3, 0.1)| + |(0.1, -0.25, 0)|) / 3, constant.
    let truth = (0.4 + (0.04f64 + 0.09 + 0.01).sqrt() + (0.01f64 + 0.0625).sqrt()) / 3.0;
    assert!((r.mean_true_mps - truth).abs() < 1e-6);
    // Only millimetre depth quantisation and box rounding to 1/100 px remain.
    assert!(r.speed_rmse_mps < 0.03, "{}", summary(&r));
    assert!((r.mean_est_mps - truth).abs() < 0.02, "{}", summary(&r));
    assert!(r.depth_rmse_m.is_none());
    assert_eq!(r.series.len(), N as usize);
}

#[test]
fn tracker_boxes_are_scored_for_tracking_and_speed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    let seq = Sequence::open(&dir).unwrap();
    let opts = EvalOptions { boxes: fme::eval::BoxesChoice::Tracker, ..Default::default() };
    let r = evaluate(&seq, &depth_chord(), &opts).unwrap();
    let m = r.mot.expect("tracking metrics for --boxes tracker");
    // Three well separated fish, 5% misses and jitter: the tracker keeps them apart.
    assert!(m.idf1 > 0.8 && m.mota > 0.7, "{}", summary(&r));
    assert!(r.detection.is_none());
    let j = serde_json::to_value(&r).unwrap();
    for k in ["idf1", "mota", "motp", "id_switches"] {
        assert!(j.get(k).is_some_and(|v| v.is_number()), "{k} missing at the top level of {j}");
    }
    let truth = (0.4 + (0.04f64 + 0.09 + 0.01).sqrt() + (0.01f64 + 0.0625).sqrt()) / 3.0;
    assert!((r.mean_est_mps - truth).abs() < 0.05, "{}", summary(&r));
    let gt = evaluate(&seq, &depth_chord(), &EvalOptions::default()).unwrap();
    assert!(r.speed_rmse_mps > gt.speed_rmse_mps * 0.5, "noisy detections cannot beat ground truth by much");
}

#[test]
fn post_processing_removes_box_fluctuation() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence_with(&dir, true, 3);
    let seq = Sequence::open(&dir).unwrap();
    let mut cfg = depth_chord();
    cfg.motion.along_ray = fme::motion::AlongRay::default();
    cfg.postprocess = fme::postprocess::PostprocessConfig::paper();
    cfg.postprocess.depth_smoothing_s = Seconds(0.0);
    cfg.motion.speed_span_s = Seconds(0.0);
    let r = evaluate(&seq, &cfg, &EvalOptions::default()).unwrap();
    cfg.postprocess = fme::postprocess::PostprocessConfig::off();
    let raw = evaluate(&seq, &cfg, &EvalOptions::default()).unwrap();
    assert!(r.boxes_corrected > 0 && raw.boxes_corrected == 0);
    assert!(raw.speed_rmse_mps > 0.2, "{}", summary(&raw));
    assert!(r.speed_rmse_mps < 0.5 * raw.speed_rmse_mps, "{} vs {}", summary(&r), summary(&raw));
}

/// Ground-truth depth made relative without noise, then the inverse fit: the depth path with
/// nothing in it that is not exact.
fn exact_relative_gt() -> (Config, EvalOptions) {
    let mut cfg = depth_chord();
    cfg.depth.fit = FitMethod::Inverse;
    let mut opts = EvalOptions { depth: DepthChoice::RelativeGt, ..Default::default() };
    opts.relative.pixel_noise = 0.0;
    opts.relative.low_freq = 0.0;
    (cfg, opts)
}

#[test]
fn relative_gt_with_inverse_and_robust_fits_gets_depth_right() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    let seq = Sequence::open(&dir).unwrap();
    let (mut cfg, mut opts) = exact_relative_gt();
    let exact = evaluate(&seq, &cfg, &opts).unwrap();
    assert_eq!(exact.references_visible, 6);
    assert!(exact.depth_rmse_m.unwrap() < 0.01, "{}", summary(&exact));
    // Ground-truth boxes carry world.csv's ids: depth is also scored against each body centre
    // (the painted fish are flat at their centre depth, so the two agree).
    assert!(exact.depth_body_rmse_m.unwrap() < 0.01, "{}", summary(&exact));
    assert_eq!(exact.depth_body_delta_1_25, Some(1.0));
    assert_eq!(exact.depth_delta_1_25, Some(1.0));
    assert!(exact.fit_residual_m.unwrap() < 0.01);
    // Two fouled references: the plain inverse fit suffers, the robust one does not.
    opts.foul_refs = 2;
    let fouled = evaluate(&seq, &cfg, &opts).unwrap();
    cfg.depth.fit = FitMethod::Robust;
    let robust = evaluate(&seq, &cfg, &opts).unwrap();
    assert!(fouled.depth_rmse_m.unwrap() > 0.1, "{}", summary(&fouled));
    assert!(fouled.depth_body_rmse_m.unwrap() > 0.1, "{}", summary(&fouled));
    assert!(robust.depth_rmse_m.unwrap() < 0.01, "{}", summary(&robust));
    assert_eq!(robust.references_rejected, 2 * N as u64);
}

#[test]
fn visible_sampling_reads_a_half_hidden_fish_where_it_is_seen() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence_hidden(&dir);
    let seq = Sequence::open(&dir).unwrap();
    let (mut cfg, opts) = exact_relative_gt();
    // The near quarter of the whole core is fish 0, 1 m in front of fish 3: 1 m of error on one
    // fish in four.
    cfg.depth.sample = DepthSample::Box;
    let boxed = evaluate(&seq, &cfg, &opts).unwrap();
    assert!(boxed.depth_body_rmse_m.unwrap() > 0.4, "{}", summary(&boxed));
    // Where no other box covers it, fish 3 is itself; every fish keeps its depth.
    cfg.depth.sample = DepthSample::Visible;
    let visible = evaluate(&seq, &cfg, &opts).unwrap();
    assert!(visible.depth_body_rmse_m.unwrap() < 0.02, "{}", summary(&visible));
    assert_eq!(visible.depth_body_coverage, Some(1.0), "{}", summary(&visible));
    assert!(visible.speed_rmse_mps < boxed.speed_rmse_mps, "{} vs {}", summary(&visible), summary(&boxed));
}

#[test]
fn cli_json_series_and_plot() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    let (series, plot) = (tmp.path().join("s.csv"), tmp.path().join("p.png"));
    let out = fme()
        .args(["eval", "--sequence"])
        .arg(&dir)
        .args(["--depth", "relative-gt", "--json", "--series"])
        .arg(&series)
        .arg("--plot")
        .arg(&plot)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for k in [
        "frames",
        "speed_rmse_mps",
        "speed_distcorr",
        "error_ci95_mps",
        "speed_rmse_now_mps",
        "cpu_ms_per_frame",
        "depth_rmse_m",
        "depth_delta_1_25",
        "depth_delta_1_25_2",
    ] {
        assert!(j.get(k).is_some_and(|v| v.is_number() || v.is_array()), "missing {k} in {j}");
    }
    let csv = std::fs::read_to_string(&series).unwrap();
    assert!(csv.starts_with(
        "frame,t,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,latency_s,too_few_fish,uncalibrated,scale,unlike_fish,true_mps,true_now_mps\n"
    ));
    assert_eq!(csv.lines().count(), N as usize + 1);
    let png = image::open(&plot).unwrap();
    assert_eq!((png.width(), png.height()), (1200, 560));
}

#[test]
fn cli_tracks_rows_follow_each_fish() {
    // `--tracks`: one row per fish and frame, with the box centre, the depth the speed used and the
    // fish's speed; with ground-truth depth these are the fish's own camera depth and speed.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    let tracks = tmp.path().join("t.csv");
    let out = fme().arg("eval").args(EXACT).arg("--sequence").arg(&dir).arg("--tracks").arg(&tracks).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = std::fs::read_to_string(&tracks).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps"));
    let cam = camera();
    let mut rows = 0;
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 10, "{line}");
        let (frame, t, id): (u32, f64, u32) = (f[0].parse().unwrap(), f[1].parse().unwrap(), f[2].parse().unwrap());
        assert!((t - f64::from(frame - 1) / FPS).abs() < 1e-9, "{line}");
        let (p, v) = fish(id - 1, t);
        let px = cam.world_to_pixel(&p).unwrap();
        let (u, vv): (f64, f64) = (f[3].parse().unwrap(), f[4].parse().unwrap());
        assert!((u - px.u).abs() < 0.01 && (vv - px.v).abs() < 0.01, "centre of fish {id} at frame {frame}: {line}");
        let z = cam.pose.to_camera(&p).depth().0;
        let (raw, depth): (f64, f64) = (f[7].parse().unwrap(), f[8].parse().unwrap());
        assert!((depth - z).abs() < 2e-3 && (raw - depth).abs() < 1e-9, "depth of fish {id} at frame {frame}: {line}");
        if frame == 1 {
            assert_eq!(f[9], "", "no speed before a second position: {line}");
        } else {
            let s: f64 = f[9].parse().unwrap();
            assert!((s - v.norm()).abs() < 0.01, "speed of fish {id} at frame {frame}: {s} vs {}", v.norm());
        }
        rows += 1;
    }
    assert_eq!(rows, 3 * N, "three fish in every frame");
    // An output that cannot be created is an error that names it, raised before the evaluation:
    // the missing depth model (which the evaluation would open first) is not what it reports.
    for flag in ["--tracks", "--series", "--plot"] {
        let bad = tmp.path().join("no-such-dir").join("out");
        let out = fme()
            .args(["eval", "--depth", "model", "--depth-model"])
            .arg(tmp.path().join("missing.onnx"))
            .arg("--sequence")
            .arg(&dir)
            .arg(flag)
            .arg(&bad)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("no-such-dir/out"), "{flag}: {err}");
        assert!(!err.contains("missing.onnx") && out.stdout.is_empty(), "{flag}: evaluated before failing: {err}");
    }
    // When the evaluation itself fails, an existing output keeps its contents and a new one is not
    // left behind.
    let (old, new) = (tmp.path().join("old.csv"), tmp.path().join("new.csv"));
    std::fs::write(&old, "keep\n").unwrap();
    let out = fme()
        .args(["eval", "--depth", "model", "--depth-model"])
        .arg(tmp.path().join("missing.onnx"))
        .arg("--sequence")
        .arg(&dir)
        .arg("--series")
        .arg(&old)
        .arg("--tracks")
        .arg(&new)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("missing.onnx"), "{err}");
    assert_eq!(std::fs::read_to_string(&old).unwrap(), "keep\n");
    assert!(!new.exists(), "a failed evaluation left {} behind", new.display());
}

#[test]
fn a_reader_that_closes_the_pipe_early_is_not_an_error() {
    // `fme eval ... | head -1`: the report meets a closed pipe; eval must not panic (println! did).
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    for json in [false, true] {
        let mut cmd = fme();
        cmd.args(["eval", "--sequence"]).arg(&dir);
        if json {
            cmd.arg("--json");
        }
        let mut child = cmd.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
        drop(child.stdout.take()); // the reader is gone before eval writes anything
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "json {json}: {:?}: {err}", out.status);
        assert!(!err.contains("panicked"), "json {json}: {err}");
    }
}

fn fails_with(args: &[&str], dir: &Path, needles: &[&str]) {
    let out = fme().args(["eval", "--sequence"]).arg(dir).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "expected a usage error (2) for {args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
}

#[test]
fn bad_input_names_file_and_line_and_exits_non_zero() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    // Missing models are named; a bad tracker preset is a usage error.
    fails_with(&["--boxes", "model", "--det-model", "/nonexistent/det.onnx"], &dir, &["/nonexistent/det.onnx"]);
    fails_with(&["--depth", "model", "--depth-model", "/nonexistent/depth.onnx"], &dir, &["/nonexistent/depth.onnx"]);
    fails_with(&["--boxes", "tracker", "--set", "tracker.preset=bogus"], &dir, &["tracker.preset", "bogus"]);
    fails_with(&["--set", "motion.speed_span_s=-1"], &dir, &["motion.speed_span_s"]);
    // A track file with a malformed row and one with NaN.
    let tracks = tmp.path().join("tracks.txt");
    std::fs::write(&tracks, "1,1,10,10,20,8,1,-1,-1,-1\n2,1,oops,10,20,8,1,-1,-1,-1\n").unwrap();
    fails_with(&["--boxes", tracks.to_str().unwrap()], &dir, &["tracks.txt:2"]);
    std::fs::write(&tracks, "1,1,10,10,20,8,1,-1,-1,-1\n2,1,10,NaN,20,8,1,-1,-1,-1\n").unwrap();
    fails_with(&["--boxes", tracks.to_str().unwrap()], &dir, &["tracks.txt:2"]);
    fails_with(&["--boxes", tmp.path().join("none.txt").to_str().unwrap()], &dir, &["none.txt"]);
    // NaN in gt/world.csv, line 4 (header + 3 rows of frame 1).
    let world = dir.join("gt/world.csv");
    let good_world = std::fs::read_to_string(&world).unwrap();
    let mut lines: Vec<String> = good_world.lines().map(String::from).collect();
    let mut cols: Vec<String> = lines[3].split(',').map(String::from).collect();
    cols[5] = "NaN".into();
    lines[3] = cols.join(",");
    std::fs::write(&world, lines.join("\n") + "\n").unwrap();
    fails_with(&[], &dir, &["world.csv:4"]);
    std::fs::write(&world, &good_world).unwrap();
    // Malformed gt.txt row 2.
    let gt = dir.join("gt/gt.txt");
    let good_gt = std::fs::read_to_string(&gt).unwrap();
    let mut g: Vec<&str> = good_gt.lines().collect();
    g[1] = "1,2,3";
    std::fs::write(&gt, g.join("\n") + "\n").unwrap();
    fails_with(&[], &dir, &["gt.txt:2"]);
    std::fs::write(&gt, &good_gt).unwrap();
    // A missing depth map, then a meta.json without a camera (a meta.json is optional, but one
    // that is there must be a calibration).
    std::fs::remove_file(dir.join("depth/000007.png")).unwrap();
    fails_with(&[], &dir, &["000007.png", "missing"]);
    std::fs::write(dir.join("meta.json"), "{\"fps\": 30}").unwrap();
    fails_with(&[], &dir, &["meta.json", "camera"]);
    fails_with(&[], &tmp.path().join("nowhere"), &["nowhere"]);
    // Bad option values are usage errors (exit code 2).
    // Bad option values are usage errors (exit code 2) that name the key, on a valid sequence.
    let good = tmp.path().join("good");
    write_sequence(&good);
    let out = fme().args(["eval", "--sequence"]).arg(&good).arg("--speed-span=-1").output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("motion.speed_span_s"));
}
