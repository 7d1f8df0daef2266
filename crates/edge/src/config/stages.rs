//! `[camera]`: where the calibration comes from. The other pipeline sections are owned by their
//! stage modules ([`fme_core::infer::DetectorConfig`], [`fme_core::infer::DepthConfig`],
//! [`fme_core::track::TrackerConfig`], [`fme_core::postprocess::PostprocessConfig`],
//! [`fme_core::motion::MotionConfig`]) and composed by [`super::Config`].

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[camera]`: the camera calibration and the reference objects (paper eq. 1-2).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// A JSON file with the `camera` block (intrinsics, distortion, world-to-camera pose) and the
    /// `reference_objects` list, in the format of a sequence's `meta.json` (other keys are ignored).
    /// Empty: the recorded source's own `meta.json`; a V4L2 camera without one runs uncalibrated
    /// (status bit 3 clear, no speeds).
    pub calibration: PathBuf,
}
