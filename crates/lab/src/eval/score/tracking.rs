//! Tracking quality of the pipeline's tracks against `gt/gt.txt` (MOTChallenge conventions, IoU 0.5).

use super::{FrameTruth, Scorer};
use crate::eval::report::MotSummary;
use crate::eval::{EvalError, EvalReport};
use crate::mot::MotAccumulator;
use fme_core::geometry::PixelBox;
use fme_core::pipeline::FrameOutcome;

/// Scores the tracked boxes that entered the estimator on each frame.
#[derive(Debug)]
pub struct TrackingScorer {
    mot: MotAccumulator,
    truth: Vec<(i64, PixelBox)>,
    tracks: Vec<(i64, PixelBox)>,
}

impl TrackingScorer {
    /// At IoU 0.5, as the MOTChallenge devkit.
    pub fn new() -> Self {
        Self { mot: MotAccumulator::new(), truth: Vec::new(), tracks: Vec::new() }
    }
}

impl Default for TrackingScorer {
    fn default() -> Self {
        Self::new()
    }
}

impl Scorer for TrackingScorer {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        self.truth.clear();
        self.truth.extend(truth.boxes.iter().map(|&(id, b, _)| (i64::from(id), b)));
        self.tracks.clear();
        self.tracks.extend(o.observations.iter().map(|t| (i64::from(t.id), t.bbox)));
        self.mot.update(&self.truth, &self.tracks);
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.mot = Some(MotSummary::from(&self.mot.metrics()));
        Ok(())
    }
}
