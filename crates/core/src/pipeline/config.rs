//! What the pipeline reads of the one configuration: its stage sections and the frame size. The
//! edge composes the whole file (`fme_edge::config::Config::pipeline`); every command that estimates
//! activity builds its pipeline from this one type.

use crate::familiarity::FamiliarityConfig;
use crate::infer::{DepthConfig, DetectorConfig};
use crate::motion::MotionConfig;
use crate::postprocess::PostprocessConfig;
use crate::track::TrackerConfig;

/// The pipeline's sections of `config/fme.toml`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PipelineConfig {
    /// Frame width the source delivers, px (`source.width`; the uncalibrated camera's image).
    pub frame_width: u32,
    /// Frame height, px (`source.height`).
    pub frame_height: u32,
    /// `[detector]`.
    pub detector: DetectorConfig,
    /// `[depth]`.
    pub depth: DepthConfig,
    /// `[tracker]`.
    pub tracker: TrackerConfig,
    /// `[postprocess]`.
    pub postprocess: PostprocessConfig,
    /// `[motion]`.
    pub motion: MotionConfig,
    /// `[familiarity]`.
    pub familiarity: FamiliarityConfig,
}

impl PipelineConfig {
    /// Checks every stage section; the error names the section's key.
    pub fn validate(&self) -> Result<(), String> {
        self.detector.validate().map_err(|e| e.to_string())?;
        self.depth.validate().map_err(|e| e.to_string())?;
        self.tracker.validate().map_err(|e| format!("tracker: {e}"))?;
        self.motion.validate().map_err(str::to_string)?;
        self.postprocess.validate().map_err(str::to_string)?;
        self.familiarity.validate()
    }
}
