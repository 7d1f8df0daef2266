//! The pipeline's sections: `[camera]` (where the calibration comes from) and the check of the
//! stage sections. Those are owned by their stage modules ([`fme_core::infer::DetectorConfig`],
//! [`fme_core::infer::DepthConfig`], [`fme_core::track::TrackerConfig`],
//! [`fme_core::postprocess::PostprocessConfig`], [`fme_core::motion::MotionConfig`],
//! [`fme_core::familiarity::FamiliarityConfig`]), checked by their own `validate` and composed by
//! [`super::Config`]; here their errors become the one [`KeyError`].

use super::{Config, KeyError};
use fme_core::infer::InferError;
use fme_core::track::TrackerConfigError;
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

/// Each stage section's own check, once, then what needs two sections: a fish-scaled depth needs
/// the cohort's length.
pub(super) fn check(cfg: &Config) -> Result<(), KeyError> {
    cfg.detector.validate()?;
    cfg.depth.validate()?;
    cfg.tracker.validate()?;
    cfg.postprocess.validate().map_err(KeyError::leading_key)?;
    cfg.motion.validate().map_err(KeyError::leading_key)?;
    cfg.familiarity.validate().map_err(KeyError::leading_key)?;
    if cfg.depth.scale == fme_core::metric::DepthScale::Fish && cfg.motion.body_length().is_none() {
        return Err(KeyError::new("depth.scale", "\"fish\" needs the cohort's mean length: motion.body_length_m > 0"));
    }
    Ok(())
}

/// `[detector]` and `[depth]`: their check names the key.
impl From<InferError> for KeyError {
    fn from(e: InferError) -> Self {
        match e {
            InferError::Config { key, reason } => Self::new(key, reason),
            other => Self::new("?", other.to_string()),
        }
    }
}

/// `[tracker]`: its check names the key inside the section.
impl From<TrackerConfigError> for KeyError {
    fn from(e: TrackerConfigError) -> Self {
        match e {
            TrackerConfigError::Key(k, m) => Self::new(format!("tracker.{k}"), m),
            other => Self::new("tracker", other.to_string()),
        }
    }
}
