//! `[motion]`: how speeds and the activity index are computed (paper eq. 5).

use super::heading::AlongRay;
use crate::units::{Metres, MetresPerSecond, Seconds};

/// How a fish's speed is computed from its recent world positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SpeedMethod {
    /// `|P_t - P_ref| / (t - t_ref)` with `P_ref` the oldest position within `speed_span` (at least
    /// the previous one): with span 0 this is the paper's frame-to-frame speed.
    #[default]
    Chord,
    /// Norm of the least-squares slope of position against time over the positions within
    /// `speed_span` (at least 3 of them, else the chord): per-fish velocity noise falls with the
    /// number of positions, and so does the upward bias that noise gives `|v|`.
    Regression,
}

impl crate::choice::Choice for SpeedMethod {
    const ALL: &'static [Self] = &[Self::Chord, Self::Regression];
}

/// Motion settings: the `[motion]` section of the config (paper eq. 5 and the activity sample).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Mean fish body length for body lengths/s, m; 0 = estimated per fish
    /// ([`super::heading::fish_length`]).
    pub body_length_m: Metres,
    /// Spread of the cohort's lengths: standard deviation over the mean (a graded cohort about 0.1).
    /// The fish fit (`depth.scale`) accepts a fish as a ruler within twice this of the others.
    pub body_length_cv: f64,
    /// Fewer fish in the mean than this raises the "too few fish" status bit.
    pub min_fish: u32,
    /// Time constant of the exponential smoothing of the activity index, s.
    pub smoothing_s: Seconds,
    /// Speed is taken over the oldest stored position at most this long ago (at least the previous
    /// one), s: 0 = frame to frame, as the paper. Longer spans trade latency for less noise (at most
    /// 32 positions are kept, so spans beyond 32 frames use the oldest of those).
    pub speed_span_s: Seconds,
    /// A fish enters the mean only once it has been tracked this long, s: a young track's speed is a
    /// chord over its first few frames, noisy and biased. 0 = every fish with two positions, as the
    /// paper.
    pub min_age_s: Seconds,
    /// Chord (the paper) or least-squares regression over the span.
    pub speed_method: SpeedMethod,
    /// Where the speed along the line of sight comes from: the fish's heading
    /// ([`super::heading`]) or the change of its depth (the paper).
    pub along_ray: AlongRay,
    /// A fish's width over its length, as seen head-on (salmon about 0.1): the heading method's
    /// foreshortening model.
    pub body_width_ratio: f64,
    /// A track not seen for this long is forgotten (its slot is reused), s.
    pub track_timeout_s: Seconds,
    /// Per-fish speeds above this are treated as glitches and left out of the mean, m/s.
    pub max_speed_mps: MetresPerSecond,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            body_length_m: Metres(0.35),
            body_length_cv: 0.1,
            min_fish: 3,
            smoothing_s: Seconds(60.0),
            // 1 s chords instead of the paper's frame-to-frame speed (docs/accuracy.md, ablations);
            // the estimate then refers to t - 0.5 s (`SwarmEstimate::latency`).
            speed_span_s: Seconds(1.0),
            // A full span before a fish counts (docs/accuracy.md, ablations).
            min_age_s: Seconds(1.0),
            speed_method: SpeedMethod::Chord,
            along_ray: AlongRay::Heading,
            body_width_ratio: 0.1,
            track_timeout_s: Seconds(1.0),
            max_speed_mps: MetresPerSecond(10.0),
        }
    }
}

impl MotionConfig {
    /// The configured body length, or `None` when it is estimated per fish (`body_length_m = 0`).
    pub fn body_length(&self) -> Option<Metres> {
        (self.body_length_m.0 > 0.0).then_some(self.body_length_m)
    }

    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.body_length_m.0.is_finite() && self.body_length_m.0 >= 0.0) {
            return Err("motion.body_length_m must be >= 0 m (0 = estimated per fish)");
        }
        if !(self.body_length_cv.is_finite() && (0.0..=0.5).contains(&self.body_length_cv)) {
            return Err("motion.body_length_cv must be within 0..=0.5");
        }
        if !(self.speed_span_s.0.is_finite() && self.speed_span_s.0 >= 0.0) {
            return Err("motion.speed_span_s must be zero or a positive number of seconds");
        }
        if !(self.min_age_s.0.is_finite() && self.min_age_s.0 >= 0.0) {
            return Err("motion.min_age_s must be zero or a positive number of seconds");
        }
        if !(self.body_width_ratio.is_finite() && (0.0..=0.5).contains(&self.body_width_ratio)) {
            return Err("motion.body_width_ratio must be within 0..=0.5");
        }
        if !(self.smoothing_s.0.is_finite() && self.smoothing_s.0 > 0.0) {
            return Err("motion.smoothing_s must be a positive number of seconds");
        }
        if !(self.track_timeout_s.0.is_finite() && self.track_timeout_s.0 > 0.0) {
            return Err("motion.track_timeout_s must be a positive number of seconds");
        }
        if !(self.max_speed_mps.0.is_finite() && self.max_speed_mps.0 > 0.0) {
            return Err("motion.max_speed_mps must be a positive speed in m/s");
        }
        Ok(())
    }
}
