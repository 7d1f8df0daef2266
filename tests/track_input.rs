//! Bad input: malformed rows, negative sizes, NaN, frames out of order, time going backwards.

use fme::cli::ConfigArgs;
use fme::cli::track::{TrackArgs, run};
use fme::geometry::PixelBox;
use fme::track::{Detection, TrackError, Tracker, TrackerConfig, TrackerPreset};
use fme::units::Seconds;
use std::path::PathBuf;

fn args(det: PathBuf, out: PathBuf) -> TrackArgs {
    TrackArgs {
        det: Some(det),
        out: Some(out),
        preset: None,
        config: ConfigArgs::default(),
        fps: 30.0,
        gt: None,
        hyp: None,
        json: false,
    }
}

#[test]
fn cli_errors_name_file_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        ("1,-1,10,10,5,5,0.9\n1,-1,10,10,5\n", ":2: missing height"),
        ("1,-1,10,10,5,5,0.9\n2,-1,10,10,-5,5,0.9\n", ":2: negative box size"),
        ("1,-1,10,10,5,5,0.9\n2,-1,10,NaN,5,5,0.9\n", ":2: y is NaN"),
        ("1,-1,10,10,5,5,0.9\n1,-1,10,10,5,5,x\n", ":2: score `x` is not a number"),
        ("2,-1,10,10,5,5,0.9\n3,-1,10,10,5,5,0.9\n1,-1,10,10,5,5,0.9\n", ":3: frame 1 comes after frame 3"),
        (
            "1,-1,10,10,5,5,0.9\n4294967296,-1,10,10,5,5,0.9\n",
            ":2: frame 4294967296 is not a whole number in 1..=4294967295",
        ),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let det = dir.path().join(format!("det{i}.txt"));
        std::fs::write(&det, text).expect("write");
        let err = run(args(det.clone(), dir.path().join("out.txt"))).expect_err(want);
        let msg = format!("{err:#}");
        assert!(msg.contains(&format!("det{i}.txt{want}")), "{msg}");
    }
    let err = run(args(dir.path().join("missing.txt"), dir.path().join("o.txt"))).expect_err("missing");
    assert!(format!("{err:#}").contains("missing.txt"));
    let mut a = args(dir.path().join("det0.txt"), dir.path().join("o.txt"));
    a.config.set = vec!["tracker.preset=bogus".into()];
    let err = run(a).expect_err("preset");
    assert_eq!(fme::cli::exit_code(&err), 2);
    assert!(format!("{err:#}").contains("tracker.preset"), "{err:#}");
}

#[test]
fn huge_frame_numbers_neither_allocate_nor_overflow() {
    let dir = tempfile::tempdir().expect("tempdir");
    let det = dir.path().join("det.txt");
    std::fs::write(&det, "1,-1,1,1,5,5,0.9\n4294967295,-1,1,1,5,5,0.9\n").expect("write");
    for (name, preset) in [("sort", TrackerPreset::Sort), ("default", TrackerPreset::Default)] {
        let out = dir.path().join(format!("{name}.txt"));
        let mut a = args(det.clone(), out.clone());
        a.preset = Some(preset);
        run(a).expect("runs");
        let text = std::fs::read_to_string(out).expect("read");
        assert!(text.lines().all(|l| l.starts_with("1,") || l.starts_with("4294967295,")), "{text}");
        // SORT outputs a track from its first hit (its warm-up frames); ByteTrack needs two hits.
        if preset == TrackerPreset::Sort {
            assert!(text.lines().any(|l| l.starts_with("1,")), "{name}: {text:?}");
        }
    }
}

#[test]
fn cli_writes_tracks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let det = dir.path().join("det.txt");
    let text: String = (1..=10).map(|f| format!("{f},-1,{},20,30,60,0.9,-1,-1,-1\n", 10 + 3 * f)).collect();
    std::fs::write(&det, text).expect("write");
    let out = dir.path().join("tracks.txt");
    run(args(det, out.clone())).expect("runs");
    let rows = std::fs::read_to_string(out).expect("read");
    let lines: Vec<&str> = rows.lines().collect();
    assert_eq!(lines.len(), 9, "confirmed from the second hit on:\n{rows}");
    assert!(lines.iter().all(|l| l.split(',').nth(1) == Some("1")));
    // Frame 2: the filtered box lies between the first detection (x 13) and the second (x 16).
    let x: f64 = lines[0].split(',').nth(2).and_then(|v| v.parse().ok()).expect("x");
    assert!(lines[0].starts_with("2,1,") && x > 13.0 && x <= 16.0, "{}", lines[0]);
    let last_x: f64 = lines[8].split(',').nth(2).and_then(|v| v.parse().ok()).expect("x");
    assert!((last_x - 40.0).abs() < 1.0, "{}", lines[8]);
}

#[test]
fn tracker_skips_invalid_detections_and_rejects_time_going_back() {
    for cfg in [TrackerConfig::default_preset(), TrackerConfig::sort()] {
        let mut t = Tracker::new(cfg);
        let bad = [
            Detection::new(PixelBox::new(f64::NAN, 0.0, 10.0, 10.0), 0.9),
            Detection::new(PixelBox::new(0.0, 0.0, -10.0, 10.0), 0.9),
            Detection::new(PixelBox::new(0.0, 0.0, 0.0, 10.0), 0.9),
            Detection::new(PixelBox::new(0.0, 0.0, 10.0, 10.0), f64::NAN),
            Detection::new(PixelBox::new(0.0, 0.0, f64::INFINITY, 10.0), 0.9),
        ];
        t.update(Seconds(0.0), &bad).expect("ok");
        assert_eq!(t.stats().invalid_dets, 5);
        assert_eq!(t.live_tracks(), 0);
        let e = t.update(Seconds(0.0), &[]).expect_err("same time");
        assert!(matches!(e, TrackError::TimeNotIncreasing { .. }));
        assert!(t.update(Seconds(-1.0), &[]).is_err());
        assert!(t.update(Seconds(f64::NAN), &[]).is_err());
        assert!(t.update(Seconds(1.0), &[]).is_ok());
        // Predicting ahead (a frame without detection) then updating at that time is fine; updating
        // before the predicted time is an error.
        t.predict(Seconds(2.0)).expect("predict");
        assert!(t.update(Seconds(1.5), &[]).is_err());
        assert!(t.update(Seconds(2.0), &[]).is_ok());
    }
}

#[test]
fn bad_depths_are_dropped_not_fatal() {
    use fme::units::Metres;
    let mut cfg = TrackerConfig::default_preset();
    cfg.depth_weight = 1.0;
    let mut t = Tracker::new(cfg);
    for k in 0..10 {
        let depth = match k % 4 {
            0 => Some(Metres(f64::NAN)),
            1 => Some(Metres(-2.0)),
            2 => Some(Metres(f64::INFINITY)),
            _ => Some(Metres(2.0)),
        };
        let d = Detection { depth, ..Detection::new(PixelBox::new(10.0 + k as f64, 10.0, 30.0, 20.0), 0.9) };
        let out = t.update(Seconds(k as f64 / 30.0), &[d]).expect("ok");
        if k >= 1 {
            assert_eq!(out.len(), 1, "frame {k}");
            assert_eq!(out[0].id, 1);
            assert!(out[0].depth.is_none_or(|z| z.get() == 2.0));
        }
    }
    assert_eq!(t.stats().invalid_dets, 0);
}
