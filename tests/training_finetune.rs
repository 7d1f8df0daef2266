//! The training recipes, where they need the training Python stack: `make -C training finetune
//! DATA=DIR` (docs/training.md "Train on your own cage") on tiny labelled folders in the two layouts
//! CVAT exports, "MOT 1.1" (`img1/` + `gt/gt.txt`, no seqinfo.ini) and "YOLO 1.1" (`obj_train_data/`
//! with a label file beside each image), made from frames of the bundled recording: the recipe
//! starts from the bundled detector, writes a model pair that fme loads, and reports P / R on the
//! held-out part of the data before and after. Also the real-fish recipe's fish zoom and its score
//! calibration for the tracker (`training/calibrate.py`).
//!
//! Needs the training Python stack that `make test` installs first (`make setup-training`,
//! FME_TRAINING_VENV or /tmp/venv-infer); without it the test fails and says so.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

const REC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/swarm20");
const W: f64 = 640.0;
const H: f64 = 384.0;

fn venv() -> PathBuf {
    let v = PathBuf::from(std::env::var("FME_TRAINING_VENV").unwrap_or_else(|_| "/tmp/venv-infer".into()));
    assert!(
        v.join("bin/python").exists(),
        "no training Python stack at {} (run `make setup-training`, as `make test` does)",
        v.display()
    );
    v
}

/// The training venv's Python in `training/` at the recipes' 480x288 input: (success, stdout + stderr).
fn training_py(args: &[&str]) -> (bool, String) {
    let run = Command::new(venv().join("bin/python"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/training"))
        .env("FME_NET", "480x288")
        .output()
        .expect("python runs");
    let log = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    (run.status.success(), log)
}

/// gt rows of the recording by frame: (x, y, w, h) of the fish at least half visible.
fn gt_rows() -> Vec<(u32, String)> {
    let text = fs::read_to_string(Path::new(REC).join("gt/gt.txt")).expect("recording gt");
    text.lines()
        .filter_map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            let vis: f64 = v.get(8)?.parse().ok()?;
            (vis >= 0.5).then(|| (v[0].parse().ok().unwrap_or(0), l.to_string()))
        })
        .collect()
}

/// A CVAT "MOT 1.1" export of frames 1..=n: img1/NNNNNN.jpg and gt/gt.txt (CVAT's nine columns).
fn mot_export(dir: &Path, n: u32) {
    fs::create_dir_all(dir.join("img1")).unwrap();
    fs::create_dir_all(dir.join("gt")).unwrap();
    for f in 1..=n {
        let name = format!("{f:06}.jpg");
        fs::copy(Path::new(REC).join("img1").join(&name), dir.join("img1").join(&name)).unwrap();
    }
    let rows: Vec<String> = gt_rows()
        .into_iter()
        .filter(|(f, _)| *f <= n)
        .map(|(_, l)| {
            let v: Vec<&str> = l.split(',').collect();
            format!("{},{},{},{},{},{},1,1,1.0", v[0], v[1], v[2], v[3], v[4], v[5])
        })
        .collect();
    fs::write(dir.join("gt/gt.txt"), rows.join("\n") + "\n").unwrap();
    fs::write(dir.join("gt/labels.txt"), "fish\n").unwrap();
}

/// A CVAT "YOLO 1.1" export of frames first..=last: obj.names, obj.data, obj_train_data/*.jpg + .txt.
fn yolo_export(dir: &Path, first: u32, last: u32) {
    let data = dir.join("obj_train_data");
    fs::create_dir_all(&data).unwrap();
    fs::write(dir.join("obj.names"), "fish\n").unwrap();
    fs::write(dir.join("obj.data"), "classes = 1\nnames = obj.names\ntrain = train.txt\n").unwrap();
    let rows = gt_rows();
    for f in first..=last {
        let name = format!("frame_{f:06}");
        fs::copy(Path::new(REC).join(format!("img1/{f:06}.jpg")), data.join(format!("{name}.jpg"))).unwrap();
        let mut labels = String::new();
        for (_, l) in rows.iter().filter(|(g, _)| *g == f) {
            let v: Vec<f64> = l.split(',').skip(2).take(4).map(|s| s.parse().unwrap()).collect();
            let (x0, y0) = (v[0].max(0.0), v[1].max(0.0));
            let (x1, y1) = ((v[0] + v[2]).min(W), (v[1] + v[3]).min(H));
            if x1 - x0 < 2.0 || y1 - y0 < 2.0 {
                continue;
            }
            let (cx, cy, w, h) = ((x0 + x1) / 2.0 / W, (y0 + y1) / 2.0 / H, (x1 - x0) / W, (y1 - y0) / H);
            labels += &format!("0 {cx:.6} {cy:.6} {w:.6} {h:.6}\n");
        }
        fs::write(data.join(format!("{name}.txt")), labels).unwrap();
    }
}

fn finetune(data: &str, out: &Path, venv: &Path) -> std::process::Output {
    Command::new("make")
        .args(["--no-print-directory", "-C", concat!(env!("CARGO_MANIFEST_DIR"), "/training"), "finetune"])
        .arg(format!("DATA={data}"))
        .arg(format!("OUT={}", out.display()))
        .arg("BUDGET_S=4")
        .arg(format!("VENV={}", venv.display()))
        .output()
        .expect("make runs")
}

#[test]
fn finetune_on_cvat_exports_writes_a_model_pair_fme_runs() {
    let venv = venv();
    let tmp = tempfile::tempdir().unwrap();
    let (mot, yolo, out) = (tmp.path().join("cage-mot"), tmp.path().join("cage-yolo"), tmp.path().join("out"));
    mot_export(&mot, 40);
    yolo_export(&yolo, 41, 56);
    let run = finetune(&format!("{} {}", mot.display(), yolo.display()), &out, &venv);
    let log = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "finetune failed:\n{log}");
    for f in ["fish_det_fp32.onnx", "fish_det_int8.onnx", "metrics.json"] {
        assert!(out.join(f).exists(), "{f} not written:\n{log}");
    }
    // Held out: the last 15 % of the recording's frames and the YOLO folder's held-out groups (or,
    // with none, its training part), scored before and after.
    let m: serde_json::Value = serde_json::from_str(&fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let real_train = &m["data"]["real_train"];
    assert_eq!(real_train["cage-mot/."].as_u64(), Some(34), "MOT training frames: {real_train}");
    assert_eq!(m["data"]["held_out"]["cage-mot/."].as_u64(), Some(6), "{}", m["data"]);
    assert!(m["before"]["cage-mot/."][0]["precision"].is_number(), "no before-score: {}", m["before"]);
    assert!(m["int8_u8s8"]["quality"]["cage-mot/."][0]["recall"].is_number());

    // fme loads the fine-tuned int8 file and it still finds the recording's fish (a few seconds of
    // fine-tuning from a detector with P / R 0.99 there do not undo it).
    let eval = Command::new(env!("CARGO_BIN_EXE_fme"))
        .args(["eval", "--sequence", REC, "--boxes", "model", "--depth", "gt", "--json", "--det-model"])
        .arg(out.join("fish_det_int8.onnx"))
        .output()
        .unwrap();
    assert!(eval.status.success(), "fme eval: {}", String::from_utf8_lossy(&eval.stderr));
    let r: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    let (p, rc) = (r["detection"]["precision"].as_f64(), r["detection"]["recall"].as_f64());
    assert!(p.unwrap_or(0.0) > 0.8 && rc.unwrap_or(0.0) > 0.8, "fine-tuned detector: P {p:?} R {rc:?}");
}

#[test]
fn finetune_names_a_missing_data_folder() {
    let venv = venv();
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-recording");
    let run = finetune(&missing.display().to_string(), &tmp.path().join("out"), &venv);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("no-such-recording") && err.contains("does not exist"), "{err}");
}

/// The recipe's `--fish-zoom` augmentation (`det.zoom_to_fish`): a window around one fish, scaled so
/// that its long side lands in 64-320 px (at most 6x); the fish's box follows its pixels; frames with
/// no fish it may enlarge are left alone.
#[test]
fn fish_zoom_enlarges_one_whole_fish_and_moves_its_box_with_it() {
    let script = r#"
import numpy as np, det
rng = np.random.default_rng(0)
img = np.zeros((288, 480, 3), np.uint8)
img[100:112, 200:230] = 255                      # a 30 x 12 px fish
img[20:26, 20:30] = 128                          # a 10 px fish: too small to enlarge
boxes = np.array([[200, 100, 30, 12, 1.0], [20, 20, 10, 6, 1.0]], np.float32)
longs = []
for _ in range(100):
    out, b, cut = det.zoom_to_fish(img, boxes, rng)
    x, y, w, h = b[0, :4]
    longs.append(max(w, h))
    assert 63.9 <= max(w, h) <= 180.1, b[0]     # 64-320 px, at most 6 x 30 px
    assert not cut[0] and x >= -1 and y >= -1 and x + w <= 481 and y + h <= 289, b[0]
    ys, xs = np.nonzero(out[:, :, 0] > 127)         # half-way between the fish and the water
    assert abs(xs.min() - x) <= 1.5 and abs(xs.max() + 1 - (x + w)) <= 1.5, (xs.min(), xs.max(), b[0])
    assert abs(ys.min() - y) <= 1.5 and abs(ys.max() + 1 - (y + h)) <= 1.5, (ys.min(), ys.max(), b[0])
assert max(longs) - min(longs) > 60, (min(longs), max(longs))
assert det.zoom_to_fish(img, boxes[1:], rng) is None
assert det.zoom_to_fish(img, np.array([[200, 100, 30, 12, 0.1]], np.float32), rng) is None
assert det.zoom_to_fish(img, np.zeros((0, 5), np.float32), rng) is None
print("ok")
"#;
    let (ok, log) = training_py(&["-c", script]);
    assert!(ok && log.contains("ok"), "{log}");
}

/// `training/calibrate.py`: the score map for the tracker keeps every box fme finds at its confidence
/// threshold (the same detections on the recording), its fit recovers a known map, a reference
/// detector of another input size is fed the frames letterboxed to its own (the same fish found), and
/// a calibrated file is not calibrated twice.
#[test]
fn score_calibration_keeps_the_detections_and_its_fit_recovers_a_known_map() {
    let tmp = tempfile::tempdir().unwrap();
    let cal = tmp.path().join("cal_int8.onnx");
    let bundled = concat!(env!("CARGO_MANIFEST_DIR"), "/models/fish_det_int8.onnx");
    let renders = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");
    let c = cal.to_str().unwrap();
    let (ok, log) = training_py(&["calibrate.py", bundled, c, "--renders", renders, "--slope", "1.6"]);
    assert!(ok, "calibrate.py: {log}");
    // Mapping the calibrated file back onto the bundled one's scores takes the inverse slope.
    let fit = format!(
        "import calibrate, data\nims, b, _, _ = data.load_many({renders:?}, every=5, with_depth=False)\n\
         s, r = (calibrate.true_scores(f, ims, b, 0.3) for f in ({c:?}, {bundled:?}))\n\
         a, rep = calibrate.fit(s, r, 0.3)\nassert abs(a - 1 / 1.6) < 0.01, rep\n\
         assert calibrate.score_map_of({c:?}) == (1.6, 0.3)\n\
         import cv2, numpy as np\nk = np.array([416 / 480, 256 / 288, 416 / 480, 256 / 288, 1], np.float32)\n\
         small = [cv2.resize(i, (416, 256), interpolation=cv2.INTER_AREA) for i in ims]\n\
         r2 = calibrate.true_scores({bundled:?}, small, [g * k for g in b], 0.3)\n\
         assert abs(len(r2) - len(r)) <= 0.05 * len(r) and abs(np.median(r2) - np.median(r)) < 0.03, (len(r2), len(r))\n\
         print('ok')"
    );
    let (ok, log) = training_py(&["-c", &fit]);
    assert!(ok && log.contains("ok"), "{log}");
    let (ok, log) =
        training_py(&["calibrate.py", c, tmp.path().join("twice.onnx").to_str().unwrap(), "--renders", renders]);
    assert!(!ok && log.contains("already calibrated"), "{log}");

    let detection = |model: &str| {
        let eval = Command::new(env!("CARGO_BIN_EXE_fme"))
            .args(["eval", "--sequence", REC, "--boxes", "model", "--depth", "gt", "--json", "--det-model", model])
            .output()
            .unwrap();
        assert!(eval.status.success(), "fme eval {model}: {}", String::from_utf8_lossy(&eval.stderr));
        let r: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
        r["detection"].clone()
    };
    let (before, after) = (detection(bundled), detection(c));
    assert!(before["tp"].as_u64().unwrap_or(0) > 0, "{before}");
    assert_eq!(before, after, "the map changed which boxes fme keeps");
}
