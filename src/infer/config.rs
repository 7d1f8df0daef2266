//! Settings of the inference stage, meant to be embedded as sections of the fme TOML file
//! (`[detector]`, `[depth]`, `[schedule]`). Every field has a default; `validate`
//! names the offending key.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::InferError;
use super::frame::Normalize;

/// The detector (Ultralytics YOLOv8/YOLO11 export convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorConfig {
    /// ONNX model file.
    pub model: PathBuf,
    /// Input `[width, height]`; required only when the model's input size is dynamic, and must
    /// match the model when both are given.
    pub input_size: Option<[u32; 2]>,
    /// Expected number of classes; checked against the model's output when given.
    pub num_classes: Option<usize>,
    /// Minimum class score of a detection (Ultralytics `conf`).
    pub conf_threshold: f32,
    /// IoU above which a lower-scoring box of the same class is suppressed (Ultralytics `iou`).
    pub iou_threshold: f32,
    /// Suppress across classes.
    pub class_agnostic: bool,
    /// Most detections kept per frame.
    pub max_detections: usize,
    /// Most candidates entering NMS (highest scores first).
    pub max_candidates: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from("models/fish_det_int8.onnx"),
            input_size: None,
            num_classes: None,
            conf_threshold: 0.25,
            iou_threshold: 0.7,
            class_agnostic: false,
            max_detections: 300,
            max_candidates: 3000,
        }
    }
}

impl DetectorConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), InferError> {
        unit("detector.conf_threshold", self.conf_threshold)?;
        unit("detector.iou_threshold", self.iou_threshold)?;
        if self.max_detections == 0 {
            return Err(InferError::Config { key: "detector.max_detections", reason: "must be at least 1".into() });
        }
        if self.max_candidates < self.max_detections {
            return Err(InferError::Config {
                key: "detector.max_candidates",
                reason: format!("{} is below detector.max_detections ({})", self.max_candidates, self.max_detections),
            });
        }
        size("detector.input_size", self.input_size)
    }
}

/// The relative-depth network (MiDaS v2.1 small / Depth Anything V2 convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthConfig {
    /// ONNX model file.
    pub model: PathBuf,
    /// Input `[width, height]`; required only when the model's input size is dynamic (Depth
    /// Anything: multiples of 14; MiDaS: multiples of 32).
    pub input_size: Option<[u32; 2]>,
    /// Channel means (R, G, B) in 0..1 units, subtracted after `/255`. ImageNet by default; use
    /// `[0, 0, 0]` for the official MiDaS v2.1 small ONNX, which normalises inside the graph.
    pub mean: [f32; 3],
    /// Channel standard deviations (R, G, B); `[1, 1, 1]` for the official MiDaS ONNX.
    pub std: [f32; 3],
    /// Half-size, in depth-map pixels, of the window whose median is returned by a sample
    /// (0 = the nearest map pixel, at most 3).
    pub sample_radius: u32,
    /// Also run the network on the mirrored frame and average the two maps (test-time
    /// augmentation: twice the depth time, less of the network's per-frame noise).
    pub flip: bool,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from("models/fish_depth_int8.onnx"),
            input_size: None,
            mean: Normalize::IMAGENET.mean,
            std: Normalize::IMAGENET.std,
            sample_radius: 1,
            flip: false,
        }
    }
}

impl DepthConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), InferError> {
        if self.std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(InferError::Config { key: "depth.std", reason: format!("{:?} must be positive", self.std) });
        }
        if self.mean.iter().any(|m| !m.is_finite()) {
            return Err(InferError::Config { key: "depth.mean", reason: format!("{:?} must be finite", self.mean) });
        }
        if self.sample_radius > super::depth::MAX_SAMPLE_RADIUS {
            return Err(InferError::Config {
                key: "depth.sample_radius",
                reason: format!("{} exceeds {}", self.sample_radius, super::depth::MAX_SAMPLE_RADIUS),
            });
        }
        size("depth.input_size", self.input_size)
    }

    /// The normalisation these settings give.
    pub fn normalize(&self) -> Normalize {
        Normalize { mean: self.mean, std: self.std }
    }
}

/// Reduced-rate scheduling (Frigate style: detection decoupled from the camera rate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScheduleConfig {
    /// Detector runs per second of frame time; 0 = every frame.
    pub detect_hz: f64,
    /// Depth-network runs per second of frame time; 0 = every frame.
    pub depth_hz: f64,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        Self { detect_hz: 10.0, depth_hz: 2.0 }
    }
}

impl ScheduleConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), InferError> {
        for (key, v) in [("schedule.detect_hz", self.detect_hz), ("schedule.depth_hz", self.depth_hz)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(InferError::Config { key, reason: format!("{v} must be a finite rate >= 0 Hz") });
            }
        }
        Ok(())
    }
}

fn unit(key: &'static str, v: f32) -> Result<(), InferError> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(InferError::Config { key, reason: format!("{v} is outside 0..1") })
    }
}

fn size(key: &'static str, s: Option<[u32; 2]>) -> Result<(), InferError> {
    match s {
        Some([w, h]) if w == 0 || h == 0 || w > 4096 || h > 4096 => {
            Err(InferError::Config { key, reason: format!("[{w}, {h}] must be within 1..4096") })
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_parse_from_toml() {
        DetectorConfig::default().validate().unwrap();
        DepthConfig::default().validate().unwrap();
        ScheduleConfig::default().validate().unwrap();
        let d: DetectorConfig = toml::from_str("model = \"a.onnx\"\niou_threshold = 0.5").unwrap();
        assert_eq!(d.iou_threshold, 0.5);
        assert_eq!(d.conf_threshold, 0.25);
        assert!(toml::from_str::<DetectorConfig>("modle = \"a.onnx\"").is_err());
    }

    #[test]
    fn bad_values_name_the_key() {
        let d = DetectorConfig { iou_threshold: 1.5, ..Default::default() };
        assert!(d.validate().unwrap_err().to_string().contains("detector.iou_threshold"));
        let d = DepthConfig { std: [0.2, 0.0, 0.2], ..Default::default() };
        assert!(d.validate().unwrap_err().to_string().contains("depth.std"));
        let s = ScheduleConfig { depth_hz: -1.0, ..Default::default() };
        assert!(s.validate().unwrap_err().to_string().contains("schedule.depth_hz"));
    }
}
