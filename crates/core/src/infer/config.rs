//! Settings of the inference stage: the `[detector]` and `[depth]` sections of the config. Each
//! network's rate, threads and model live with it; every command reads these same types.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::InferError;
use super::frame::Normalize;
use super::runtime::SessionOptions;
use crate::metric::{DepthSample, DepthScale, FitMethod};

/// Most detections kept per frame (the tracker's fixed capacity).
pub const MAX_DETECTIONS: usize = 256;

/// Largest supported depth sampling radius (`depth.sample_radius`: a 7x7 window).
pub const MAX_SAMPLE_RADIUS: u32 = 3;

/// `[detector]`: the fish detector (Ultralytics YOLOv8/YOLO11 export convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorConfig {
    /// ONNX model file (relative paths: the working directory, then the install prefix of the
    /// executable, see [`super::runtime::resolve_model`]).
    pub model: PathBuf,
    /// Detector runs per second of frame time, Hz (decoupled from the camera rate; frames in between
    /// are only predicted by the tracker). 0 = every frame.
    pub rate_hz: f64,
    /// Minimum detection confidence, 0..1 (Ultralytics `conf`).
    pub confidence: f64,
    /// Non-maximum-suppression IoU threshold, 0..1 (Ultralytics `iou`).
    pub nms_iou: f64,
    /// Inference threads (ONNX Runtime's intra-op threads; tract's matrix products).
    pub threads: usize,
    /// Let ONNX Runtime's idle worker threads spin between operators (with `threads >= 2`): lower
    /// latency, more CPU; off leaves the cores to the tracker and the other network.
    pub spin: bool,
    /// Drop detections on the calibrated reference cubes (they look like small fish to a detector).
    pub ignore_references: bool,
    /// Suppress across classes.
    pub class_agnostic: bool,
    /// Most detections kept per frame, 1..=256.
    pub max_detections: usize,
    /// Most candidates entering NMS (highest scores first).
    pub max_candidates: usize,
    /// Input `[width, height]`; required only when the model's input size is dynamic, and must
    /// match the model when both are given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_size: Option<[u32; 2]>,
    /// Expected number of classes; checked against the model's output when given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub num_classes: Option<usize>,
}

/// The bundled detector in the form this build's default backend runs fastest: int8 with ONNX
/// Runtime; fp32 with tract alone (the static binary), which runs the fp32 graph faster than the
/// int8 one and matches ONNX Runtime's results on it (docs/benchmarks.md#backends).
pub const DEFAULT_DETECTOR_MODEL: &str =
    if cfg!(feature = "ort") { "models/fish_det_int8.onnx" } else { "models/fish_det_fp32.onnx" };

/// The bundled depth network in the form this build's default backend runs fastest (as
/// [`DEFAULT_DETECTOR_MODEL`]).
pub const DEFAULT_DEPTH_MODEL: &str =
    if cfg!(feature = "ort") { "models/fish_depth_int8.onnx" } else { "models/fish_depth_fp32.onnx" };

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from(DEFAULT_DETECTOR_MODEL),
            rate_hz: 10.0,
            confidence: 0.3,
            nms_iou: 0.5,
            threads: 1,
            spin: false,
            ignore_references: true,
            class_agnostic: true,
            max_detections: MAX_DETECTIONS,
            max_candidates: 3000,
            input_size: None,
            num_classes: None,
        }
    }
}

impl DetectorConfig {
    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<(), InferError> {
        model("detector.model", &self.model)?;
        rate("detector.rate_hz", self.rate_hz)?;
        unit("detector.confidence", self.confidence)?;
        unit("detector.nms_iou", self.nms_iou)?;
        threads("detector.threads", self.threads)?;
        if self.max_detections == 0 || self.max_detections > MAX_DETECTIONS {
            return Err(InferError::Config {
                key: "detector.max_detections",
                reason: format!("must be 1..={MAX_DETECTIONS}, got {}", self.max_detections),
            });
        }
        if self.max_candidates < self.max_detections {
            return Err(InferError::Config {
                key: "detector.max_candidates",
                reason: format!("{} is below detector.max_detections ({})", self.max_candidates, self.max_detections),
            });
        }
        size("detector.input_size", self.input_size)
    }

    /// The ONNX Runtime session options of this network.
    pub fn session(&self) -> SessionOptions {
        SessionOptions { intra_threads: self.threads, spin: self.spin }
    }
}

/// `[depth]`: the relative-depth network (MiDaS v2.1 small / Depth Anything V2 convention) and how
/// its map becomes metres (paper eq. 1-2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthConfig {
    /// ONNX relative (inverse) depth model file.
    pub model: PathBuf,
    /// Depth-network runs per second of frame time, Hz. 0 = every frame.
    pub rate_hz: f64,
    /// Inference threads (ONNX Runtime's intra-op threads; tract's matrix products).
    pub threads: usize,
    /// Let ONNX Runtime's idle worker threads spin between operators (with `threads >= 2`).
    pub spin: bool,
    /// Also run the network on the mirrored frame and average the two maps (test-time
    /// augmentation: twice the depth time, less of the network's per-frame noise).
    pub flip: bool,
    /// Metric fit of relative inverse depth on the reference objects (paper eq. 2 and Table 4).
    pub fit: FitMethod,
    /// What sets the metric scale: the reference objects, the fish (of length
    /// `motion.body_length_m`), or the references while they fit well and else the fish.
    pub scale: DepthScale,
    /// With `scale = "auto"`: while the references set the scale, measure the fish's length under
    /// their fit, and use it instead of `motion.body_length_m` when the fish take over.
    pub learn_fish_length: bool,
    /// How a fish's depth is read from the map (see [`DepthSample`]).
    pub sample: DepthSample,
    /// Channel means (R, G, B) in 0..1 units, subtracted after `/255`. ImageNet by default; use
    /// `[0, 0, 0]` for the official MiDaS v2.1 small ONNX, which normalises inside the graph.
    pub mean: [f64; 3],
    /// Channel standard deviations (R, G, B); `[1, 1, 1]` for the official MiDaS ONNX.
    pub std: [f64; 3],
    /// Half-size, in depth-map pixels, of the window whose median a point sample returns
    /// (0 = the nearest map pixel, at most 3).
    pub sample_radius: u32,
    /// Input `[width, height]`; required only when the model's input size is dynamic (Depth
    /// Anything: multiples of 14; MiDaS: multiples of 32).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_size: Option<[u32; 2]>,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from(DEFAULT_DEPTH_MODEL),
            rate_hz: 5.0,
            threads: 1,
            spin: false,
            flip: false,
            fit: FitMethod::Robust,
            scale: DepthScale::Auto,
            learn_fish_length: true,
            sample: DepthSample::Visible,
            mean: [0.485, 0.456, 0.406],
            std: [0.229, 0.224, 0.225],
            sample_radius: 1,
            input_size: None,
        }
    }
}

impl DepthConfig {
    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<(), InferError> {
        model("depth.model", &self.model)?;
        rate("depth.rate_hz", self.rate_hz)?;
        threads("depth.threads", self.threads)?;
        if self.std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(InferError::Config { key: "depth.std", reason: format!("{:?} must be positive", self.std) });
        }
        if self.mean.iter().any(|m| !m.is_finite()) {
            return Err(InferError::Config { key: "depth.mean", reason: format!("{:?} must be finite", self.mean) });
        }
        if self.sample_radius > MAX_SAMPLE_RADIUS {
            return Err(InferError::Config {
                key: "depth.sample_radius",
                reason: format!("{} exceeds {MAX_SAMPLE_RADIUS}", self.sample_radius),
            });
        }
        size("depth.input_size", self.input_size)
    }

    /// The normalisation these settings give.
    pub fn normalize(&self) -> Normalize {
        Normalize { mean: self.mean.map(|v| v as f32), std: self.std.map(|v| v as f32) }
    }

    /// The ONNX Runtime session options of this network.
    pub fn session(&self) -> SessionOptions {
        SessionOptions { intra_threads: self.threads, spin: self.spin }
    }
}

fn model(key: &'static str, p: &std::path::Path) -> Result<(), InferError> {
    if p.as_os_str().is_empty() {
        Err(InferError::Config { key, reason: "must name an ONNX model file".into() })
    } else {
        Ok(())
    }
}

fn rate(key: &'static str, v: f64) -> Result<(), InferError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(InferError::Config { key, reason: format!("{v} must be a finite rate >= 0 Hz (0 = every frame)") })
    }
}

fn threads(key: &'static str, n: usize) -> Result<(), InferError> {
    if (1..=64).contains(&n) { Ok(()) } else { Err(InferError::Config { key, reason: format!("{n} must be 1..=64") }) }
}

fn unit(key: &'static str, v: f64) -> Result<(), InferError> {
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
    use std::path::Path;

    #[test]
    fn defaults_validate_and_parse_from_toml() {
        DetectorConfig::default().validate().unwrap();
        DepthConfig::default().validate().unwrap();
        let d: DetectorConfig = toml::from_str("model = \"a.onnx\"\nnms_iou = 0.4").unwrap();
        assert_eq!(d.nms_iou, 0.4);
        assert_eq!(d.confidence, 0.3);
        assert!(toml::from_str::<DetectorConfig>("modle = \"a.onnx\"").is_err());
    }

    #[test]
    fn each_backend_defaults_to_the_model_form_it_runs_fastest() {
        let (det, depth) = (DetectorConfig::default().model, DepthConfig::default().model);
        let form = if cfg!(feature = "ort") { "int8" } else { "fp32" };
        assert_eq!(det, PathBuf::from(format!("models/fish_det_{form}.onnx")));
        assert_eq!(depth, PathBuf::from(format!("models/fish_depth_{form}.onnx")));
        // Both forms are bundled, so the default resolves in a checkout and in the static binary.
        for m in [&det, &depth] {
            let in_repo = Path::new(crate::REPO_DIR).join(m);
            assert!(in_repo.is_file(), "{} is not bundled", in_repo.display());
        }
    }

    #[test]
    fn bad_values_name_the_key() {
        let d = DetectorConfig { nms_iou: 1.5, ..Default::default() };
        assert!(d.validate().unwrap_err().to_string().contains("detector.nms_iou"));
        let d = DepthConfig { std: [0.2, 0.0, 0.2], ..Default::default() };
        assert!(d.validate().unwrap_err().to_string().contains("depth.std"));
        let d = DepthConfig { rate_hz: -1.0, ..Default::default() };
        assert!(d.validate().unwrap_err().to_string().contains("depth.rate_hz"));
    }
}
