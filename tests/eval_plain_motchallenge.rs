//! `fme eval` on a plain MOTChallenge folder (`seqinfo.ini`, `img1/`, `gt/gt.txt`; no `meta.json`,
//! no `depth/`, no `gt/world.csv`), made from the bundled recording tests/data/swarm20: detection,
//! tracking, depth consistency and the activity with the fish as the ruler are reported, the speed
//! is not scored and the report says why; only the first `seqLength` frames count.

use std::path::Path;
use std::process::Command;

const SRC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/swarm20");

/// A plain folder with frames `1..=jpgs` of swarm20 and `seqinfo.ini` saying `seq_length`
/// (gt.txt rows up to `seq_length`).
fn plain_folder(dir: &Path, jpgs: u32, seq_length: u32) {
    let src = Path::new(SRC);
    std::fs::create_dir_all(dir.join("img1")).expect("img1");
    std::fs::create_dir_all(dir.join("gt")).expect("gt");
    let ini = std::fs::read_to_string(src.join("seqinfo.ini")).expect("seqinfo.ini");
    assert!(ini.contains("seqLength=120"), "{ini}");
    std::fs::write(dir.join("seqinfo.ini"), ini.replace("seqLength=120", &format!("seqLength={seq_length}")))
        .expect("write seqinfo.ini");
    for k in 1..=jpgs {
        let name = format!("{k:06}.jpg");
        std::fs::copy(src.join("img1").join(&name), dir.join("img1").join(&name)).expect("copy frame");
    }
    let gt = std::fs::read_to_string(src.join("gt/gt.txt")).expect("gt.txt");
    let rows: String = gt
        .lines()
        .filter(|l| l.split(',').next().and_then(|f| f.parse::<u32>().ok()).is_some_and(|f| f <= seq_length))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(dir.join("gt/gt.txt"), rows).expect("write gt.txt");
    assert!(!dir.join("meta.json").exists());
}

fn eval(dir: &Path, args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_fme"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["eval", "--json", "--sequence"])
        .arg(dir)
        .args(args)
        .output()
        .expect("run fme eval");
    assert!(out.status.success(), "fme eval {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("fme eval --json prints JSON")
}

fn absent(j: &serde_json::Value) -> String {
    j["absent"].as_array().expect("absent is a list").iter().filter_map(|a| a.as_str()).collect::<Vec<_>>().join("; ")
}

#[test]
fn a_plain_folder_is_scored_for_detection_tracking_and_activity() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("plain");
    plain_folder(&dir, 120, 120);

    let j = eval(&dir, &["--boxes", "model", "--depth", "model"]);
    let d = &j["detection"];
    assert!(d["precision"].as_f64().is_some_and(|p| p > 0.9), "{j}");
    assert!(d["recall"].as_f64().is_some_and(|r| r > 0.9), "{j}");
    assert!(j["mota"].as_f64().is_some_and(|m| m > 0.8) && j["idf1"].as_f64().is_some_and(|m| m > 0.8), "{j}");
    // No calibration, no references: the fish are the ruler, and the activity is in body lengths/s.
    assert_eq!(j["scale_source"], "fish", "{j}");
    assert!(j["activity_frames"].as_u64().is_some_and(|n| n > 30), "{j}");
    let bls = j["mean_activity_bls"].as_f64().unwrap_or(f64::NAN);
    assert!(bls > 0.2 && bls < 3.0, "activity {bls} BL/s: {j}");
    assert!(j["depth_consistency"].as_f64().is_some_and(|c| c > 0.0), "{j}");
    assert!(j["depth_consistency_frames"].as_u64().is_some_and(|n| n >= 15), "{j}");
    // No speed truth: nothing scored for speed, and the report says so.
    assert_eq!(j["frames"].as_u64(), Some(0), "{j}");
    assert!(j["speed_rmse_mps"].is_null(), "{j}");
    let why = absent(&j);
    assert!(why.contains("gt/world.csv") && why.contains("depth/"), "{why}");

    let g = eval(&dir, &["--boxes", "gt", "--depth", "model"]);
    assert_eq!(g["scale_source"], "fish", "{g}");
    assert!(g["mean_activity_bls"].as_f64().is_some_and(|b| b > 0.2 && b < 3.0), "{g}");
    assert!(g["depth_consistency"].as_f64().is_some_and(|c| c > 0.0), "{g}");
    assert!(g["detection"].is_null() && g["mota"].is_null(), "{g}");
    assert!(absent(&g).contains("detection and tracking"), "{g}");
    // The depth network sees the same frames whatever the boxes: the same consistency.
    assert_eq!(g["depth_consistency"], j["depth_consistency"]);
}

/// Images beyond `seqLength` are not part of the sequence: 60 JPEGs under `seqLength=40` score as
/// exactly 40 (they would otherwise be frames without truth, every detection a false positive).
#[test]
fn only_seq_length_frames_are_scored() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let (extra, exact) = (tmp.path().join("extra"), tmp.path().join("exact"));
    plain_folder(&extra, 60, 40);
    plain_folder(&exact, 40, 40);
    let series = tmp.path().join("series.csv");
    let args = ["--boxes", "model", "--depth", "model", "--series", series.to_str().expect("utf-8 path")];
    let a = eval(&extra, &args);
    let rows = std::fs::read_to_string(&series).expect("series").lines().count();
    assert_eq!(rows, 41, "a header and one row per frame of seqLength");
    let b = eval(&exact, &args);
    assert_eq!(a["detection"], b["detection"], "extra JPEGs changed the detection score");
    assert_eq!(a["false_positives"], b["false_positives"]);
    assert_eq!(a["mota"], b["mota"]);
}
