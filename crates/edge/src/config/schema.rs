//! The configuration schema: one section per table of `config/fme.toml`, in pipeline order. Each
//! section's type (with its defaults and its check) lives beside the module that reads it; this
//! file composes them and re-exports them, so `crate::config::ModbusConfig` names them all.
//!
//! Every field has a default (documented next to it and in `config/fme.toml`), so an empty file is a
//! valid configuration. Unknown keys are errors: a typo must never be silently ignored on a box that
//! runs unattended for months.

use serde::{Deserialize, Serialize};

pub use super::stages::CameraConfig;
pub use crate::capture::config::{CameraFormat, RtspTransport, SourceConfig, SourceKind};
pub use crate::console::config::ConsoleConfig;
pub use crate::history::config::HistoryConfig;
pub use crate::output::config::{
    FeedingConfig, MetricsConfig, ModbusConfig, ModbusMode, MqttConfig, OutputConfig, Parity, SerialLineConfig,
    WordOrder,
};
pub use crate::record::config::RecordConfig;
pub use crate::service::config::ServiceConfig;
pub use crate::web::config::WebConfig;
pub use fme_core::familiarity::FamiliarityConfig;
pub use fme_core::infer::{DepthConfig, DetectorConfig};
pub use fme_core::motion::MotionConfig;
pub use fme_core::postprocess::PostprocessConfig;
pub use fme_core::track::TrackerConfig;

/// The whole configuration: `fme run`, `fme eval`, `fme track` and `fme tune` read this one type.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// `[source]`: camera or recorded sequence.
    pub source: SourceConfig,
    /// `[camera]`: calibration and reference objects for metric depth (paper eq. 1-2).
    pub camera: CameraConfig,
    /// `[detector]`: ONNX fish detector.
    pub detector: DetectorConfig,
    /// `[depth]`: ONNX relative-depth network.
    pub depth: DepthConfig,
    /// `[tracker]`: Kalman tracking-by-detection.
    pub tracker: TrackerConfig,
    /// `[postprocess]`: box-fluctuation and depth-jump detectors (paper eq. 3-4).
    pub postprocess: PostprocessConfig,
    /// `[motion]`: speeds and the activity index (paper eq. 5).
    pub motion: MotionConfig,
    /// `[familiarity]`: "detections look unlike fish" (status bit 10; the feeding rule holds off).
    pub familiarity: FamiliarityConfig,
    /// `[output]`: Modbus and serial line.
    pub output: OutputConfig,
    /// `[console]`: serial field-diagnostics console.
    pub console: ConsoleConfig,
    /// `[feeding]`: the feeding-recommended rule.
    pub feeding: FeedingConfig,
    /// `[service]`: watchdog, logging, threads, state directory.
    pub service: ServiceConfig,
    /// `[record]`: black box (rolling ring of frames), frozen recordings and snapshots.
    pub record: RecordConfig,
    /// `[history]`: a daily CSV row per output update (`docs/history.md`).
    pub history: HistoryConfig,
    /// `[web]`: the web pages and JSON API (`docs/web.md`).
    pub web: WebConfig,
}

impl Config {
    /// The pipeline's sections and the frame size: what [`fme_core::pipeline::FishPipeline`] reads.
    pub fn pipeline(&self) -> fme_core::pipeline::PipelineConfig {
        fme_core::pipeline::PipelineConfig {
            frame_width: self.source.width,
            frame_height: self.source.height,
            detector: self.detector.clone(),
            depth: self.depth.clone(),
            tracker: self.tracker,
            postprocess: self.postprocess,
            motion: self.motion,
            familiarity: self.familiarity,
        }
    }
}
