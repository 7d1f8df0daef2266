//! Grid search of tracker thresholds (the paper's Table 1) on sequences with ground truth.
//!
//! Pure functions: detections are synthesised from ground truth with seeded, realistic noise
//! ([`DetNoise`]: position/size jitter, misses that grow with occlusion, scores that drop with
//! occlusion, false positives), every grid point runs the tracker on every sequence, and the runs
//! are scored with [`crate::mot::MotAccumulator`] and pooled over sequences. `fme tune` adds the
//! I/O, threads and progress bar.

use crate::mot::{MotAccumulator, MotMetrics};
use crate::rng::Rng;
use fme_core::geometry::PixelBox;
use fme_core::track::{Detection, MAX_TRACKS, Tracker, TrackerConfig};
use fme_core::units::{Metres, Seconds};

/// One ground-truth box with what detection noise depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GtObs {
    /// Frame, from 1.
    pub frame: u32,
    /// Object id.
    pub id: i64,
    /// Box.
    pub bbox: PixelBox,
    /// Visible fraction in `[0, 1]`.
    pub visibility: f64,
    /// True camera depth, when known.
    pub depth: Option<f64>,
}

/// A sequence prepared for tuning.
#[derive(Debug, Clone)]
pub struct TuneSequence {
    /// Name for reports.
    pub name: String,
    /// Frames per second.
    pub fps: f64,
    /// Number of frames.
    pub frames: u32,
    /// Image size, pixels.
    pub width: f64,
    /// Image height, pixels.
    pub height: f64,
    /// Ground truth, any order.
    pub gt: Vec<GtObs>,
}

/// Noise of the synthetic detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetNoise {
    /// Probability of missing a fully visible object (grows to `miss + 0.5` at visibility 0).
    pub miss: f64,
    /// Standard deviation of the centre and size, as a fraction of the box size.
    pub jitter: f64,
    /// Mean number of false positives per frame (Poisson).
    pub fp_per_frame: f64,
    /// Relative standard deviation of the depth attached to detections.
    pub depth_noise: f64,
    /// Detect only every k-th frame (1 = every frame).
    pub every: u32,
}

impl Default for DetNoise {
    fn default() -> Self {
        Self { miss: 0.05, jitter: 0.05, fp_per_frame: 0.5, depth_noise: 0.05, every: 1 }
    }
}

/// The generator of this module's synthetic data (detections, test swarms) for `seed`. Its stream is
/// fixed (the scrambling of the seed differs from [`Rng::new`]'s and predates the merge of the
/// crate's two generators), so tuning results and `fme eval --boxes tracker` figures stay the same
/// for a given seed.
fn tune_rng(seed: u64) -> Rng {
    Rng::from_state(seed ^ 0x9E37_79B9_7F4A_7C15)
}

/// Synthesises detections per frame (index 0 = frame 1) from ground truth.
pub fn synth_detections(seq: &TuneSequence, noise: &DetNoise, seed: u64) -> Vec<Vec<Detection>> {
    let mut rng = tune_rng(seed);
    let mut frames: Vec<Vec<Detection>> = vec![Vec::new(); seq.frames as usize];
    let mut gt = seq.gt.clone();
    gt.sort_by_key(|g| (g.frame, g.id));
    for g in &gt {
        let Some(slot) = frames.get_mut(g.frame as usize - 1) else { continue };
        let v = g.visibility.clamp(0.0, 1.0);
        if v <= 0.05 || rng.uniform() < noise.miss + 0.5 * (1.0 - v) {
            continue;
        }
        let b = g.bbox;
        let (cx, cy) =
            (b.x + b.w / 2.0 + rng.normal() * noise.jitter * b.w, b.y + b.h / 2.0 + rng.normal() * noise.jitter * b.h);
        let w = (b.w * (1.0 + rng.normal() * noise.jitter)).max(2.0);
        let h = (b.h * (1.0 + rng.normal() * noise.jitter)).max(2.0);
        let score = (0.95 - 0.6 * (1.0 - v) + 0.08 * rng.normal()).clamp(0.05, 1.0);
        let depth = g.depth.map(|z| Metres(z * (1.0 + noise.depth_noise * rng.normal())));
        slot.push(Detection { depth, ..Detection::new(PixelBox::new(cx - w / 2.0, cy - h / 2.0, w, h), score) });
    }
    // False positives: sizes borrowed from real boxes, anywhere in the image.
    if !gt.is_empty() {
        for slot in frames.iter_mut() {
            for _ in 0..rng.poisson(noise.fp_per_frame) {
                let model = gt[(rng.uniform() * gt.len() as f64) as usize % gt.len()];
                let (w, h) = (model.bbox.w.max(4.0), model.bbox.h.max(4.0));
                let x = rng.uniform() * (seq.width - w).max(1.0);
                let y = rng.uniform() * (seq.height - h).max(1.0);
                let score = 0.1 + 0.6 * rng.uniform();
                let depth = model.depth.map(|z| Metres(z * (0.7 + 0.6 * rng.uniform())));
                slot.push(Detection { depth, ..Detection::new(PixelBox::new(x, y, w, h), score) });
            }
        }
    }
    if noise.every > 1 {
        for (i, slot) in frames.iter_mut().enumerate() {
            if !(i as u32).is_multiple_of(noise.every) {
                slot.clear();
            }
        }
    }
    frames
}

/// Runs the tracker on per-frame detections and scores it against the sequence's ground truth.
/// With `every > 1` the tracker only sees every k-th frame but is scored on those frames only.
pub fn evaluate(cfg: TrackerConfig, seq: &TuneSequence, dets: &[Vec<Detection>], every: u32) -> MotMetrics {
    evaluate_with(cfg, seq, dets, every, true)
}

/// [`evaluate`], optionally without HOTA (faster; HOTA fields NaN).
pub fn evaluate_with(
    cfg: TrackerConfig,
    seq: &TuneSequence,
    dets: &[Vec<Detection>],
    every: u32,
    hota: bool,
) -> MotMetrics {
    let mut tracker = Tracker::new(cfg);
    let mut gt_by_frame: Vec<Vec<(i64, PixelBox)>> = vec![Vec::new(); seq.frames as usize];
    for g in &seq.gt {
        if let Some(v) = gt_by_frame.get_mut(g.frame as usize - 1) {
            v.push((g.id, g.bbox));
        }
    }
    let mut acc = if hota { MotAccumulator::new() } else { MotAccumulator::new().without_hota() };
    let mut hyp = Vec::with_capacity(MAX_TRACKS);
    let every = every.max(1) as usize;
    for (i, d) in dets.iter().enumerate().step_by(every) {
        let t = Seconds(i as f64 / seq.fps);
        hyp.clear();
        if let Ok(out) = tracker.update(t, d) {
            hyp.extend(out.iter().map(|o| (i64::from(o.id), o.bbox)));
        }
        acc.update(&gt_by_frame[i], &hyp);
    }
    acc.metrics()
}

/// Pools metrics of several sequences (sums of counts; ratios recomputed).
pub fn pooled(ms: &[MotMetrics]) -> MotMetrics {
    let s = |f: fn(&MotMetrics) -> u64| ms.iter().map(f).sum::<u64>();
    let (gt, pred) = (s(|m| m.num_objects), s(|m| m.num_predictions));
    let (matches, sw, fp, fnn) =
        (s(|m| m.num_matches), s(|m| m.num_switches), s(|m| m.num_false_positives), s(|m| m.num_misses));
    let idtp = s(|m| m.idtp);
    let det = matches + sw;
    let dist: f64 = ms.iter().map(|m| m.motp * (m.num_matches + m.num_switches) as f64).sum();
    let r = |a: f64, b: f64| if b == 0.0 { 0.0 } else { a / b };
    MotMetrics {
        num_frames: s(|m| m.num_frames),
        num_objects: gt,
        num_predictions: pred,
        num_unique_objects: s(|m| m.num_unique_objects),
        num_matches: matches,
        num_switches: sw,
        num_false_positives: fp,
        num_misses: fnn,
        num_fragmentations: s(|m| m.num_fragmentations),
        mostly_tracked: s(|m| m.mostly_tracked),
        partially_tracked: s(|m| m.partially_tracked),
        mostly_lost: s(|m| m.mostly_lost),
        recall: r(det as f64, gt as f64),
        precision: r(det as f64, pred as f64),
        mota: 1.0 - r((fnn + sw + fp) as f64, gt as f64),
        motp: r(dist, det as f64),
        idtp,
        idfp: pred - idtp,
        idfn: gt - idtp,
        idp: r(idtp as f64, pred as f64),
        idr: r(idtp as f64, gt as f64),
        idf1: r(2.0 * idtp as f64, (gt + pred) as f64),
        // HOTA does not pool from sums: ground-truth-weighted means of the sequences' values.
        hota: r(ms.iter().map(|m| m.hota * m.num_objects as f64).sum(), gt as f64),
        deta: r(ms.iter().map(|m| m.deta * m.num_objects as f64).sum(), gt as f64),
        assa: r(ms.iter().map(|m| m.assa * m.num_objects as f64).sum(), gt as f64),
    }
}

/// Sets one numeric `[tracker]` key the way the config file does (the same serde types, names and
/// checks: an unknown key or a value out of range is an error naming it).
pub fn set_key(cfg: &mut TrackerConfig, key: &str, v: f64) -> Result<(), String> {
    let mut table = toml::Table::try_from(*cfg).map_err(|e| format!("tracker: {e}"))?;
    let value = match table.get(key) {
        Some(toml::Value::Integer(_)) if v >= 0.0 && v.fract() == 0.0 => toml::Value::Integer(v as i64),
        Some(toml::Value::Integer(_)) => return Err(format!("grid key `{key}`: {v} is not a whole number >= 0")),
        Some(toml::Value::Float(_)) => toml::Value::Float(v),
        _ => return Err(format!("unknown grid key `{key}`: not a numeric [tracker] key")),
    };
    table.insert(key.to_string(), value);
    *cfg = toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| format!("grid key `{key}` = {v}: {e}"))?;
    Ok(())
}

/// A search grid: named keys and the values each takes.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// `(key, values)` pairs, in order.
    pub axes: Vec<(String, Vec<f64>)>,
}

impl Grid {
    /// The paper's Table 1 on our keys: `T_d`, `T_t`, `T_unt`, `T_unc`, `T_iou` in 30%..70%.
    pub fn paper() -> Self {
        let v = vec![0.3, 0.4, 0.5, 0.6, 0.7];
        let axes =
            ["det_threshold", "track_threshold", "new_track_threshold", "unconfirmed_iou_threshold", "iou_threshold"]
                .iter()
                .map(|k| (k.to_string(), v.clone()))
                .collect();
        Self { axes }
    }

    /// Parses a TOML grid: `key = [values...]` (or a single value) per line.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let table: toml::Table = toml::from_str(text).map_err(|e| format!("grid: {e}"))?;
        let mut axes = Vec::new();
        for (k, v) in table {
            let num = |x: &toml::Value| x.as_float().or_else(|| x.as_integer().map(|i| i as f64));
            let vals: Vec<f64> = match &v {
                toml::Value::Array(a) => a.iter().map(num).collect::<Option<_>>(),
                other => num(other).map(|x| vec![x]),
            }
            .ok_or_else(|| format!("grid key `{k}`: values must be numbers"))?;
            if vals.is_empty() {
                return Err(format!("grid key `{k}`: no values"));
            }
            // Each value must be one the config accepts for this key.
            for &x in &vals {
                set_key(&mut TrackerConfig::default_preset(), &k, x)?;
            }
            axes.push((k, vals));
        }
        if axes.is_empty() {
            return Err("grid: no keys".into());
        }
        Ok(Self { axes })
    }

    /// Number of grid points.
    pub fn len(&self) -> usize {
        self.axes.iter().map(|(_, v)| v.len()).product()
    }

    /// True when a grid has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th point as `(key, value)` settings applied over `base`.
    pub fn point(&self, mut i: usize, base: TrackerConfig) -> (TrackerConfig, Vec<(String, f64)>) {
        let mut cfg = base;
        let mut set = Vec::with_capacity(self.axes.len());
        for (k, vals) in &self.axes {
            let v = vals[i % vals.len()];
            i /= vals.len();
            // Keys and values were checked when the grid was built; a combination the checks
            // refuse keeps the previous value.
            if let Err(e) = set_key(&mut cfg, k, v) {
                tracing::warn!("{e}");
            }
            set.push((k.clone(), v));
        }
        (cfg, set)
    }
}

/// A toy 2D swarm for tests and benchmarks (not the renderer of `fme synth`): `n` fish swimming at 30 fps in a 960 x 540 image: wandering headings, bouncing off the edges,
/// nearer fish (larger) occlude farther ones; visibility is the uncovered fraction of the box.
pub fn toy_swarm(n: usize, frames: u32, seed: u64) -> TuneSequence {
    let mut rng = tune_rng(seed);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_points_cover_the_product() {
        let g = Grid::from_toml("iou_threshold = [0.3, 0.5]\nmin_hits = [1, 2, 3]\n").expect("valid");
        assert_eq!(g.len(), 6);
        let pts: std::collections::BTreeSet<String> =
            (0..6).map(|i| format!("{:?}", g.point(i, TrackerConfig::default_preset()).1)).collect();
        assert_eq!(pts.len(), 6);
        assert!(Grid::from_toml("iou_tresh = [0.3]").expect_err("typo").contains("iou_tresh"));
        assert_eq!(Grid::paper().len(), 3125);
    }
}
