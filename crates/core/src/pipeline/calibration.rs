//! The camera calibration the daemon needs for metric depth (paper eq. 1-2): intrinsics, the
//! world-to-camera pose and the reference objects. Read from a `meta.json`-format file by the edge
//! (`fme_edge::calibration`); the pipeline only consumes it.

use crate::geometry::{Camera, WorldPoint};
use crate::units::Metres;
use std::path::PathBuf;

/// A loaded calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The file it came from.
    pub path: PathBuf,
    /// Intrinsics and pose.
    pub camera: Camera,
    /// The camera-facing surface of each reference object, world frame (what a depth map sees).
    pub references: Vec<WorldPoint>,
    /// Each reference cube's centre and edge length (for telling detections on them from fish).
    pub cubes: Vec<(WorldPoint, Metres)>,
}
