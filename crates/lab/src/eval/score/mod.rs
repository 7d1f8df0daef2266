//! `fme eval`'s scorers: each reads every frame's outcome (`FrameOutcome`) beside the truth of that
//! frame and writes its own fields of the report. The run (`super::run`) only drives them.

mod consistency;
mod depth;
mod detection;
mod familiarity;
mod fish_rows;
mod pipeline_state;
mod speed;
mod tracking;

pub use consistency::ConsistencyScorer;
pub use depth::DepthScorer;
pub use detection::DetectionScorer;
pub use familiarity::FamiliarityScorer;
pub use fish_rows::FishRows;
pub use pipeline_state::PipelineState;
pub use speed::SpeedScorer;
pub use tracking::TrackingScorer;

use super::{EvalError, EvalReport};
use fme_core::geometry::PixelBox;
use fme_core::pipeline::FrameOutcome;

/// The truth of one frame the scorers share.
#[derive(Debug, Clone, Copy)]
pub struct FrameTruth<'a> {
    /// 1-based frame number.
    pub frame: u32,
    /// The true boxes on it, clipped to the image: id, box, visibility.
    pub boxes: &'a [(u32, PixelBox, f64)],
}

/// One score of the report.
pub trait Scorer {
    /// Reads one frame's outcome beside its truth.
    fn frame(&mut self, truth: &FrameTruth<'_>, outcome: &FrameOutcome<'_>) -> Result<(), EvalError>;
    /// Writes its fields of the report; an error when there is nothing it can score.
    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError>;
}
