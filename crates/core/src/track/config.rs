//! Tracker configuration: the `[tracker]` section of the config. A preset gives the base values and
//! every other key overrides it; `fme run`, `fme eval`, `fme track` and `fme tune` read the same type.

use super::kalman::CvNoise;

/// Association algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Exact SORT (abewley/sort): one IoU stage over all detections, SORT's filter and output rule,
    /// frame-counted ages.
    Sort,
    /// ByteTrack-style cascade on a constant-velocity filter in real time (the `default` preset).
    Byte,
}

/// The base settings a `[tracker]` section starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrackerPreset {
    /// ByteTrack-style two-stage association on a constant-velocity filter (our best).
    #[default]
    Default,
    /// The reference SORT tracker (abewley/sort), exactly.
    Sort,
}

impl crate::choice::Choice for TrackerPreset {
    const ALL: &'static [Self] = &[Self::Default, Self::Sort];
}

/// All tracker settings (`[tracker]`). See the module docs of [`crate::track`] for the mapping onto
/// the paper's Table 1. Deserialised over its preset: keys not given keep the preset's values.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Patch")]
pub struct TrackerConfig {
    /// The base the other keys override: `default` or `sort`.
    pub preset: TrackerPreset,
    /// Association algorithm.
    pub mode: Mode,
    /// `T_d`: detections scoring below this are ignored.
    pub det_threshold: f64,
    /// `T_t`: detections at or above this score are "high" (first stage, may start tracks); the
    /// others (at or above `det_threshold`) only extend existing tracks in the second stage.
    pub track_threshold: f64,
    /// `T_unt`: minimum score of an unmatched ("untracked") detection to start a new track.
    pub new_track_threshold: f64,
    /// `T_iou`: minimum IoU between a predicted track box and a detection in the first stage.
    pub iou_threshold: f64,
    /// Minimum IoU in the second (low-score) stage.
    pub low_iou_threshold: f64,
    /// `T_unc`: minimum IoU to extend an unconfirmed (tentative) track.
    pub unconfirmed_iou_threshold: f64,
    /// Hits needed to confirm a track (SORT: consecutive hits, `min_hits`).
    pub min_hits: u32,
    /// Byte mode: how long a lost track is kept for recovery, seconds.
    pub max_age_s: f64,
    /// Sort mode: SORT's `max_age`, in frames (updates).
    pub max_age_frames: u32,
    /// Byte mode: multiply IoU by the detection score in the first-stage cost (ByteTrack's fusion).
    pub fuse_score: bool,
    /// Byte mode: weight of the relative depth difference in the cost (0 = depth unused).
    pub depth_weight: f64,
    /// Byte mode: buffered IoU (C-BIoU, Yang et al. 2023): both boxes are widened by `b` times their
    /// size on each side before the IoU, for tentative tracks, with `b = min(buffer_max, buffer_rate * time since the
    /// track's last match)`, so that a new track can be confirmed at slow detection rates.
    pub buffer_rate: f64,
    /// Byte mode: largest buffer `b`.
    pub buffer_max: f64,
    /// Byte mode: Kalman noise.
    pub noise: CvNoise,
    /// Most live tracks, at most [`super::MAX_TRACKS`] (the compiled capacity).
    pub max_tracks: usize,
}

impl TrackerConfig {
    /// Exact SORT: `max_age = 1`, `min_hits = 3`, `iou_threshold = 0.3`, no score threshold.
    pub fn sort() -> Self {
        Self {
            preset: TrackerPreset::Sort,
            mode: Mode::Sort,
            det_threshold: f64::NEG_INFINITY,
            track_threshold: f64::NEG_INFINITY,
            new_track_threshold: f64::NEG_INFINITY,
            iou_threshold: 0.3,
            low_iou_threshold: 0.3,
            unconfirmed_iou_threshold: 0.3,
            min_hits: 3,
            max_age_s: 0.0,
            max_age_frames: 1,
            fuse_score: false,
            depth_weight: 0.0,
            buffer_rate: 0.0,
            buffer_max: 0.0,
            noise: CvNoise::default(),
            max_tracks: super::MAX_TRACKS,
        }
    }

    /// Our best settings (found with `fme tune` and on mot15; docs/accuracy.md, "Tracking").
    pub fn default_preset() -> Self {
        Self {
            preset: TrackerPreset::Default,
            mode: Mode::Byte,
            det_threshold: 0.1,
            track_threshold: 0.5,
            new_track_threshold: 0.8,
            iou_threshold: 0.2,
            low_iou_threshold: 0.5,
            unconfirmed_iou_threshold: 0.3,
            min_hits: 2,
            max_age_s: 1.0,
            max_age_frames: 30,
            fuse_score: false,
            depth_weight: 0.0,
            buffer_rate: 3.0,
            buffer_max: 0.5,
            noise: CvNoise::default(),
            max_tracks: super::MAX_TRACKS,
        }
    }

    /// The settings of a preset.
    pub fn preset(preset: TrackerPreset) -> Self {
        match preset {
            TrackerPreset::Sort => Self::sort(),
            TrackerPreset::Default => Self::default_preset(),
        }
    }

    /// Checks ranges; returns the first offending key.
    pub fn validate(&self) -> Result<(), TrackerConfigError> {
        let unit = |k: &str, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(TrackerConfigError::Key(k.into(), format!("{v} is not in [0, 1]")))
            }
        };
        unit("iou_threshold", self.iou_threshold)?;
        unit("low_iou_threshold", self.low_iou_threshold)?;
        unit("unconfirmed_iou_threshold", self.unconfirmed_iou_threshold)?;
        for (k, v) in [
            ("det_threshold", self.det_threshold),
            ("track_threshold", self.track_threshold),
            ("new_track_threshold", self.new_track_threshold),
        ] {
            if v.is_nan() {
                return Err(TrackerConfigError::Key(k.into(), "a score threshold must not be NaN".into()));
            }
        }
        if !(self.max_age_s >= 0.0 && self.max_age_s.is_finite()) {
            return Err(TrackerConfigError::Key(
                "max_age_s".into(),
                format!("{} is not a finite time >= 0", self.max_age_s),
            ));
        }
        if !(self.depth_weight >= 0.0 && self.depth_weight.is_finite()) {
            return Err(TrackerConfigError::Key("depth_weight".into(), format!("{} is not >= 0", self.depth_weight)));
        }
        if self.buffer_rate.is_nan() || self.buffer_rate < 0.0 {
            return Err(TrackerConfigError::Key("buffer_rate".into(), format!("{} is not >= 0", self.buffer_rate)));
        }
        if !(self.buffer_max >= 0.0 && self.buffer_max.is_finite()) {
            return Err(TrackerConfigError::Key(
                "buffer_max".into(),
                format!("{} is not finite and >= 0", self.buffer_max),
            ));
        }
        if self.max_tracks == 0 || self.max_tracks > super::MAX_TRACKS {
            return Err(TrackerConfigError::Key(
                "max_tracks".into(),
                format!("{} is not in 1..={}", self.max_tracks, super::MAX_TRACKS),
            ));
        }
        let n = self.noise;
        for (k, v) in [("noise.meas", n.meas), ("noise.accel", n.accel), ("noise.init_vel", n.init_vel)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(TrackerConfigError::Key(k.into(), format!("{v} is not a finite number > 0")));
            }
        }
        Ok(())
    }
}

/// A configuration error naming the key.
#[derive(Debug, thiserror::Error)]
pub enum TrackerConfigError {
    /// Not valid TOML or an unknown/ill-typed key (the message names it).
    #[error("tracker config: {0}")]
    Toml(String),
    /// A key with a value out of range.
    #[error("tracker config key `{0}`: {1}")]
    Key(String, String),
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self::default_preset()
    }
}

/// What a `[tracker]` section may set: a preset and any key over it.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields, expecting = "a [tracker] table (preset and tracker keys)")]
struct Patch {
    preset: Option<TrackerPreset>,
    mode: Option<Mode>,
    det_threshold: Option<f64>,
    track_threshold: Option<f64>,
    new_track_threshold: Option<f64>,
    iou_threshold: Option<f64>,
    low_iou_threshold: Option<f64>,
    unconfirmed_iou_threshold: Option<f64>,
    min_hits: Option<u32>,
    max_age_s: Option<f64>,
    max_age_frames: Option<u32>,
    fuse_score: Option<bool>,
    depth_weight: Option<f64>,
    buffer_rate: Option<f64>,
    buffer_max: Option<f64>,
    noise: Option<CvNoise>,
    max_tracks: Option<usize>,
}

impl TryFrom<Patch> for TrackerConfig {
    type Error = TrackerConfigError;
    fn try_from(p: Patch) -> Result<Self, TrackerConfigError> {
        p.apply()
    }
}

impl Patch {
    fn apply(self) -> Result<TrackerConfig, TrackerConfigError> {
        let mut c = TrackerConfig::preset(self.preset.unwrap_or_default());
        macro_rules! set {
            ($($k:ident),*) => { $( if let Some(v) = self.$k { c.$k = v; } )* };
        }
        set!(
            mode,
            det_threshold,
            track_threshold,
            new_track_threshold,
            iou_threshold,
            low_iou_threshold,
            unconfirmed_iou_threshold
        );
        set!(min_hits, max_age_s, max_age_frames, fuse_score, depth_weight, buffer_rate, buffer_max, noise, max_tracks);
        c.validate()?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<TrackerConfig, String> {
        toml::from_str::<TrackerConfig>(text).map_err(|e| e.to_string())
    }

    #[test]
    fn keys_override_the_preset_and_unknown_keys_are_rejected() {
        let c = parse("preset = \"sort\"\niou_threshold = 0.5\n").expect("valid");
        assert_eq!((c.preset, c.mode, c.iou_threshold, c.min_hits), (TrackerPreset::Sort, Mode::Sort, 0.5, 3));
        let e = parse("iou_tresh = 0.5").expect_err("typo");
        assert!(e.contains("iou_tresh"), "{e}");
        let c = parse("iou_threshold = 0.4\nmax_age_s = 2.0\nmax_tracks = 64\n").expect("keys");
        assert_eq!((c.preset, c.iou_threshold, c.max_age_s, c.max_tracks), (TrackerPreset::Default, 0.4, 2.0, 64));
        assert!(parse("max_tracks = 129").is_err());
        let e = parse("iou_threshold = 1.5").expect_err("range");
        assert!(e.contains("iou_threshold"), "{e}");
        assert!(parse("preset = \"bytetrack\"").is_err(), "presets are an enum");
    }

    #[test]
    fn serialised_config_reads_back_identical() {
        for c in [TrackerConfig::sort(), TrackerConfig::default_preset()] {
            let text = toml::to_string(&c).expect("serialise");
            assert_eq!(parse(&text), Ok(c), "{text}");
        }
    }
}
