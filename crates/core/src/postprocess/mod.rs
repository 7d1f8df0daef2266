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
//!   window (1 s) of corrected depths. A jump that persists longer than `depth_max_hold_s` is accepted
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
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

/// Post-processing settings: the `[postprocess]` section of the config (paper eq. 3 and 4). One type
/// for every command: `fme run`, `fme eval`, `fme track` and `fme tune` read the same keys.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PostprocessConfig {
    /// Box-fluctuation detector and its correction (eq. 3). Off by default: it raised the speed
    /// error on our synthetic swarms (docs/accuracy.md, ablations).
    pub box_fluctuation: bool,
    /// Window of past frame-to-frame size changes averaged by eq. 3, s (paper: 30 frames at 30 fps).
    pub box_window_s: Seconds,
    /// Window of previous sizes whose EWMA replaces an abnormal size, s (paper: 5 frames at 30 fps).
    pub box_ewma_s: Seconds,
    /// What stays put when eq. 3 replaces a dimension.
    pub box_anchor: BoxAnchor,
    /// Past size changes needed before eq. 3 may fire (warm-up).
    pub box_min_history: usize,
    /// Depth-jump detector and its correction (eq. 4).
    pub depth_jump: bool,
    /// Eq. 4's threshold delta, m (paper: 0.6 m).
    pub depth_jump_m: Metres,
    /// Window of past corrected depths whose EWMA replaces a jumped depth, s (paper: 30 frames at 30 fps).
    pub depth_window_s: Seconds,
    /// A jump persisting longer than this is accepted as the new depth, s.
    pub depth_max_hold_s: Seconds,
    /// Time constant of each track's depth smoothing after eq. 4, s (0 = off; not in the paper): a
    /// depth network's frame-to-frame flicker otherwise becomes speed; longer smoothing also damps
    /// real depth motion (docs/accuracy.md).
    pub depth_smoothing_s: Seconds,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        // The paper's frame counts at its 30 fps.
        const FPS: f64 = 30.0;
        Self {
            box_fluctuation: false,
            box_window_s: Seconds(30.0 / FPS),
            box_ewma_s: Seconds(5.0 / FPS),
            box_anchor: BoxAnchor::LeastMoved,
            box_min_history: 3,
            depth_jump: true,
            depth_jump_m: Metres(0.6),
            depth_window_s: Seconds(30.0 / FPS),
            depth_max_hold_s: Seconds(1.0),
            depth_smoothing_s: Seconds(0.75),
        }
    }
}

impl PostprocessConfig {
    /// The paper's settings: both detectors on.
    pub fn paper() -> Self {
        Self { box_fluctuation: true, ..Self::default() }
    }

    /// Both detectors and the depth smoothing off: boxes and depths pass through unchanged.
    pub fn off() -> Self {
        Self { box_fluctuation: false, depth_jump: false, depth_smoothing_s: Seconds(0.0), ..Self::default() }
    }

    /// Checks that windows and thresholds are positive and finite; names the bad key.
    pub fn validate(&self) -> Result<(), &'static str> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.box_window_s.0) {
            return Err("postprocess.box_window_s must be a positive number of seconds");
        }
        if !pos(self.box_ewma_s.0) {
            return Err("postprocess.box_ewma_s must be a positive number of seconds");
        }
        if !pos(self.depth_jump_m.0) {
            return Err("postprocess.depth_jump_m must be a positive number of metres");
        }
        if !pos(self.depth_window_s.0) {
            return Err("postprocess.depth_window_s must be a positive number of seconds");
        }
        if !pos(self.depth_max_hold_s.0) {
            return Err("postprocess.depth_max_hold_s must be a positive number of seconds");
        }
        if !(self.depth_smoothing_s.0.is_finite() && self.depth_smoothing_s.0 >= 0.0) {
            return Err("postprocess.depth_smoothing_s must be zero (off) or a positive number of seconds");
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
        let bad = PostprocessConfig { depth_window_s: Seconds(f64::NAN), ..Default::default() };
        assert!(bad.validate().unwrap_err().contains("depth_window_s"));
    }
}
