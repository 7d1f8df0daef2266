//! Sections of the pipeline stages: `[camera]`, `[detector]`, `[depth]`, `[tracker]`, `[postprocess]`,
//! `[motion]`. These are the operator-facing keys (documented in `config/fme.toml`); the pipeline
//! builder ([`crate::service::fish_pipeline`]) maps them onto the stage modules' own settings
//! (`infer`, `track`, `postprocess`, `motion`), so the stage modules stay free of daemon concerns.

use serde::Deserialize;
use std::path::PathBuf;

/// `[camera]`: where the camera calibration and the reference objects come from (paper eq. 1-2).
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// A JSON file with the `camera` block (intrinsics, distortion, world-to-camera pose) and the
    /// `reference_objects` list, in the format of a sequence's `meta.json` (other keys are ignored).
    /// Empty: the recorded source's own `meta.json`; a V4L2 camera without one runs uncalibrated
    /// (status bit 3 clear, no speeds).
    pub calibration: PathBuf,
}

/// `[detector]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DetectorConfig {
    /// ONNX model file (relative paths: the working directory, then the executable's `../../`,
    /// i.e. the repository when run as `target/release/fme`).
    pub model: PathBuf,
    /// Detection rate, Hz (decoupled from the camera rate; frames in between are only predicted).
    pub rate_hz: f64,
    /// Minimum detection confidence, 0..1.
    pub confidence: f64,
    /// Non-maximum-suppression IoU threshold, 0..1.
    pub nms_iou: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Let ONNX Runtime's idle worker threads spin between operators (with `threads >= 2`): lower
    /// latency, more CPU; off leaves the cores to the tracker and the other network.
    pub spin: bool,
    /// Drop detections on the calibrated reference cubes (they look like small fish to a detector).
    pub ignore_references: bool,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from("models/fish_det_int8.onnx"),
            rate_hz: 10.0,
            confidence: 0.3,
            nms_iou: 0.5,
            threads: 1,
            spin: false,
            ignore_references: true,
        }
    }
}

/// `[depth]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DepthConfig {
    /// ONNX relative-depth model file (MiDaS / Depth Anything convention).
    pub model: PathBuf,
    /// Depth rate, Hz.
    pub rate_hz: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Let ONNX Runtime's idle worker threads spin between operators (with `threads >= 2`): lower
    /// latency, more CPU; off leaves the cores to the tracker and the other network.
    pub spin: bool,
    /// Also run the network on the mirrored frame and average the two maps: twice the depth time
    /// for a little less per-frame noise (README, "Mirrored depth").
    pub flip: bool,
    /// Metric fit of relative inverse depth (paper eq. 2): `linear`, `inverse` or `robust`.
    pub fit: crate::metric::FitMethod,
    /// How a fish's depth is read from the map: `visible` (nearest quarter of the central half of its
    /// box, where no other fish's box covers it; none for a hidden fish, or one seen behind another
    /// with little of it left), `box` (the same over the
    /// whole core) or `centre` (the paper's choice). See [`crate::metric::DepthSample`].
    pub sample: crate::metric::DepthSample,
    /// Input normalisation: channel means (R, G, B) after `/255` (ImageNet; `[0, 0, 0]` for the
    /// official MiDaS v2.1 small ONNX).
    pub mean: [f32; 3],
    /// Input normalisation: channel standard deviations (`[1, 1, 1]` for the official MiDaS ONNX).
    pub std: [f32; 3],
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self {
            model: PathBuf::from("models/fish_depth_int8.onnx"),
            rate_hz: 5.0,
            threads: 1,
            spin: false,
            flip: false,
            fit: crate::metric::FitMethod::Robust,
            sample: crate::metric::DepthSample::Visible,
            mean: crate::infer::Normalize::IMAGENET.mean,
            std: crate::infer::Normalize::IMAGENET.std,
        }
    }
}

/// `[tracker]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// Base settings: `default` (ByteTrack-style, our best) or `sort` (the reference SORT tracker).
    pub preset: String,
    /// Maximum simultaneous tracks (fixed capacity, no allocation per frame), 1..=128.
    pub max_tracks: usize,
    /// Minimum IoU to match a detection to a track (paper Table 1 `T_iou`), 0..1.
    pub iou_threshold: f64,
    /// Detections needed before a track is confirmed.
    pub min_hits: u32,
    /// A lost track is kept this long to be recovered, s.
    pub max_age_s: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        let d = crate::track::TrackerConfig::default_preset();
        Self {
            preset: "default".into(),
            max_tracks: crate::track::MAX_TRACKS,
            iou_threshold: d.iou_thresh,
            min_hits: d.min_hits,
            max_age_s: d.max_lost_s,
        }
    }
}

/// `[postprocess]` (paper eq. 3 and 4).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PostprocessConfig {
    /// Box-fluctuation detector and correction (eq. 3). Off by default: it raised the speed error
    /// on our synthetic swarms (README, "Post-processing").
    pub box_fluctuation: bool,
    /// Window of the box-fluctuation detector (eq. 3), s.
    pub box_window_s: f64,
    /// Window of previous sizes whose EWMA replaces an abnormal box size (eq. 3), s.
    pub box_ewma_s: f64,
    /// Depth-jump detector and correction (eq. 4).
    pub depth_jump: bool,
    /// Depth jump threshold delta (eq. 4), m.
    pub depth_jump_m: f64,
    /// Window of the depth EWMA that replaces a jump (eq. 4), s.
    pub depth_window_s: f64,
    /// Time constant of each fish's depth smoothing after eq. 4, s (0 = off). Not in the paper: the
    /// depth network's frame-to-frame flicker otherwise becomes speed.
    pub depth_smoothing_s: f64,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        let d = crate::postprocess::PostprocessConfig::default();
        Self {
            box_fluctuation: d.box_fluctuation,
            box_window_s: d.fluctuation_window.0,
            box_ewma_s: d.box_ewma_window.0,
            depth_jump: d.depth_jump,
            depth_jump_m: d.depth_jump_threshold.0,
            depth_window_s: d.depth_ewma_window.0,
            depth_smoothing_s: crate::postprocess::ESTIMATED_DEPTH_SMOOTHING.0,
        }
    }
}

/// `[motion]` (paper eq. 5 and the activity sample).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Mean fish body length used for body lengths/s, m; 0 = estimated per fish
    /// ([`crate::motion::heading::fish_length`]).
    pub body_length_m: f64,
    /// Fewer tracked fish than this raises the "too few fish" status bit.
    pub min_fish: u32,
    /// Time constant of the smoothed activity value (EWMA), s.
    pub smoothing_s: f64,
    /// Each fish's speed is its displacement over this span, s (0 = frame to frame, as the paper).
    pub speed_span_s: f64,
    /// A fish enters the mean once it has been tracked this long, s (0 = at once, as the paper).
    pub min_age_s: f64,
    /// Where each fish's speed along the line of sight comes from: `heading` (its speed across the
    /// image over the box's foreshortening: fish swim head first) or `depth` (its change of depth, the paper).
    pub along_ray: crate::motion::AlongRay,
    /// A fish's width over its length as seen head-on (salmon about 0.1), for `along_ray = "heading"`.
    pub body_width_ratio: f64,
    /// Per-fish speeds above this are glitches and left out of the mean, m/s.
    pub max_speed_mps: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        let d = crate::motion::MotionConfig::default();
        Self {
            body_length_m: 0.35,
            min_fish: 3,
            smoothing_s: 60.0,
            speed_span_s: d.speed_span.0,
            min_age_s: d.min_age.0,
            along_ray: d.along_ray,
            body_width_ratio: d.body_width_ratio,
            max_speed_mps: d.max_speed.0,
        }
    }
}
