//! Detection scoring (precision and recall at IoU 0.5) and the inputs `fme eval` derives from
//! ground truth: the clipped ground-truth boxes of each frame, and realistic noisy detections for
//! `--boxes tracker` on sequences without a `det/det.txt`.

use crate::tune::{DetNoise, GtObs, TuneSequence, synth_detections};
use fme_core::geometry::PixelBox;
use fme_core::track::Detection;
use fme_edge::sequence::Sequence;

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
pub fn gt_by_frame(seq: &Sequence) -> Vec<Vec<(u32, PixelBox, f64)>> {
    let (w, h) = (f64::from(seq.info.im_width), f64::from(seq.info.im_height));
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
        fps: seq.info.frame_rate,
        frames: seq.len(),
        width: f64::from(seq.info.im_width),
        height: f64::from(seq.info.im_height),
        gt: seq
            .gt
            .iter()
            .map(|g| GtObs { frame: g.frame, id: i64::from(g.id), bbox: g.bbox, visibility: g.visibility, depth: None })
            .collect(),
    };
    synth_detections(&ts, &DetNoise::default(), seed)
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
