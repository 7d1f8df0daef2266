//! Boxes computed by `fme eval` itself: fme's tracker on detections (the sequence's `det/det.txt`,
//! or ground truth turned into realistic noisy detections), and the ONNX detector on the frames. Each
//! run is also scored as multi-object tracking (MOTA, IDF1, ...) and, for the detector, as
//! detection (precision and recall at IoU 0.5).

use super::EvalError;
use super::boxes::IndexedBoxes;
use crate::geometry::PixelBox;
use crate::infer::{Detector, RgbFrame};
use crate::metric::ReferenceFootprints;
use crate::mot::{MotAccumulator, MotMetrics};
use crate::sequence::Sequence;
use crate::track::tune::{DetNoise, GtObs, TuneSequence, synth_detections};
use crate::track::{Detection, Tracker, TrackerConfig};

/// Ground-truth fish at least this visible must be detected; less visible ones are "don't care"
/// (a detection on them is neither a true nor a false positive). Same rule as `training/evaluate.py`.
pub const VIS_REQUIRED: f64 = 0.5;

/// Detection quality at IoU 0.5 over a sequence.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct DetectionScore {
    /// Detections matched to a required ground-truth fish.
    pub tp: u64,
    /// Detections matching no ground-truth fish.
    pub fp: u64,
    /// Required ground-truth fish without a detection.
    pub fn_: u64,
    /// `tp / (tp + fp)`.
    pub precision: f64,
    /// `tp / (tp + fn)`.
    pub recall: f64,
}

impl DetectionScore {
    /// Adds one frame: greedy matching, highest score first, preferring required fish.
    pub fn add_frame(&mut self, dets: &[Detection], gt: &[(PixelBox, f64)]) {
        let mut used = vec![false; gt.len()];
        let mut order: Vec<usize> = (0..dets.len()).collect();
        order.sort_by(|&a, &b| dets[b].score.total_cmp(&dets[a].score));
        for i in order {
            let best = |required: bool, used: &[bool]| {
                gt.iter()
                    .enumerate()
                    .filter(|(j, g)| !used[*j] && (g.1 >= VIS_REQUIRED) == required)
                    .map(|(j, g)| (j, dets[i].bbox.iou(&g.0)))
                    .filter(|&(_, iou)| iou >= 0.5)
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(j, _)| j)
            };
            if let Some(j) = best(true, &used) {
                used[j] = true;
                self.tp += 1;
            } else if let Some(j) = best(false, &used) {
                used[j] = true;
            } else {
                self.fp += 1;
            }
        }
        self.fn_ += gt.iter().zip(&used).filter(|(g, u)| g.1 >= VIS_REQUIRED && !**u).count() as u64;
        self.precision = self.tp as f64 / (self.tp + self.fp).max(1) as f64;
        self.recall = self.tp as f64 / (self.tp + self.fn_).max(1) as f64;
    }
}

/// Ground-truth boxes of every frame with their visibility (index 0 = frame 1), clipped to the
/// image (gt.txt boxes are amodal and may reach outside it; a detector can only see the inside).
/// Fish entirely outside the image are left out.
fn gt_by_frame(seq: &Sequence) -> Vec<Vec<(u32, PixelBox, f64)>> {
    let (w, h) = (f64::from(seq.meta.width), f64::from(seq.meta.height));
    let mut out = vec![Vec::new(); seq.len() as usize];
    for g in &seq.gt {
        let b = g.bbox;
        let (x0, y0) = (b.x.max(0.0), b.y.max(0.0));
        let (x1, y1) = ((b.x + b.w).min(w), (b.y + b.h).min(h));
        if x1 - x0 < 1.0 || y1 - y0 < 1.0 {
            continue;
        }
        if let Some(v) = out.get_mut(g.frame as usize - 1) {
            v.push((g.id, PixelBox { x: x0, y: y0, w: x1 - x0, h: y1 - y0 }, g.visibility));
        }
    }
    out
}

/// Noisy detections from ground truth (misses that grow with occlusion, jitter, false positives):
/// the stand-in detector `fme tune` uses, with a fixed seed.
pub fn synthetic_detections(seq: &Sequence, seed: u64) -> Vec<Vec<Detection>> {
    let ts = TuneSequence {
        name: seq.dir.display().to_string(),
        fps: seq.meta.fps,
        frames: seq.len(),
        width: f64::from(seq.meta.width),
        height: f64::from(seq.meta.height),
        gt: seq
            .gt
            .iter()
            .map(|g| GtObs { frame: g.frame, id: i64::from(g.id), bbox: g.bbox, visibility: g.visibility, depth: None })
            .collect(),
    };
    synth_detections(&ts, &DetNoise::default(), seed)
}

/// Reads frame `frame` (1-based) of `seq` as RGB.
pub(crate) fn read_frame_rgb(seq: &Sequence, frame: u32) -> Result<image::RgbImage, EvalError> {
    let path = seq.frame_path(frame);
    match image::open(&path) {
        Ok(img) => Ok(img.to_rgb8()),
        Err(e) => Err(EvalError::Input { path, msg: format!("cannot read frame: {e}") }),
    }
}

/// Runs the detector on every frame image; returns the detections per frame and their score.
/// Detections on the reference cubes are dropped first, as `fme run` does (`detector.ignore_references`).
pub fn model_detections(
    seq: &Sequence,
    detector: &mut Detector,
) -> Result<(Vec<Vec<Detection>>, DetectionScore), EvalError> {
    let gt = gt_by_frame(seq);
    let cubes = seq.meta.reference_objects.iter().map(|r| (r.center(), r.size()));
    let footprints = ReferenceFootprints::project(&seq.camera, cubes);
    let mut score = DetectionScore::default();
    let mut out = Vec::with_capacity(seq.len() as usize);
    let mut frame_gt = Vec::new();
    for frame in 1..=seq.len() {
        let img = read_frame_rgb(seq, frame)?;
        let d = detector
            .detect(&RgbFrame::from(&img), seq.timestamp(frame))
            .map_err(|e| EvalError::Input { path: seq.frame_path(frame), msg: e.to_string() })?;
        let dets: Vec<Detection> =
            d.items.iter().filter(|x| !footprints.covers(&x.bbox)).map(|x| Detection::new(x.bbox, x.score)).collect();
        frame_gt.clear();
        frame_gt.extend(gt[frame as usize - 1].iter().map(|&(_, b, v)| (b, v)));
        score.add_frame(&dets, &frame_gt);
        out.push(dets);
    }
    Ok((out, score))
}

/// Runs the tracker over per-frame detections (index 0 = frame 1) on the sequence's timestamps;
/// returns the confirmed tracks as boxes for the estimator and the MOT metrics against `gt/gt.txt`.
pub fn track(seq: &Sequence, cfg: TrackerConfig, dets: &[Vec<Detection>], name: &str) -> (IndexedBoxes, MotMetrics) {
    let gt = gt_by_frame(seq);
    let mut tracker = Tracker::new(cfg);
    let mut acc = MotAccumulator::new();
    let mut by_frame = vec![Vec::new(); seq.len() as usize + 1];
    let (mut g, mut h) = (Vec::new(), Vec::new());
    for frame in 1..=seq.len() {
        let empty = Vec::new();
        let d = dets.get(frame as usize - 1).unwrap_or(&empty);
        h.clear();
        if let Ok(out) = tracker.update(seq.timestamp(frame), d) {
            h.extend(out.iter().map(|o| (i64::from(o.id), o.bbox)));
        }
        g.clear();
        g.extend(gt[frame as usize - 1].iter().map(|&(id, b, _)| (i64::from(id), b)));
        acc.update(&g, &h);
        by_frame[frame as usize] = h.iter().map(|&(id, b)| (id as u32, b)).collect();
    }
    (IndexedBoxes::new(name.to_string(), by_frame), acc.metrics())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(x: f64) -> PixelBox {
        PixelBox { x, y: 0.0, w: 10.0, h: 10.0 }
    }

    #[test]
    fn detection_score_counts_dont_care_fish_as_neither() {
        let mut s = DetectionScore::default();
        // gt: one required fish at 0, one hidden fish at 100; dets: on both, plus one on nothing.
        let gt = [(b(0.0), 0.9), (b(100.0), 0.1)];
        let dets = [Detection::new(b(1.0), 0.9), Detection::new(b(100.0), 0.8), Detection::new(b(300.0), 0.7)];
        s.add_frame(&dets, &gt);
        assert_eq!((s.tp, s.fp, s.fn_), (1, 1, 0));
        s.add_frame(&[], &gt);
        assert_eq!(s.fn_, 1);
        assert!((s.recall - 0.5).abs() < 1e-12 && (s.precision - 0.5).abs() < 1e-12);
    }
}
