//! Sections of the pipeline stages: `[detector]`, `[depth]`, `[tracker]`, `[postprocess]`, `[motion]`.
//!
//! **Integration point.** These are the daemon's placeholders, kept small and isolated on purpose:
//! the stage modules define their own serde sections (`infer::{DetectorConfig, DepthConfig,
//! ScheduleConfig, RuntimeConfig}`, `track::TrackerConfig`, `motion::MotionConfig`, the
//! post-processing config). At integration, replace the field types in [`super::Config`] with
//! theirs, call their `validate` from [`super::Config::validate`] (mapping the key they name to a
//! line with [`super::find_key_line`]) and update `config/fme.toml`. The daemon itself reads only
//! `motion.smoothing_s` and `motion.body_length_m` (for the stand-in pipeline).

use serde::Deserialize;
use std::path::PathBuf;

/// `[detector]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DetectorConfig {
    /// ONNX model file (relative paths are relative to the working directory).
    pub model: PathBuf,
    /// Detection rate, Hz (decoupled from the camera rate; frames in between are only predicted).
    pub rate_hz: f64,
    /// Minimum detection confidence, 0..1.
    pub confidence: f64,
    /// Non-maximum-suppression IoU threshold, 0..1.
    pub nms_iou: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self { model: PathBuf::from("models/detector.onnx"), rate_hz: 10.0, confidence: 0.35, nms_iou: 0.5, threads: 1 }
    }
}

/// `[depth]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DepthConfig {
    /// ONNX relative-depth model file.
    pub model: PathBuf,
    /// Depth rate, Hz.
    pub rate_hz: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Metric fit of relative inverse depth (paper eq. 2): `linear`, `inverse` or `robust`.
    pub fit: String,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self { model: PathBuf::from("models/depth.onnx"), rate_hz: 5.0, threads: 1, fit: "robust".into() }
    }
}

/// `[tracker]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// Maximum simultaneous tracks (fixed capacity, no allocation per frame).
    pub max_tracks: usize,
    /// Minimum IoU to match a detection to a track, 0..1.
    pub iou_threshold: f64,
    /// Detections needed before a track is confirmed.
    pub min_hits: u32,
    /// A track not matched for this long is deleted, s.
    pub max_age_s: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self { max_tracks: 64, iou_threshold: 0.3, min_hits: 3, max_age_s: 1.0 }
    }
}

/// `[postprocess]` (paper eq. 3 and 4).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PostprocessConfig {
    /// Window of the box-fluctuation detector (eq. 3), s.
    pub box_window_s: f64,
    /// Frames averaged by the EWMA that replaces an abnormal box size (eq. 3).
    pub box_ewma_frames: usize,
    /// Depth jump threshold delta (eq. 4), m.
    pub depth_jump_m: f64,
    /// Window of the depth EWMA that replaces a jump (eq. 4), s.
    pub depth_window_s: f64,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        Self { box_window_s: 1.0, box_ewma_frames: 5, depth_jump_m: 0.6, depth_window_s: 1.0 }
    }
}

/// `[motion]` (paper eq. 5 and the activity sample).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Mean fish body length used for body lengths/s, m.
    pub body_length_m: f64,
    /// Fewer tracked fish than this raises the "too few fish" status bit.
    pub min_fish: u32,
    /// Time constant of the smoothed activity value (EWMA), s.
    pub smoothing_s: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self { body_length_m: 0.35, min_fish: 3, smoothing_s: 60.0 }
    }
}
