//! Post-processing of tracks (paper section 3.2): the box-fluctuation detector (eq. 3) and the
//! depth-jump detector (eq. 4), each followed by an EWMA correction.
//!
//! Our reading of what the paper leaves open (`design.md`):
//! - Eq. 3 compares `|w_t - w_{t-1}|` with the mean absolute frame-to-frame change of the raw width
//!   over the past window (30 frames at 30 fps = 1 s); same for the height. On an abnormal change the
//!   dimension becomes the EWMA of its previous 5 corrected values (1/6 s at 30 fps) and the box is
//!   rebuilt around the edge that moved least, so tail swings do not drag the centre.
//! - Eq. 4 flags `|d_t - d*_{t-1}| >= delta` (0.6 m), comparing with the previous *corrected* depth so
//!   an occlusion lasting several frames stays flagged; the depth then becomes the EWMA of the past
//!   window (1 s) of corrected depths. A jump that persists longer than `depth_max_hold` is accepted
//!   as real (e.g. an identity switch), so a track cannot freeze forever.
//! - EWMA weight `alpha = 2 / (N + 1)` for `N` samples, oldest first.
//! - Windows are in seconds and applied to the samples' timestamps, so a reduced detection rate keeps
//!   their meaning; history is capped at [`HISTORY`] samples per track.
//!
//! [`TrackFilter`] is the fixed-size per-track state; it never allocates.

mod filter;

pub use filter::{BoxCorrection, TrackFilter};

use crate::units::{Metres, Seconds};

/// Samples of history kept per track (covers a 1 s window up to 64 samples/s).
pub const HISTORY: usize = 64;

/// Which part of the detected box stays put when eq. 3 replaces its width or height.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum BoxAnchor {
    /// The edge (per axis) that moved least since the previous frame (`design.md`).
    #[default]
    LeastMoved,
    /// The top-left corner, as a literal reading of the paper ("update the dimensions, then compute
    /// the centre").
    TopLeft,
    /// The detected centre: only the size is smoothed, the centre (and so the speed) is untouched.
    Centre,
}

/// Depth smoothing for depth estimated by a network (`fme run`'s default, `fme eval --depth model`'s
/// default). Measured on held-out swarms (README): without it the network's flicker becomes speed
/// (+0.09 to +0.20 m/s of bias); longer, it damps real depth motion (-0.03 to -0.05 m/s at 2 s).
/// 0.75 s since depth is read only where a fish is seen (`depth.sample = "visible"`): less flicker
/// to smooth. With ground-truth depth it only adds lag, so the library default is off.
pub const ESTIMATED_DEPTH_SMOOTHING: Seconds = Seconds(0.75);

/// Post-processing settings (the `[postprocess]` config section).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PostprocessConfig {
    /// Switch for the box-fluctuation detector and its correction (eq. 3).
    pub box_fluctuation: bool,
    /// Window of past frame-to-frame size changes averaged by eq. 3 (paper: 30 frames at 30 fps).
    pub fluctuation_window: Seconds,
    /// Window of previous sizes whose EWMA replaces an abnormal size (paper: 5 frames at 30 fps).
    pub box_ewma_window: Seconds,
    /// What stays put when eq. 3 replaces a dimension.
    pub box_anchor: BoxAnchor,
    /// Minimum number of past size changes before eq. 3 may fire (warm-up).
    pub fluctuation_min_history: usize,
    /// Switch for the depth-jump detector and its correction (eq. 4).
    pub depth_jump: bool,
    /// Eq. 4's threshold delta (paper: 0.6 m).
    pub depth_jump_threshold: Metres,
    /// Window of past corrected depths whose EWMA replaces a jumped depth (paper: 30 frames at 30 fps).
    pub depth_ewma_window: Seconds,
    /// A jump persisting longer than this is accepted as the new depth.
    pub depth_max_hold: Seconds,
    /// Time constant of an exponential smoothing of each track's depth after eq. 4 (not in the
    /// paper; 0 = off). For estimated depth maps, whose frame-to-frame flicker otherwise becomes speed.
    pub depth_smoothing: Seconds,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        // The paper's frame counts at its 30 fps.
        const FPS: f64 = 30.0;
        Self {
            // Off by default: on our synthetic swarms eq. 3 (as read in design.md) raises the speed
            // RMSE (0.016 -> 0.02 m/s with 1 s spans, 0.09 -> 0.23 frame to frame); see the README.
            box_fluctuation: false,
            fluctuation_window: Seconds(30.0 / FPS),
            box_ewma_window: Seconds(5.0 / FPS),
            box_anchor: BoxAnchor::LeastMoved,
            fluctuation_min_history: 3,
            depth_jump: true,
            depth_jump_threshold: Metres(0.6),
            depth_ewma_window: Seconds(30.0 / FPS),
            depth_max_hold: Seconds(1.0),
            depth_smoothing: Seconds(0.0),
        }
    }
}

impl PostprocessConfig {
    /// The paper's settings: both detectors on.
    pub fn paper() -> Self {
        Self { box_fluctuation: true, ..Self::default() }
    }

    /// Both detectors off: boxes and depths pass through unchanged.
    pub fn off() -> Self {
        Self { box_fluctuation: false, depth_jump: false, ..Self::default() }
    }

    /// Checks that windows and thresholds are positive and finite; names the bad key.
    pub fn validate(&self) -> Result<(), &'static str> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.fluctuation_window.0) {
            return Err("postprocess.fluctuation_window must be a positive number of seconds");
        }
        if !pos(self.box_ewma_window.0) {
            return Err("postprocess.box_ewma_window must be a positive number of seconds");
        }
        if !pos(self.depth_jump_threshold.0) {
            return Err("postprocess.depth_jump_threshold must be a positive number of metres");
        }
        if !pos(self.depth_ewma_window.0) {
            return Err("postprocess.depth_ewma_window must be a positive number of seconds");
        }
        if !pos(self.depth_max_hold.0) {
            return Err("postprocess.depth_max_hold must be a positive number of seconds");
        }
        if !(self.depth_smoothing.0.is_finite() && self.depth_smoothing.0 >= 0.0) {
            return Err("postprocess.depth_smoothing must be zero (off) or a positive number of seconds");
        }
        Ok(())
    }
}

/// EWMA of `values` (oldest first) with `alpha = 2 / (N + 1)`; `None` for no values.
pub fn ewma(values: impl ExactSizeIterator<Item = f64>) -> Option<f64> {
    let n = values.len();
    let alpha = 2.0 / (n as f64 + 1.0);
    let mut acc: Option<f64> = None;
    for v in values {
        acc = Some(match acc {
            None => v,
            Some(e) => alpha * v + (1.0 - alpha) * e,
        });
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ewma_weights_recent_values_more() {
        assert_eq!(ewma([].into_iter()), None);
        assert_eq!(ewma([4.0].into_iter()), Some(4.0));
        // N = 2, alpha = 2/3: 1 then 2/3*4 + 1/3*1 = 3.
        assert!((ewma([1.0, 4.0].into_iter()).unwrap() - 3.0).abs() < 1e-12);
        assert!(PostprocessConfig::default().validate().is_ok());
        let bad = PostprocessConfig { depth_ewma_window: Seconds(f64::NAN), ..Default::default() };
        assert!(bad.validate().unwrap_err().contains("depth_ewma_window"));
    }
}
