//! The pipeline: frames in, activity samples out (paper eq. 1-5), one implementation for every
//! command.
//!
//! [`FishPipeline`] is the chain `fme run` ships: detector and depth network at reduced rates on
//! frame time, tracker, metric fit on the reference objects (eq. 1-2), post-processing (eq. 3-4) and
//! motion (eq. 5). `fme eval` drives the same type over a recording, with ground truth swapped in
//! for a stage where asked ([`Substitute`]), and scores what each frame returns: one
//! [`FrameOutcome`], the same value the daemon publishes from, so what it scores is what the PLC
//! receives. The daemon (capture, queues, outputs, console, watchdog) only knows the [`Pipeline`]
//! trait.
//!
//! Errors from a stage are returned as [`PipelineError::Stage`] (the service counts and logs them and
//! keeps going; a panic inside `process` is caught and counted the same way).

mod calibration;
mod config;
mod fish;
mod frame;
mod outcome;
mod rate;
mod substitute;

pub use calibration::Calibration;
pub use config::PipelineConfig;

pub use fish::FishPipeline;
pub use frame::{Frame, PixelFormat, i420_len};
pub use outcome::FrameOutcome;
pub use substitute::Substitute;
// The depth fit's types, where the pipeline's users have always found them.
pub use crate::metric::{DepthFitState, DepthGrid, FitStats, ScaleSource};

use crate::units::{MetresPerSecond, Seconds};

/// Quality flags of an activity sample (mirrored in the status register bits 3, 4, 6 and 10).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QualityFlags {
    /// Fewer tracked fish than `motion.min_fish`.
    pub too_few_fish: bool,
    /// No metric depth fit yet (reference objects not seen): speeds are in uncalibrated units.
    pub unfitted: bool,
    /// The value is older than `output.stale_after_s` (set by the service, not the pipeline).
    pub stale: bool,
    /// The detections look unlike fish (`[familiarity]`, status bit 10): the value is not to be
    /// trusted, and the feeding rule does not act on it.
    pub unlike_fish: bool,
}

/// One activity sample (paper eq. 5: mean over tracked fish of each fish's 3D speed at a frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActivitySample {
    /// Timestamp of the frame the sample belongs to (camera clock).
    pub timestamp: Seconds,
    /// Swarm mean speed (eq. 5), m/s.
    pub mean: MetresPerSecond,
    /// Swarm mean speed in body lengths per second.
    pub mean_body_lengths: f64,
    /// Smoothed activity (EWMA over `motion.smoothing_s`), m/s.
    pub smoothed: MetresPerSecond,
    /// Half-width of the 95% interval of the mean, m/s.
    pub ci95_half: MetresPerSecond,
    /// Number of fish in the mean.
    pub fish: u32,
    /// How far back the mean refers to (a speed over a span is the speed at its middle), s.
    pub latency: Seconds,
    /// Quality flags.
    pub flags: QualityFlags,
    /// What set the metric scale of this sample (status bit 8, the series' and history's `scale`).
    pub scale: ScaleSource,
}

/// Health of the pipeline stages, published in the status register and the console.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageHealth {
    /// The detector ran successfully on its last scheduled frame.
    pub detector_ok: bool,
    /// The depth network ran successfully on its last scheduled frame.
    pub depth_ok: bool,
    /// Detector runs per second achieved.
    pub detector_hz: f64,
    /// Depth runs per second achieved.
    pub depth_hz: f64,
    /// Detector runs since start (the metrics' counter; `rate()` of it is `detector_hz`).
    pub detector_runs: u64,
    /// Depth network runs since start.
    pub depth_runs: u64,
    /// Tracks currently confirmed.
    pub tracks: u32,
    /// The familiarity monitor's state ("detections look unlike fish", `[familiarity]`).
    pub familiarity: crate::familiarity::FamiliarityState,
}

/// A pipeline: owns all per-frame state; called on the pipeline thread only.
pub trait Pipeline: Send {
    /// Processes one frame and returns what it produced (the pipeline decides its own detection
    /// and depth schedule from frame timestamps; the service rate-limits what reaches the outputs).
    /// An `Err` is a bad frame or a stage failure: the service logs it, raises a status bit and goes on.
    fn process(&mut self, frame: &Frame) -> Result<FrameOutcome<'_>, PipelineError>;
    /// Current stage health (also after a frame that failed).
    fn health(&self) -> StageHealth;
    /// Takes a new camera calibration while running (a reload: SIGHUP or the web page's apply),
    /// set up as at start; `Err` (named problem) keeps the one in use. The default: refused.
    fn set_calibration(&mut self, _calibration: Option<&Calibration>) -> Result<(), String> {
        Err("this pipeline cannot take a new calibration while running".into())
    }
    /// The networks this pipeline runs (the start-up line, the build-info metric). The default: none.
    fn networks(&self) -> Networks {
        Networks::default()
    }
    /// Each reference object in view: its pixel and the depth fit's residual there (fitted minus
    /// known depth, m; NaN without a fit or a depth reading), into `out`. A depth reading each, so
    /// only snapshots ask. The default: none.
    fn reference_residuals(&self, out: &mut Vec<(crate::geometry::Pixel, f64)>) {
        out.clear();
    }
    /// Metric depth (m, NaN where unknown) on a `cols` x `rows` grid of cell centres over a
    /// `width` x `height` image, row-major into `out`; false when there is no metric depth yet.
    fn depth_grid(&self, _size: (u32, u32), _grid: (u32, u32), _out: &mut Vec<f32>) -> bool {
        false
    }
}

/// One network a pipeline runs: its file, numeric form and backend.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    /// The model file as resolved (an embedded copy keeps its default path).
    pub path: std::path::PathBuf,
    /// float32, int8 QDQ or int8 QOperator.
    pub form: crate::infer::ModelForm,
    /// The runtime running it.
    pub backend: crate::infer::Backend,
}

/// The networks of a pipeline; `None` where a stage runs none (replaced in `fme eval`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Networks {
    /// The fish detector.
    pub detector: Option<Network>,
    /// The relative-depth network.
    pub depth: Option<Network>,
}

impl std::fmt::Display for Networks {
    /// `detector models/fish_det_int8.onnx (int8-qdq, onnxruntime), depth ...`, or `none`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut first = true;
        for (what, n) in [("detector", &self.detector), ("depth", &self.depth)] {
            if let Some(n) = n {
                let sep = if first { "" } else { ", " };
                write!(f, "{sep}{what} {} ({}, {})", n.path.display(), n.form, n.backend)?;
                first = false;
            }
        }
        if first {
            f.write_str("none")?;
        }
        Ok(())
    }
}

/// A per-frame pipeline failure.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The frame could not be decoded.
    #[error("frame {seq}: cannot decode: {message}")]
    Decode {
        /// Frame sequence number.
        seq: u64,
        /// Decoder message.
        message: String,
    },
    /// A stage (detector, depth, ...) failed.
    #[error("{stage}: {message}")]
    Stage {
        /// Stage name.
        stage: &'static str,
        /// What went wrong.
        message: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::infer::{Backend, ModelForm};

    #[test]
    fn networks_read_as_the_start_up_line_names_them() {
        assert_eq!(Networks::default().to_string(), "none");
        let det = Network { path: "models/d.onnx".into(), form: ModelForm::Int8Qdq, backend: Backend::DEFAULT };
        let depth = Network { path: "models/z.onnx".into(), form: ModelForm::Fp32, backend: Backend::DEFAULT };
        let b = Backend::DEFAULT.name();
        let both = Networks { detector: Some(det), depth: Some(depth.clone()) };
        assert_eq!(
            both.to_string(),
            format!("detector models/d.onnx (int8-qdq, {b}), depth models/z.onnx (fp32, {b})")
        );
        assert_eq!(
            Networks { detector: None, depth: Some(depth) }.to_string(),
            format!("depth models/z.onnx (fp32, {b})")
        );
    }
}
