//! `fme calibrate` (docs/calibration.md): the pose recovered from the reference objects of the
//! bundled calibrated recording tests/data/swarm20 (layout F) with 0.5 px of seeded pixel noise, a
//! mis-measured reference named by the consensus step, the activity series of `fme eval` under the
//! recovered calibration against the one under the true meta.json, `--check`, and bad input; and
//! over 50 seeded random cage cameras with realistic click and tape noise, that no good reference
//! is refused while one moved by 0.3 m is named (the accuracy table of docs/calibration.md is made
//! by the ignored `accuracy_table` test here).

use fme::calib::{self, CalibError, Options, Reference};
use fme::geometry::{Camera, Intrinsics, Pixel, Pose, WorldPoint};
use fme::rng::Rng;
use fme::sequence::Meta;
use fme::units::Metres;
use nalgebra::{Rotation3, Vector3};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SEQ: &str = "tests/data/swarm20";
const FRAME: &str = "tests/data/swarm20/img1/000001.jpg";

fn meta() -> (Meta, Camera) {
    let path = Path::new(SEQ).join("meta.json");
    let m = Meta::read(&path).expect("swarm20 meta.json");
    let cam = m.camera(&path).expect("camera");
    (m, cam)
}

/// The reference objects' front faces at their true pixels plus `noise_px` (per axis, Gaussian).
fn references(m: &Meta, cam: &Camera, noise_px: f64, seed: u64) -> Vec<Reference> {
    let mut rng = Rng::new(seed);
    m.reference_objects
        .iter()
        .map(|r| {
            let w = r.front_face_center();
            let p = cam.world_to_pixel(&w).expect("reference in front of the camera");
            Reference {
                name: format!("cube{}", r.id),
                line: 0,
                world: w,
                pixel: Pixel::new(p.u + noise_px * rng.normal(), p.v + noise_px * rng.normal()),
            }
        })
        .collect()
}

/// The command's defaults: 3 px limit, 1.5 px clicks, 1 cm tape.
fn opts(m: &Meta) -> Options {
    Options { max_rms_px: 3.0, click_px: 1.5, tape_m: 0.01, width: m.width, height: m.height }
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Pose error over 100 seeded trials at 0.5 px: every trial within 3 cm and 0.5 degrees (the
/// figures are printed with `--nocapture`; docs/calibration.md quotes them).
#[test]
fn pose_within_3_cm_and_half_a_degree_at_half_a_pixel_of_noise() {
    let (m, truth) = meta();
    for estimate in [false, true] {
        let (mut dc, mut da) = (Vec::new(), Vec::new());
        for seed in 0..100 {
            let refs = references(&m, &truth, 0.5, seed);
            let k = (!estimate).then_some(truth.intrinsics);
            let sol = calib::calibrate(&refs, k.as_ref(), &opts(&m)).expect("solves");
            dc.push(sol.camera.pose.camera_center().distance(&truth.pose.camera_center()).get() * 100.0);
            da.push(calib::rotation_angle_deg(&sol.camera.pose.rotation, &truth.pose.rotation));
        }
        let (max_c, max_a) = (dc.iter().copied().fold(0.0, f64::max), da.iter().copied().fold(0.0, f64::max));
        println!(
            "{}: centre error median {:.2} cm, p95 {:.2} cm, max {max_c:.2} cm; orientation median {:.3} deg, p95 {:.3} \
             deg, max {max_a:.3} deg",
            if estimate { "intrinsics estimated" } else { "intrinsics known" },
            percentile(&mut dc, 0.5),
            percentile(&mut dc, 0.95),
            percentile(&mut da, 0.5),
            percentile(&mut da, 0.95),
        );
        if !estimate {
            assert!(max_c < 3.0 && max_a < 0.5, "worst trial {max_c:.2} cm / {max_a:.3} deg");
        }
    }
}

/// A reference whose measured position is 0.3 m off (across the line of sight) is named, whichever
/// it is, with the intrinsics given or estimated.
#[test]
fn a_reference_moved_by_30_cm_is_named() {
    let (m, truth) = meta();
    for i in 0..m.reference_objects.len() {
        let mut refs = references(&m, &truth, 0.5, 7 + i as u64);
        // Across the line of sight: perpendicular to the viewing ray, in the horizontal plane.
        let ray = refs[i].world.0 - truth.pose.camera_center().0;
        let across = ray.cross(&nalgebra::Vector3::z()).normalize();
        refs[i].world = WorldPoint(refs[i].world.0 + across * 0.3);
        // With the intrinsics given, and with them estimated too (ten references, seven needed).
        for k in [Some(&truth.intrinsics), None] {
            match calib::calibrate(&refs, k, &opts(&m)) {
                Err(CalibError::Outlier { label, .. }) => {
                    assert!(label.contains(&format!("'{}'", refs[i].name)), "named {label}, moved {}", refs[i].name)
                }
                other => panic!("moving {} by 0.3 m (intrinsics {k:?}): {other:?}", refs[i].name),
            }
        }
    }
}

fn fme(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fme")).args(args).output().expect("fme runs")
}

fn write_csv(dir: &Path, name: &str, refs: &[Reference]) -> PathBuf {
    let mut s = String::from("name,x,y,z,u,v\n");
    for r in refs {
        let p = r.world.0;
        s += &format!("{},{},{},{},{:.3},{:.3}\n", r.name, p.x, p.y, p.z, r.pixel.u, r.pixel.v);
    }
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

fn activity(path: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "activity_mps").expect("activity_mps column");
    lines.map(|l| l.split(',').nth(col).unwrap().parse::<f64>().unwrap_or(f64::NAN)).collect()
}

/// The calibration written by `fme calibrate` (intrinsics from the recording's meta.json, true
/// pixels plus 0.5 px) gives an activity series within 2% (relative RMS) of the true calibration's.
#[test]
fn eval_with_the_recovered_calibration_matches_the_true_one() {
    let (m, truth) = meta();
    let dir = tempfile::tempdir().unwrap();
    let csv = write_csv(dir.path(), "points.csv", &references(&m, &truth, 0.5, 11));
    let calib = dir.path().join("calib.json");
    let overlay = dir.path().join("overlay.png");
    let meta_json = format!("{SEQ}/meta.json");
    let out = fme(&[
        "calibrate",
        "--frame",
        FRAME,
        "--points",
        csv.to_str().unwrap(),
        "--intrinsics",
        &meta_json,
        "--out",
        calib.to_str().unwrap(),
        "--overlay",
        overlay.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("error_px") && stdout.contains("cube3") && stdout.contains("RMS"), "{stdout}");
    let written = std::fs::read_to_string(&calib).unwrap();
    assert!(written.contains("\"click_px\": 1.5") && written.contains("\"tape_m\": 0.01"), "{written}");
    let img = image::open(&overlay).expect("overlay PNG");
    assert_eq!((img.width(), img.height()), (m.width, m.height));

    let series = |name: &str, extra: &[String]| {
        let path = dir.path().join(name);
        let mut args: Vec<String> = ["eval", "--sequence", SEQ, "--boxes", "gt", "--depth", "relative-gt", "--series"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        args.push(path.to_str().unwrap().into());
        args.extend_from_slice(extra);
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = fme(&refs);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        activity(&path)
    };
    let a = series("true.csv", &[]);
    let b = series("recovered.csv", &["--set".into(), format!("camera.calibration={}", calib.display())]);
    assert_eq!(a.len(), b.len());
    let pairs: Vec<(f64, f64)> =
        a.iter().zip(&b).filter(|(x, y)| x.is_finite() && y.is_finite()).map(|(x, y)| (*x, *y)).collect();
    assert!(pairs.len() * 2 > a.len(), "{} of {} rows have an activity in both", pairs.len(), a.len());
    let n = pairs.len() as f64;
    let diff = (pairs.iter().map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt();
    let level = (pairs.iter().map(|(x, _)| x * x).sum::<f64>() / n).sqrt();
    println!("activity: relative RMS difference {:.3}% over {} rows", 100.0 * diff / level, pairs.len());
    assert!(diff < 0.02 * level, "relative RMS difference {:.3}%", 100.0 * diff / level);

    // --check: the same points pass (exit 0); points of a moved camera fail (exit 1) and say so.
    let c = calib.to_str().unwrap();
    let o = fme(&["calibrate", "--check", c, "--frame", FRAME, "--points", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("has not moved"));
    let mut moved = truth;
    moved.pose.rotation = nalgebra::Rotation3::from_euler_angles(0.0, 0.03, 0.0).into_inner() * truth.pose.rotation;
    let csv2 = write_csv(dir.path(), "moved.csv", &references(&m, &moved, 0.5, 12));
    let o = fme(&["calibrate", "--check", c, "--frame", FRAME, "--points", csv2.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("camera has moved") && err.contains("limit of 3 px"), "{err}");
}

/// Bad input exits 2 and names the problem (the reference, the line, or the limit).
#[test]
fn bad_input_exits_2_naming_the_problem() {
    let (m, truth) = meta();
    let dir = tempfile::tempdir().unwrap();
    let meta_json = format!("{SEQ}/meta.json");
    let good = references(&m, &truth, 0.5, 3);
    let run = |csv: &Path, extra: &[&str]| {
        let out = dir.path().join("c.json");
        let mut args = vec![
            "calibrate",
            "--frame",
            FRAME,
            "--points",
            csv.to_str().unwrap(),
            "--intrinsics",
            &meta_json,
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = fme(&args);
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let expect = |name: &str, refs: &[Reference], extra: &[&str], want: &[&str]| {
        let csv = write_csv(dir.path(), name, refs);
        let (code, err) = run(&csv, extra);
        assert_eq!(code, Some(2), "{name}: {err}");
        for w in want {
            assert!(err.contains(w), "{name}: `{w}` not in: {err}");
        }
    };
    expect("few.csv", &good[..3], &[], &["3 reference(s)", "at least 4"]);
    let mut coincident = good.clone();
    coincident[4].world = coincident[2].world;
    expect("coincident.csv", &coincident, &[], &["'cube3'", "'cube5'", "same world position"]);
    let line: Vec<Reference> = good
        .iter()
        .take(5)
        .enumerate()
        .map(|(i, r)| Reference { world: WorldPoint::new(1.0 + i as f64, 3.0, 0.5), ..r.clone() })
        .collect();
    expect("line.csv", &line, &[], &["straight line"]);
    let mut outside = good.clone();
    outside[6].pixel.u = 700.0;
    expect("outside.csv", &outside, &[], &["'cube7'", "outside the 640x384 image"]);
    // Over --max-rms is refused only when the stated noise does not explain it.
    let csv = write_csv(dir.path(), "limit.csv", &good);
    let (code, err) = run(&csv, &["--max-rms", "0.05"]);
    assert_eq!(code, Some(0), "0.5 px of noise is within the default --click-px 1.5: {err}");
    expect(
        "limit.csv",
        &good,
        &["--max-rms", "0.05", "--click-px", "0.01", "--tape-m", "0.0001"],
        &["over the limit of 0.05 px", "--click-px 0.01", "1.33x"],
    );
    for (flag, value) in [("--click-px", "0"), ("--click-px", "nan"), ("--tape-m", "-0.01"), ("--tape-m", "inf")] {
        let arg = format!("{flag}={value}");
        let (code, err) = run(&csv, &[arg.as_str()]);
        assert_eq!(code, Some(2), "{arg}: {err}");
        assert!(err.contains(flag) && err.contains("positive"), "{arg}: {err}");
    }
    let noisy = references(&m, &truth, 6.0, 5);
    expect("noisy.csv", &noisy, &[], &["over the limit of 3 px"]);
    // No intrinsics and coplanar references: the message says what to give.
    let flat: Vec<Reference> = good.iter().filter(|r| r.world.0.z < 0.1).cloned().collect();
    let csv = write_csv(dir.path(), "flat.csv", &flat);
    let o = fme(&[
        "calibrate",
        "--frame",
        FRAME,
        "--points",
        csv.to_str().unwrap(),
        "--out",
        dir.path().join("x.json").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("non-coplanar") && err.contains("--intrinsics"), "{err}");
    // A camera that is not there (--source grabs the frame from a V4L2 device).
    let o =
        fme(&["calibrate", "--source", "/dev/video-fme-none", "--frame", dir.path().join("g.png").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("/dev/video-fme-none") && err.contains("not found"), "{err}");
    // Malformed CSV: the line is named.
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "name,x,y,z,u,v\na,1,2,3,4,5\nb,1,2,3,4\n").unwrap();
    let (code, err) = run(&bad, &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("bad.csv") && err.contains("line 3") && err.contains("6 fields"), "{err}");
    // A name of 65,536 characters: a clear error, not a panic in the table.
    let mut long = good.clone();
    long[0].name = "n".repeat(65_536);
    expect("long.csv", &long, &[], &["long.csv", "name of 65536 characters", "at most 64"]);
    // --out into a folder that does not exist: what the user gave, so exit 2 naming --out.
    let csv = write_csv(dir.path(), "good.csv", &good);
    let missing = dir.path().join("no-such-folder/c.json");
    let o = fme(&[
        "calibrate",
        "--frame",
        FRAME,
        "--points",
        csv.to_str().unwrap(),
        "--intrinsics",
        &meta_json,
        "--out",
        missing.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--out") && err.contains("no-such-folder"), "{err}");
}

/// `--source` also takes a recorded sequence, as `fme run --source` does: the grabbed frame is the
/// recording's sixth (as from a camera, after exposure settles), and it solves in the same call.
#[test]
fn source_takes_a_recorded_sequence() {
    let (m, truth) = meta();
    let dir = tempfile::tempdir().unwrap();
    let grabbed = dir.path().join("frame.png");
    let o = fme(&["calibrate", "--source", SEQ, "--frame", grabbed.to_str().unwrap()]);
    let (stdout, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(stdout.contains("wrote") && stdout.contains("640x384"), "{stdout}");
    let got = image::open(&grabbed).expect("grabbed PNG").to_rgb8();
    let sixth = image::open(format!("{SEQ}/img1/000006.jpg")).unwrap().to_rgb8();
    assert!(got == sixth, "the grabbed frame is not the recording's sixth");

    let csv = write_csv(dir.path(), "points.csv", &references(&m, &truth, 0.5, 21));
    let calib = dir.path().join("calib.json");
    let o = fme(&[
        "calibrate",
        "--source",
        SEQ,
        "--frame",
        grabbed.to_str().unwrap(),
        "--points",
        csv.to_str().unwrap(),
        "--out",
        calib.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(calib.is_file());

    // A directory that is not there: exit 2, named.
    let missing = dir.path().join("no-such-recording");
    let o = fme(&["calibrate", "--source", missing.to_str().unwrap(), "--frame", grabbed.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("no-such-recording") && err.contains("not found"), "{err}");
}

/// Four or five references (no DLT; the plane-homography start is exact only for coplanar ones,
/// sampled rotations cover the rest) still solve: every 4- and 5-subset of the ten, with
/// intrinsics, noise-free, converges to the true pose.
#[test]
fn every_4_and_5_subset_converges() {
    let (m, truth) = meta();
    let all = references(&m, &truth, 0.0, 0);
    let n = all.len();
    let mut worst = 0.0f64;
    let mut failed = Vec::new();
    for mask in 0u32..(1 << n) {
        let k = mask.count_ones();
        if k != 4 && k != 5 {
            continue;
        }
        let sub: Vec<Reference> = (0..n).filter(|i| mask & (1 << i) != 0).map(|i| all[i].clone()).collect();
        match calib::calibrate(&sub, Some(&truth.intrinsics), &opts(&m)) {
            Ok(sol) => {
                let d = sol.camera.pose.camera_center().distance(&truth.pose.camera_center()).get();
                if d > 1e-3 {
                    failed.push((mask, d));
                }
                worst = worst.max(d);
            }
            Err(e) => {
                println!("{mask:010b}: {e}");
                failed.push((mask, f64::NAN));
            }
        }
    }
    println!("worst centre error {worst:.2e} m; failed {failed:?}");
    assert!(failed.is_empty(), "{} subsets failed: {failed:?}", failed.len());
}

/// A synthetic commissioning: a camera in a fish cage and references spread through its view.
struct Scene {
    truth: Camera,
    width: u32,
    height: u32,
    /// True face centres.
    world: Vec<WorldPoint>,
}

/// Camera `seed`: 640x384 or 1280x720, 60-100 degree field of view, 0.3-2.5 m up, any heading,
/// tilted 30 degrees down to 10 up and rolled by up to 5 degrees; `n` references at random pixels
/// of the central 90% of the image, 1-6 m deep, at least 0.3 m and 5% of the image width apart.
fn scene(seed: u64, n: usize) -> Scene {
    let mut rng = Rng::derive(seed, 0xca1b);
    let (width, height) = if rng.uniform() < 0.5 { (640, 384) } else { (1280, 720) };
    let k = Intrinsics::from_hfov(width, height, rng.range(60.0, 100.0)).unwrap();
    let eye = WorldPoint::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(0.3, 2.5));
    let (heading, tilt) = (rng.range(0.0, std::f64::consts::TAU), rng.range(-30.0f64, 10.0).to_radians());
    let dir = Vector3::new(heading.cos() * tilt.cos(), heading.sin() * tilt.cos(), tilt.sin());
    let mut pose = Pose::look_at(eye, WorldPoint(eye.0 + dir), Vector3::z()).unwrap();
    let roll = Rotation3::from_euler_angles(0.0, 0.0, rng.range(-5.0f64, 5.0).to_radians()).into_inner();
    pose.rotation = roll * pose.rotation;
    pose.translation = -(pose.rotation * eye.0);
    let truth = Camera { intrinsics: k, pose };
    let (w, h) = (f64::from(width), f64::from(height));
    let (mut world, mut pixels): (Vec<WorldPoint>, Vec<Pixel>) = (Vec::new(), Vec::new());
    while world.len() < n {
        let px = Pixel::new(rng.range(0.05, 0.95) * w, rng.range(0.05, 0.95) * h);
        let p = truth.pixel_to_world(px, Metres(rng.range(1.0, 6.0))).unwrap();
        if world
            .iter()
            .zip(&pixels)
            .all(|(q, r)| q.distance(&p).get() >= 0.3 && (r.u - px.u).hypot(r.v - px.v) >= 0.05 * w)
        {
            world.push(p);
            pixels.push(px);
        }
    }
    Scene { truth, width, height, world }
}

/// The references as measured: each face centre off by `tape_m` and each marked pixel by
/// `click_px`, per axis (Gaussian).
fn measure(s: &Scene, click_px: f64, tape_m: f64, rng: &mut Rng) -> Vec<Reference> {
    s.world
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let p = s.truth.world_to_pixel(w).unwrap();
            let d = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * tape_m;
            Reference {
                name: format!("ref{}", i + 1),
                line: i + 2,
                world: WorldPoint(w.0 + d),
                pixel: Pixel::new(p.u + click_px * rng.normal(), p.v + click_px * rng.normal()),
            }
        })
        .collect()
}

/// Moves one reference's measured position by 0.3 m across its line of sight (a random direction
/// perpendicular to it); returns which.
fn move_one(s: &Scene, refs: &mut [Reference], rng: &mut Rng) -> usize {
    let i = ((rng.uniform() * refs.len() as f64) as usize).min(refs.len() - 1);
    let ray = s.world[i].0 - s.truth.pose.camera_center().0;
    let across = ray.cross(&Vector3::new(rng.normal(), rng.normal(), rng.normal())).normalize();
    refs[i].world = WorldPoint(refs[i].world.0 + across * 0.3);
    i
}

/// What the solve did over a set of random cameras.
#[derive(Default)]
struct Tally {
    /// Camera centre and orientation errors of the accepted good sets, cm and degrees.
    centre_cm: Vec<f64>,
    angle_deg: Vec<f64>,
    /// Good sets refused as inconsistent (a reference named, or over the limit).
    false_rejections: Vec<String>,
    /// Good sets with no solution for another reason.
    unsolved: Vec<String>,
    /// Per camera: with one reference moved 0.3 m, was that reference named.
    named: Vec<bool>,
    misses: Vec<String>,
}

/// `cameras` random cameras (camera k has `counts[k % counts.len()]` references), each solved from
/// its references measured with the given noise (stated as that noise), then with one of them
/// moved by 0.3 m.
fn trials(cameras: usize, counts: &[usize], click_px: f64, tape_m: f64, known: bool) -> Tally {
    let mut t = Tally::default();
    for c in 0..cameras {
        let n = counts[c % counts.len()];
        let s = scene(c as u64, n);
        let mut rng = Rng::derive(c as u64, 0x0e55);
        let opts = Options { max_rms_px: 3.0, click_px, tape_m, width: s.width, height: s.height };
        let k = known.then_some(s.truth.intrinsics);
        let good = measure(&s, click_px, tape_m, &mut rng);
        match calib::calibrate(&good, k.as_ref(), &opts) {
            Ok(sol) => {
                t.centre_cm.push(sol.camera.pose.camera_center().distance(&s.truth.pose.camera_center()).get() * 100.0);
                t.angle_deg.push(calib::rotation_angle_deg(&sol.camera.pose.rotation, &s.truth.pose.rotation));
            }
            Err(e @ (CalibError::Outlier { .. } | CalibError::OverLimit { .. })) => {
                t.false_rejections.push(format!("camera {c} ({n} references): {e}"))
            }
            Err(e) => t.unsolved.push(format!("camera {c} ({n} references): {e}")),
        }
        let mut bad = good;
        let i = move_one(&s, &mut bad, &mut rng);
        match calib::calibrate(&bad, k.as_ref(), &opts) {
            Err(CalibError::Outlier { label, .. }) if label.contains(&format!("'{}'", bad[i].name)) => {
                t.named.push(true)
            }
            other => {
                t.named.push(false);
                t.misses.push(format!(
                    "camera {c} ({n} references), {} moved: {}",
                    bad[i].name,
                    other.map_or_else(|e| e.to_string(), |s| format!("accepted at {:.2} px RMS", s.rms_px))
                ))
            }
        }
    }
    t
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    percentile(&mut v, 0.5)
}

/// Realistic noise (1 px clicks, 1 cm tape, stated as such) over 50 random cage cameras with 6, 8
/// or 10 references: no good reference is refused, and a reference moved by 0.3 m is named in at
/// least 95% of the cameras where the leave-one-out test can run (five references with intrinsics;
/// without, in 95% of those with ten and 90% of those with eight: with fewer, the estimated focal
/// length and principal point absorb part of the move). The pose error is bounded by the
/// measurement noise, not by the consensus step; the bounds here are what the maximum-likelihood
/// solve reaches on these cameras (docs/calibration.md's table) with a small margin, and a worst
/// case with intrinsics.
#[test]
fn realistic_noise_refuses_no_good_reference_and_names_a_moved_one() {
    for known in [true, false] {
        let counts = [6, 8, 10];
        let t = trials(50, &counts, 1.0, 0.01, known);
        let what = if known { "intrinsics known" } else { "intrinsics estimated" };
        println!(
            "{what}: {} of 50 solved, centre median {:.2} max {:.2} cm, orientation median {:.3} max {:.3} deg; moved \
             reference named in {} of 50",
            t.centre_cm.len(),
            median(&t.centre_cm),
            max(&t.centre_cm),
            median(&t.angle_deg),
            max(&t.angle_deg),
            t.named.iter().filter(|&&x| x).count()
        );
        for m in &t.misses {
            println!("  not named: {m}");
        }
        assert!(t.false_rejections.is_empty(), "{what}: good references refused: {:#?}", t.false_rejections);
        assert!(t.unsolved.is_empty(), "{what}: {:#?}", t.unsolved);
        let named_of = |n: usize| {
            let cams: Vec<usize> = (0..50).filter(|c| counts[c % 3] == n).collect();
            (cams.iter().filter(|&&c| t.named[c]).count(), cams.len())
        };
        let need = calib::consensus::min_references(!known);
        for n in counts.into_iter().filter(|&n| n >= need) {
            let (named, of) = named_of(n);
            let pct = if known || n >= 10 { 95 } else { 90 };
            assert!(named * 100 >= pct * of, "{what}, {n} references: moved one named in {named} of {of}");
        }
        let (c, a) = (median(&t.centre_cm), median(&t.angle_deg));
        if known {
            assert!(c < 2.5 && a < 0.5 && max(&t.centre_cm) < 10.0 && max(&t.angle_deg) < 1.5, "{what}");
        } else {
            assert!(c < 6.5 && a < 1.8, "{what}: median {c:.2} cm, {a:.3} deg");
        }
    }
}

/// The accuracy table of docs/calibration.md (not a check; run it in release, it takes minutes):
/// `cargo test --release --test calibrate accuracy_table -- --ignored --nocapture`.
#[test]
#[ignore]
fn accuracy_table() {
    println!(
        "| click px | tape cm | intrinsics | refs | centre error median / p95 / max cm | orientation median / p95 / \
         max deg | good sets refused | moved 0.3 m named |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for click in [0.5, 1.0, 2.0] {
        for tape in [0.01, 0.03] {
            for known in [true, false] {
                for n in [6, 8, 10] {
                    let t = trials(50, &[n], click, tape, known);
                    let (mut c, mut a) = (t.centre_cm.clone(), t.angle_deg.clone());
                    let stats = |v: &mut Vec<f64>, p: usize| {
                        if v.is_empty() {
                            return "-".to_string();
                        }
                        let m = max(v);
                        format!("{:.*} / {:.*} / {m:.p$}", p, percentile(v, 0.5), p, percentile(v, 0.95))
                    };
                    println!(
                        "| {click} | {} | {} | {n} | {} | {} | {} of 50{} | {} of 50 |",
                        tape * 100.0,
                        if known { "known" } else { "estimated" },
                        stats(&mut c, 1),
                        stats(&mut a, 2),
                        t.false_rejections.len(),
                        if t.unsolved.is_empty() { String::new() } else { format!(" ({} unsolved)", t.unsolved.len()) },
                        t.named.iter().filter(|&&x| x).count(),
                    );
                    for f in t.false_rejections.iter().chain(&t.unsolved).chain(&t.misses) {
                        eprintln!("  {f}");
                    }
                }
            }
        }
    }
}
