//! What the parity of the two inference backends is measured on (tests/backend_parity.rs,
//! tests/backend_reference.rs, benches/backends.rs): the bundled models on the bundled recording
//! `tests/data/swarm20`. Detections of every third frame, four depth maps, and the activity series
//! of the whole pipeline over the 120 frames; and how two such outputs compare.
//!
//! The reference (ONNX Runtime's outputs) lives in tests/data/backend_reference/<set>.json with the
//! depth maps in <set>.depth (per map: u32 width, u32 height, f32 min, f32 max, then width x height
//! u16 values spanning min..max, little-endian; every second pixel of every second row of the map).

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use fme::capture::{Frame, FrameSource, RecordedSource};
use fme::config::Config;
use fme::infer::{Backend, DepthConfig, DepthNet, Detector, DetectorConfig, RgbFrame};
use fme::pipeline::{FishPipeline, Pipeline};
use fme::units::Seconds;
use serde::{Deserialize, Serialize};

pub const SEQ: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/swarm20");
/// Detections are compared on every `DET_STRIDE`-th frame.
pub const DET_STRIDE: usize = 3;
/// Frames (0-based) whose depth maps are compared.
pub const DEPTH_FRAMES: [usize; 4] = [0, 30, 60, 90];

/// The bundled model pairs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelSet {
    Int8,
    Fp32,
}

impl ModelSet {
    pub fn name(self) -> &'static str {
        match self {
            ModelSet::Int8 => "int8",
            ModelSet::Fp32 => "fp32",
        }
    }
    pub fn detector(self) -> PathBuf {
        repo(&format!("models/fish_det_{}.onnx", self.name()))
    }
    pub fn depth(self) -> PathBuf {
        repo(&format!("models/fish_depth_{}.onnx", self.name()))
    }
    /// The daemon's configuration with this set's models.
    pub fn config(self) -> Config {
        let mut c = Config::default();
        c.source.path = SEQ.into();
        c.detector.model = self.detector();
        c.depth.model = self.depth();
        c
    }
}

pub fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The recording's 120 frames.
pub fn frames() -> Vec<Frame> {
    let mut src = RecordedSource::open(Path::new(SEQ), false, false).expect("open the bundled recording");
    let mut out = Vec::new();
    while let Ok(f) = src.next_frame(Vec::new()) {
        out.push(f);
    }
    assert_eq!(out.len(), 120, "tests/data/swarm20 has 120 frames");
    out
}

/// A depth map, every second pixel of every second row.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

/// One backend's outputs on one model set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outputs {
    /// FNV-1a 64 of the detector and depth files the outputs come from.
    pub models: [String; 2],
    /// Per compared frame: `[x, y, w, h, score]` in frame pixels, after NMS.
    pub detections: Vec<Vec<[f32; 5]>>,
    /// The pipeline's activity (eq. 5, m/s) per frame; `None` before a fish is old enough.
    pub activity: Vec<Option<f64>>,
    #[serde(skip)]
    pub depth: Vec<Map>,
}

pub fn fnv1a(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

pub fn model_hashes(set: ModelSet) -> [String; 2] {
    let read = |p: PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    [fnv1a(&read(set.detector())), fnv1a(&read(set.depth()))]
}

fn rgb(frame: &Frame, buf: &mut Vec<u8>) -> (u32, u32) {
    frame.to_rgb_into(buf).expect("frame decodes to RGB")
}

/// Runs `backend` on `set`: the detector and depth network alone, then the whole pipeline.
pub fn compute(backend: Backend, set: ModelSet, frames: &[Frame]) -> Outputs {
    let cfg = set.config();
    let dcfg = DetectorConfig { model: set.detector(), ..cfg.detector.clone() };
    let mut det = Detector::open_with(&dcfg, dcfg.session(), backend).expect("detector opens");
    let zcfg = DepthConfig { model: set.depth(), ..cfg.depth.clone() };
    let mut depth = DepthNet::open_with(&zcfg, zcfg.session(), backend).expect("depth network opens");
    let mut buf = Vec::new();
    let mut detections = Vec::new();
    for (i, f) in frames.iter().enumerate().step_by(DET_STRIDE) {
        let (w, h) = rgb(f, &mut buf);
        let frame = RgbFrame::new(w, h, &buf).expect("rgb frame");
        let d = det.detect(&frame, Seconds(i as f64 / 30.0)).expect("detector runs");
        let b = |d: &fme::infer::Detection| [d.bbox.x, d.bbox.y, d.bbox.w, d.bbox.h, d.score].map(|v| v as f32);
        detections.push(d.items.iter().map(b).collect());
    }
    let mut maps = Vec::new();
    for &i in &DEPTH_FRAMES {
        let (w, h) = rgb(&frames[i], &mut buf);
        let frame = RgbFrame::new(w, h, &buf).expect("rgb frame");
        let m = depth.estimate(&frame, Seconds(i as f64 / 30.0)).expect("depth network runs");
        let (mw, mh) = m.dims();
        let mut data = Vec::new();
        for y in (0..mh as usize).step_by(2) {
            data.extend(m.data()[y * mw as usize..][..mw as usize].iter().step_by(2));
        }
        maps.push(Map { width: mw.div_ceil(2), height: mh.div_ceil(2), data });
    }
    Outputs { models: model_hashes(set), detections, activity: activity(backend, set, frames), depth: maps }
}

/// The activity series of the daemon's pipeline with `backend` on `set`.
pub fn activity(backend: Backend, set: ModelSet, frames: &[Frame]) -> Vec<Option<f64>> {
    let cal = fme::calibration::load(&Path::new(SEQ).join("meta.json")).expect("calibration");
    let mut p = FishPipeline::with_backend(&set.config().pipeline(), Some(cal), backend).expect("pipeline");
    frames
        .iter()
        .map(|f| p.process(f).expect("frame processed").sample.map(|s| s.mean.0).filter(|m| m.is_finite()))
        .collect()
}

fn reference_path(set: ModelSet, ext: &str) -> PathBuf {
    repo(&format!("tests/data/backend_reference/{}.{ext}", set.name()))
}

/// Writes `o` as the reference of `set`.
pub fn save_reference(set: ModelSet, o: &Outputs) {
    let dir = repo("tests/data/backend_reference");
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let json = serde_json::to_string(o).expect("serialise");
    let p = reference_path(set, "json");
    std::fs::write(&p, json + "\n").unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut bin = Vec::new();
    for m in &o.depth {
        let lo = m.data.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = m.data.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        bin.extend(m.width.to_le_bytes());
        bin.extend(m.height.to_le_bytes());
        bin.extend(lo.to_le_bytes());
        bin.extend(hi.to_le_bytes());
        let span = (hi - lo).max(f32::MIN_POSITIVE);
        for v in &m.data {
            bin.extend((((v - lo) / span * 65535.0).round() as u16).to_le_bytes());
        }
    }
    let p = reference_path(set, "depth");
    std::fs::write(&p, bin).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
}

/// The reference of `set`; panics naming the file and how to write it when it is missing or stale.
pub fn load_reference(set: ModelSet) -> Outputs {
    let regen = "write it with `FME_WRITE_BACKEND_REFERENCE=1 cargo test --test backend_reference` (ONNX Runtime)";
    let p = reference_path(set, "json");
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}; {regen}", p.display()));
    let mut o: Outputs = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    assert_eq!(o.models, model_hashes(set), "{}: made from other model files; {regen}", p.display());
    let p = reference_path(set, "depth");
    let bin = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}; {regen}", p.display()));
    let mut rest = &bin[..];
    let mut take = |n: usize| -> &[u8] {
        assert!(rest.len() >= n, "{}: truncated", p.display());
        let (a, b) = rest.split_at(n);
        rest = b;
        a
    };
    for _ in DEPTH_FRAMES {
        let u32_at = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let head = take(16);
        let (width, height) = (u32_at(&head[0..4]), u32_at(&head[4..8]));
        let (lo, hi) = (f32::from_bits(u32_at(&head[8..12])), f32::from_bits(u32_at(&head[12..16])));
        let n = width as usize * height as usize;
        let data = take(2 * n)
            .chunks_exact(2)
            .map(|c| lo + f32::from(u16::from_le_bytes([c[0], c[1]])) / 65535.0 * (hi - lo))
            .collect();
        o.depth.push(Map { width, height, data });
    }
    assert!(rest.is_empty(), "{}: {} bytes too many", p.display(), rest.len());
    o
}

/// How one backend's outputs compare with another's (`a` the reference).
#[derive(Debug, Clone, Copy)]
pub struct Parity {
    /// Detections (all compared frames) of `a` and of `b`.
    pub count_a: usize,
    pub count_b: usize,
    /// Detection pairs matched at IoU >= 0.5 (greedy, best IoU first, per frame).
    pub matched: usize,
    /// Mean IoU of the matched pairs.
    pub mean_iou: f64,
    /// Smallest Pearson r of the depth maps.
    pub depth_r: f64,
    /// RMSE of the activity series (frames where both have a value) over the mean of `a`'s.
    pub activity_rmse: f64,
    /// Frames where exactly one of the two has an activity value.
    pub activity_only_one: usize,
    /// Frames where `a` has an activity value.
    pub activity_frames: usize,
}

impl Parity {
    /// |count_a - count_b| / count_a.
    pub fn count_diff(&self) -> f64 {
        (self.count_a as f64 - self.count_b as f64).abs() / self.count_a.max(1) as f64
    }
}

impl std::fmt::Display for Parity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "detections {} vs {} ({:.2}%), matched {}, mean IoU {:.5}; depth r (min of {} maps) {:.6}; activity RMSE {:.3}% \
             over {} frames, {} frames with a value on one side only",
            self.count_a,
            self.count_b,
            100.0 * self.count_diff(),
            self.matched,
            self.mean_iou,
            DEPTH_FRAMES.len(),
            self.depth_r,
            100.0 * self.activity_rmse,
            self.activity_frames,
            self.activity_only_one
        )
    }
}

fn iou(a: &[f32; 5], b: &[f32; 5]) -> f64 {
    let (ax1, ay1, ax2, ay2) = (a[0], a[1], a[0] + a[2], a[1] + a[3]);
    let (bx1, by1, bx2, by2) = (b[0], b[1], b[0] + b[2], b[1] + b[3]);
    let iw = (ax2.min(bx2) - ax1.max(bx1)).max(0.0);
    let ih = (ay2.min(by2) - ay1.max(by1)).max(0.0);
    let inter = f64::from(iw * ih);
    let union = f64::from(a[2] * a[3] + b[2] * b[3]) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

fn pearson(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "depth maps of different sizes");
    let n = a.len() as f64;
    let ma = a.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let mb = b.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (f64::from(x) - ma, f64::from(y) - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    sab / (saa * sbb).sqrt()
}

/// Compares `b` with the reference `a`.
pub fn compare(a: &Outputs, b: &Outputs) -> Parity {
    assert_eq!(a.detections.len(), b.detections.len(), "compared frames");
    let (mut matched, mut iou_sum) = (0usize, 0.0);
    for (fa, fb) in a.detections.iter().zip(&b.detections) {
        let mut pairs: Vec<(f64, usize, usize)> = fa
            .iter()
            .enumerate()
            .flat_map(|(i, da)| fb.iter().enumerate().map(move |(j, db)| (iou(da, db), i, j)))
            .filter(|p| p.0 >= 0.5)
            .collect();
        pairs.sort_by(|x, y| y.0.total_cmp(&x.0));
        let (mut used_a, mut used_b) = (vec![false; fa.len()], vec![false; fb.len()]);
        for (v, i, j) in pairs {
            if !used_a[i] && !used_b[j] {
                used_a[i] = true;
                used_b[j] = true;
                matched += 1;
                iou_sum += v;
            }
        }
    }
    assert_eq!(a.depth.len(), b.depth.len(), "compared depth maps");
    let depth_r = a
        .depth
        .iter()
        .zip(&b.depth)
        .map(|(x, y)| {
            assert_eq!((x.width, x.height), (y.width, y.height), "depth map sizes");
            pearson(&x.data, &y.data)
        })
        .fold(f64::INFINITY, f64::min);
    assert_eq!(a.activity.len(), b.activity.len(), "activity series lengths");
    let both: Vec<(f64, f64)> = a.activity.iter().zip(&b.activity).filter_map(|(x, y)| Some(((*x)?, (*y)?))).collect();
    let only_one = a.activity.iter().zip(&b.activity).filter(|(x, y)| x.is_some() != y.is_some()).count();
    let mean_a = both.iter().map(|p| p.0.abs()).sum::<f64>() / both.len().max(1) as f64;
    let rmse = (both.iter().map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / both.len().max(1) as f64).sqrt();
    Parity {
        count_a: a.detections.iter().map(Vec::len).sum(),
        count_b: b.detections.iter().map(Vec::len).sum(),
        matched,
        mean_iou: if matched > 0 { iou_sum / matched as f64 } else { 0.0 },
        depth_r,
        activity_rmse: if both.is_empty() { f64::INFINITY } else { rmse / mean_a },
        activity_only_one: only_one,
        activity_frames: a.activity.iter().filter(|x| x.is_some()).count(),
    }
}

/// The bounds one comparison must meet.
#[derive(Debug, Clone, Copy)]
pub struct Bounds {
    pub mean_iou: f64,
    pub count_diff: f64,
    pub depth_r: f64,
    pub activity_rmse: f64,
    /// Most frames with an activity value on one side only.
    pub activity_only_one: usize,
}

/// Panics with every figure when `p` misses a bound.
pub fn check(what: &str, p: &Parity, b: &Bounds) {
    eprintln!("{what}: {p}");
    let mut missed = Vec::new();
    if p.mean_iou.is_nan() || p.mean_iou < b.mean_iou {
        missed.push(format!("mean IoU {:.5} < {}", p.mean_iou, b.mean_iou));
    }
    if p.count_diff() > b.count_diff {
        missed.push(format!("detection counts differ by {:.2}% > {}%", 100.0 * p.count_diff(), 100.0 * b.count_diff));
    }
    if p.depth_r.is_nan() || p.depth_r < b.depth_r {
        missed.push(format!("depth Pearson r {:.6} < {}", p.depth_r, b.depth_r));
    }
    if p.activity_rmse.is_nan() || p.activity_rmse > b.activity_rmse {
        missed.push(format!("activity RMSE {:.3}% > {}%", 100.0 * p.activity_rmse, 100.0 * b.activity_rmse));
    }
    if p.activity_only_one > b.activity_only_one {
        missed.push(format!("{} frames with activity on one side only > {}", p.activity_only_one, b.activity_only_one));
    }
    if p.activity_frames < 60 {
        missed.push(format!("only {} frames with activity in the reference", p.activity_frames));
    }
    assert!(missed.is_empty(), "{what}: {}\n({p})", missed.join("; "));
}
