//! What the detector produces and the tracker consumes: one object in frame pixels with a score.
//!
//! The one detection type of the crate: [`crate::infer`]'s decoder fills it, [`crate::track`]'s
//! tracker and [`crate::sequence::mot_text::read_detections`] take it, so the daemon hands the detector's
//! output to the tracker without conversion.

use crate::geometry::PixelBox;
use crate::units::Metres;

/// One detected object of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// The box in frame pixels (MOTChallenge top-left, width, height).
    pub bbox: PixelBox,
    /// Detector confidence in 0..1 (for YOLO heads: the sigmoided class probability).
    pub score: f64,
    /// Class index (0 for the one-class fish model and for detections read from files).
    pub class: u16,
    /// Metric depth of the box centre when known (optional association cue of the tracker).
    pub depth: Option<Metres>,
}

impl Detection {
    /// A class-0 detection without depth.
    pub const fn new(bbox: PixelBox, score: f64) -> Self {
        Self { bbox, score, class: 0, depth: None }
    }
}
