//! Depth consistency without depth truth: does the depth network order the true boxes as their
//! sizes do (`crate::eval::consistency`)? On the frames the network ran.

use super::{FrameTruth, Scorer};
use crate::eval::consistency::{DepthConsistency, inside_frame};
use crate::eval::{EvalError, EvalReport};
use fme_core::pipeline::FrameOutcome;

/// Reads the network's map at each true box of a depth frame.
#[derive(Debug)]
pub struct ConsistencyScorer {
    consistency: DepthConsistency,
    frame_size: (f64, f64),
}

impl ConsistencyScorer {
    /// For frames of `width` x `height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        Self { consistency: DepthConsistency::default(), frame_size: (f64::from(width), f64::from(height)) }
    }
}

impl Scorer for ConsistencyScorer {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        let (Some(map), true) = (o.depth_map, o.plan.depth) else { return Ok(()) };
        let (w, h) = self.frame_size;
        // Relative inverse depth at each true box's centre, 3x3 median of the map.
        self.consistency.add_frame(
            truth
                .boxes
                .iter()
                .filter(|(_, b, _)| inside_frame(b, w, h))
                .filter_map(|&(_, b, _)| map.sample_with_radius(b.center(), 1).map(|r| (f64::from(r), b))),
        );
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.depth_consistency = self.consistency.mean();
        report.depth_consistency_frames = self.consistency.frames();
        Ok(())
    }
}
