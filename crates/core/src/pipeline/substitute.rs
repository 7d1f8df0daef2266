//! Stages swapped for ground truth or recorded results (`fme eval --boxes`, `--depth`): the pipeline
//! runs unchanged around them, on the same schedule, so an evaluation isolates one stage's error.

use super::Frame;
use crate::geometry::{Pixel, PixelBox};
use crate::infer::RelDepthMap;
use crate::metric::{DepthGrid, MapKind};
use crate::track::Detection;

impl DepthGrid for RelDepthMap {
    fn kind(&self) -> MapKind {
        MapKind::InverseDepth
    }
    fn point(&self, px: Pixel) -> Option<f64> {
        self.sample(px).map(f64::from)
    }
    fn grid(&self, px: Pixel) -> Option<f64> {
        self.sample_with_radius(px, 0).map(f64::from)
    }
}

/// Inputs that replace a stage of [`super::FishPipeline`]. Each method is called only when the
/// matching `replaces_*` is true; errors name the file at fault.
pub trait Substitute: Send {
    /// Tracked boxes replace the detector and the tracker (ground-truth tracks, a track file).
    fn replaces_tracks(&self) -> bool {
        false
    }
    /// Detections replace the detector (a `det.txt`); the tracker still runs.
    fn replaces_detector(&self) -> bool {
        false
    }
    /// Depth maps replace the depth network.
    fn replaces_depth(&self) -> bool {
        false
    }
    /// The tracked boxes `(id, box)` of `frame`, every frame.
    fn tracks(&mut self, _frame: &Frame, _out: &mut Vec<(u32, PixelBox)>) -> Result<(), String> {
        Ok(())
    }
    /// The detections of `frame`, on the detector's scheduled frames.
    fn detections(&mut self, _frame: &Frame, _out: &mut Vec<Detection>) -> Result<(), String> {
        Ok(())
    }
    /// Loads the depth map of `frame`, on the depth network's scheduled frames.
    fn load_depth(&mut self, _frame: &Frame) -> Result<(), String> {
        Ok(())
    }
    /// The depth map last loaded (held until the next depth frame, as the network's is).
    fn depth(&self) -> Option<&dyn DepthGrid> {
        None
    }
}
