//! What the pictures of a frame show (docs/recording.md "What the pictures show"): an owned copy of
//! the part of a frame's outcome the black box keeps and snapshots draw.

use fme_core::geometry::{Pixel, PixelBox};
use fme_core::motion::Fish;
use fme_core::pipeline::FrameOutcome;

/// The detections, fish and reference objects of one frame, owned (they travel to the writer
/// thread). Reused across frames: filling it allocates nothing once its capacity fits.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overlays {
    /// The detector ran on this frame.
    pub detected: bool,
    /// Its detections: box and score.
    pub detections: Vec<(PixelBox, f64)>,
    /// The fish seen on this frame.
    pub fish: Vec<Fish>,
    /// The reference objects in view: their pixel, and the depth fit's residual there (fitted
    /// minus known depth, m; NaN when there is no fit or no depth reading). Snapshots only.
    pub references: Vec<(Pixel, f64)>,
}

impl Overlays {
    /// Copies the detections and the fish seen from a frame's outcome; the references are left
    /// empty (they cost a depth reading each: see `Pipeline::reference_residuals`).
    pub fn copy_from(&mut self, o: &FrameOutcome<'_>) {
        self.clear();
        self.detected = o.plan.detect;
        self.detections.extend(o.detections.iter().map(|d| (d.bbox, d.score)));
        self.fish.extend(o.fish_seen().copied());
    }

    /// Empties it, keeping its capacity.
    pub fn clear(&mut self) {
        self.detected = false;
        self.detections.clear();
        self.fish.clear();
        self.references.clear();
    }
}
