//! Depth accuracy at the fish (estimated depth only): the estimate against the true depth map read
//! the same way, and with true boxes, against the camera z of each fish's body centre.

use super::{FrameTruth, Scorer};
use crate::eval::inputs::{GT_WINDOW, to_metres};
use crate::eval::metrics::DepthAccuracy;
use crate::eval::{EvalError, EvalReport};
use fme_core::metric::{DepthSample, MapKind, RelativeMap, sample_fish, sample_median};
use fme_core::pipeline::FrameOutcome;
use fme_edge::sequence::Sequence;
use std::collections::HashMap;

/// Scores the depth of every fish seen on a frame.
#[derive(Debug)]
pub struct DepthScorer<'a> {
    seq: &'a Sequence,
    how: DepthSample,
    /// Camera z of each fish's body centre by (frame, id) (true boxes carry world.csv's ids).
    body_z: HashMap<(u32, u32), f64>,
    truth_m: Vec<f32>,
    truth_size: Option<(usize, usize)>,
    at_fish: DepthAccuracy,
    at_body: DepthAccuracy,
    body_boxes: usize,
}

impl<'a> DepthScorer<'a> {
    /// `how`: `depth.sample`, so the truth is read as the estimate was; `body`: score against the
    /// body centres too (true boxes).
    pub fn new(seq: &'a Sequence, how: DepthSample, body: bool) -> Self {
        let body_z = match (&seq.camera, body) {
            (Some(camera), true) => {
                seq.world.iter().map(|r| ((r.frame, r.id), camera.pose.to_camera(&r.position).depth().0)).collect()
            }
            _ => HashMap::new(),
        };
        let (at_fish, at_body) = (DepthAccuracy::default(), DepthAccuracy::default());
        Self { seq, how, body_z, truth_m: Vec::new(), truth_size: None, at_fish, at_body, body_boxes: 0 }
    }
}

impl Scorer for DepthScorer<'_> {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        if self.seq.has_depth {
            let dm = self.seq.read_depth(truth.frame)?;
            to_metres(&dm, &mut self.truth_m);
            self.truth_size = Some((dm.width as usize, dm.height as usize));
        }
        let Some((width, height)) = self.truth_size else { return Ok(()) };
        let gt = RelativeMap { data: &self.truth_m, width, height };
        for v in o.fish_seen() {
            let key = (truth.frame, v.id);
            let Some(e) = v.depth_measured else {
                self.body_boxes += usize::from(self.body_z.contains_key(&key));
                continue;
            };
            // Ground truth read the same way as the estimate (the same pixels).
            let others = o.fish_seen().filter(|x| x.id != v.id).map(|x| &x.bbox);
            let c = v.bbox.center();
            let read = sample_fish(
                self.how,
                MapKind::Depth,
                &v.bbox,
                others,
                || sample_median(&gt, c, GT_WINDOW, |_| true),
                |p| gt.at(p),
            );
            if let Some(g) = read {
                self.at_fish.add(e.0, g);
            }
            if let Some(&z) = self.body_z.get(&key) {
                self.body_boxes += 1;
                self.at_body.add(e.0, z);
            }
        }
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.depth_rmse_m = self.at_fish.rmse();
        report.depth_delta_1_25 = self.at_fish.delta_1_25();
        report.depth_delta_1_25_2 = self.at_fish.delta_1_25_2();
        report.depth_body_rmse_m = self.at_body.rmse();
        report.depth_body_delta_1_25 = self.at_body.delta_1_25();
        report.depth_body_coverage =
            (self.body_boxes > 0).then(|| self.at_body.count() as f64 / self.body_boxes as f64);
        Ok(())
    }
}
