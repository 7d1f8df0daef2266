//! The pipeline boundary: frames in, activity samples out.
//!
//! The daemon (capture, queues, outputs, console, watchdog) only knows the [`Pipeline`] trait. `fme run`
//! uses [`super::fish_pipeline::FishPipeline`] (detector + tracker + depth + post-processing + motion,
//! paper eq. 1-5). [`FrameDiffPipeline`] is a test double for the daemon's edges (Modbus, serial,
//! console, watchdog tests and benchmarks that must not depend on models): it is *not* a fish-speed
//! estimate.
//!
//! Errors from a stage are returned as [`PipelineError::Stage`] (the service counts and logs them and
//! keeps going; a panic inside `process` is caught and counted the same way).

use crate::capture::Frame;
use crate::units::{MetresPerSecond, Seconds};

/// Quality flags of an activity sample (mirrored in the status register bits 3, 4 and 6).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QualityFlags {
    /// Fewer tracked fish than `motion.min_fish`.
    pub too_few_fish: bool,
    /// No metric depth fit yet (reference objects not seen): speeds are in uncalibrated units.
    pub depth_uncalibrated: bool,
    /// The value is older than `output.stale_after_s` (set by the service, not the pipeline).
    pub stale: bool,
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
    /// Quality flags.
    pub flags: QualityFlags,
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
    /// Tracks currently confirmed.
    pub tracks: u32,
}

/// Metric depth calibration state (paper eq. 1-2), shown by the console `calib` command.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CalibInfo {
    /// Fitted scale s.
    pub scale: f64,
    /// Fitted shift t.
    pub shift: f64,
    /// RMS residual of the fit on the reference objects, m.
    pub residual_m: f64,
    /// Reference objects visible in the last depth frame.
    pub references_visible: u32,
    /// Whether a fit is available.
    pub calibrated: bool,
}

/// A pipeline: owns all per-frame state; called on the pipeline thread only.
pub trait Pipeline: Send {
    /// Processes one frame. Returns a sample when one is due (the pipeline decides its own detection
    /// and depth schedule from frame timestamps; the service rate-limits what reaches the outputs).
    /// An `Err` is a bad frame or a stage failure: the service logs it, raises a status bit and goes on.
    fn process(&mut self, frame: &Frame) -> Result<Option<ActivitySample>, PipelineError>;
    /// Current stage health.
    fn health(&self) -> StageHealth;
    /// Current calibration.
    fn calib(&self) -> CalibInfo {
        CalibInfo::default()
    }
    /// Writes one line per confirmed track (console `tracks`), at most `max` lines.
    fn describe_tracks(&self, _out: &mut dyn std::fmt::Write, _max: usize) -> std::fmt::Result {
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

/// Test double for the daemon's edges: the "activity" is the mean absolute
/// grey-level change between consecutive frames on a coarse grid, scaled by `scale_mps` per unit of
/// mean change per second. It exercises every edge of the daemon with values that move with the
/// scene; it is **not** a fish-speed estimate and always flags `depth_uncalibrated`.
#[derive(Debug)]
pub struct FrameDiffPipeline {
    prev: Vec<u8>,
    cur: Vec<u8>,
    prev_t: Option<Seconds>,
    smoothed: Option<f64>,
    smoothing_s: f64,
    scale_mps: f64,
    body_length_m: f64,
    grid: usize,
    ok: bool,
}

impl FrameDiffPipeline {
    /// Grid cells per side used for the grey-level comparison.
    pub const GRID: usize = 32;

    /// A test double with EWMA time constant `smoothing_s` and body length `body_length_m`.
    pub fn new(smoothing_s: f64, body_length_m: f64) -> Self {
        Self {
            prev: vec![0; Self::GRID * Self::GRID],
            cur: vec![0; Self::GRID * Self::GRID],
            prev_t: None,
            smoothed: None,
            smoothing_s,
            scale_mps: 0.02,
            body_length_m,
            grid: Self::GRID,
            ok: false,
        }
    }

    fn sample_grid(&self, frame: &Frame, out: &mut [u8]) -> Result<(), PipelineError> {
        let img = frame.to_luma().map_err(|message| PipelineError::Decode { seq: frame.seq, message })?;
        let (w, h) = (img.width() as usize, img.height() as usize);
        if w == 0 || h == 0 {
            return Err(PipelineError::Decode { seq: frame.seq, message: "empty image".into() });
        }
        for gy in 0..self.grid {
            for gx in 0..self.grid {
                let x = (gx * w + w / 2) / self.grid;
                let y = (gy * h + h / 2) / self.grid;
                out[gy * self.grid + gx] = img.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0[0];
            }
        }
        Ok(())
    }
}

impl Pipeline for FrameDiffPipeline {
    fn process(&mut self, frame: &Frame) -> Result<Option<ActivitySample>, PipelineError> {
        let mut cur = std::mem::take(&mut self.cur);
        let r = self.sample_grid(frame, &mut cur);
        self.cur = cur;
        if let Err(e) = r {
            self.ok = false;
            return Err(e);
        }
        self.ok = true;
        let t = frame.timestamp;
        let prev_t = self.prev_t.replace(t);
        std::mem::swap(&mut self.prev, &mut self.cur); // prev = this frame, cur = the previous one
        let Some(pt) = prev_t else { return Ok(None) };
        let dt = (t - pt).get();
        if dt.is_nan() || dt <= 0.0 {
            return Ok(None); // loop restart or duplicate timestamp: no speed across it
        }
        let n = self.cur.len() as f64;
        let diffs = self.cur.iter().zip(&self.prev).map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs() / 255.0);
        let (sum, sum2) = diffs.fold((0.0, 0.0), |(s, s2), d| (s + d, s2 + d * d));
        let mean = sum / n;
        let var = (sum2 / n - mean * mean).max(0.0);
        let v = self.scale_mps * mean / dt;
        let ci = self.scale_mps * 1.96 * (var / n).sqrt() / dt;
        let alpha = (dt / self.smoothing_s).clamp(0.0, 1.0);
        let s = match self.smoothed {
            Some(s) => s + alpha * (v - s),
            None => v,
        };
        self.smoothed = Some(s);
        Ok(Some(ActivitySample {
            timestamp: t,
            mean: MetresPerSecond(v),
            mean_body_lengths: v / self.body_length_m,
            smoothed: MetresPerSecond(s),
            ci95_half: MetresPerSecond(ci),
            fish: 0,
            flags: QualityFlags { too_few_fish: true, depth_uncalibrated: true, stale: false },
        }))
    }

    fn health(&self) -> StageHealth {
        // No depth stage here, so nothing to fail: depth_ok follows frame decoding like detector_ok.
        StageHealth { detector_ok: self.ok, depth_ok: self.ok, ..StageHealth::default() }
    }
}
