//! Detection quality of the pipeline's detector on the frames it ran (IoU 0.5; fish under 50%
//! visible are don't-care).

use super::{FrameTruth, Scorer};
use crate::eval::live::DetectionScore;
use crate::eval::{EvalError, EvalReport};
use fme_core::geometry::PixelBox;
use fme_core::pipeline::FrameOutcome;

/// Scores each detector run against the true boxes of its frame.
#[derive(Debug, Default)]
pub struct DetectionScorer {
    score: DetectionScore,
    truth: Vec<(PixelBox, f64)>,
}

impl Scorer for DetectionScorer {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        if o.plan.detect {
            self.truth.clear();
            self.truth.extend(truth.boxes.iter().map(|&(_, b, v)| (b, v)));
            self.score.add_frame(o.detections, &self.truth);
        }
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.detection = Some(self.score);
        Ok(())
    }
}
