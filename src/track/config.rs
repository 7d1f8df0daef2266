//! Tracker configuration: the two presets and named keys (TOML, section `[track]` or top level).

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

/// All tracker settings. See the module docs of [`crate::track`] for the mapping onto the paper's
/// Table 1.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TrackerConfig {
    /// Association algorithm.
    pub mode: Mode,
    /// `T_d`: detections scoring below this are ignored.
    pub det_thresh: f64,
    /// `T_t`: detections at or above this score are "high" (first stage, may start tracks); the
    /// others (at or above `det_thresh`) only extend existing tracks in the second stage.
    pub track_thresh: f64,
    /// `T_unt`: minimum score of an unmatched ("untracked") detection to start a new track.
    pub new_track_thresh: f64,
    /// `T_iou`: minimum IoU between a predicted track box and a detection in the first stage.
    pub iou_thresh: f64,
    /// Minimum IoU in the second (low-score) stage.
    pub low_iou_thresh: f64,
    /// `T_unc`: minimum IoU to extend an unconfirmed (tentative) track.
    pub unconfirmed_iou_thresh: f64,
    /// Hits needed to confirm a track (SORT: consecutive hits, `min_hits`).
    pub min_hits: u32,
    /// Byte mode: how long a lost track is kept for recovery, seconds.
    pub max_lost_s: f64,
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
            mode: Mode::Sort,
            det_thresh: f64::NEG_INFINITY,
            track_thresh: f64::NEG_INFINITY,
            new_track_thresh: f64::NEG_INFINITY,
            iou_thresh: 0.3,
            low_iou_thresh: 0.3,
            unconfirmed_iou_thresh: 0.3,
            min_hits: 3,
            max_lost_s: 0.0,
            max_age_frames: 1,
            fuse_score: false,
            depth_weight: 0.0,
            buffer_rate: 0.0,
            buffer_max: 0.0,
            noise: CvNoise::default(),
            max_tracks: super::MAX_TRACKS,
        }
    }

    /// Our best settings (found with `fme tune` and on mot15; see the README).
    pub fn default_preset() -> Self {
        Self {
            mode: Mode::Byte,
            det_thresh: 0.1,
            track_thresh: 0.5,
            new_track_thresh: 0.8,
            iou_thresh: 0.2,
            low_iou_thresh: 0.5,
            unconfirmed_iou_thresh: 0.3,
            min_hits: 2,
            max_lost_s: 1.0,
            max_age_frames: 30,
            fuse_score: false,
            depth_weight: 0.0,
            buffer_rate: 3.0,
            buffer_max: 0.5,
            noise: CvNoise::default(),
            max_tracks: super::MAX_TRACKS,
        }
    }

    /// A preset by name (`sort` or `default`).
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "sort" => Some(Self::sort()),
            "default" => Some(Self::default_preset()),
            _ => None,
        }
    }

    /// Applies a TOML document: keys at the top level or in a `[track]` table; `preset = "..."`
    /// picks the base, the other keys override it. Unknown keys are an error that names them.
    pub fn from_toml(text: &str, base: Self) -> Result<Self, ConfigError> {
        let value: toml::Table = toml::from_str(text).map_err(|e| ConfigError::Toml(e.to_string()))?;
        let table = match value.get("track") {
            Some(toml::Value::Table(t)) => t.clone(),
            Some(_) => return Err(ConfigError::Key("track".into(), "must be a table".into())),
            None => value,
        };
        let patch: Patch =
            toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| ConfigError::Toml(e.to_string()))?;
        patch.apply(base)
    }

    /// Checks ranges; returns the first offending key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let unit = |k: &str, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(ConfigError::Key(k.into(), format!("{v} is not in [0, 1]")))
            }
        };
        unit("iou_thresh", self.iou_thresh)?;
        unit("low_iou_thresh", self.low_iou_thresh)?;
        unit("unconfirmed_iou_thresh", self.unconfirmed_iou_thresh)?;
        if self.det_thresh.is_nan() || self.track_thresh.is_nan() || self.new_track_thresh.is_nan() {
            return Err(ConfigError::Key("det_thresh".into(), "score thresholds must not be NaN".into()));
        }
        if !(self.max_lost_s >= 0.0 && self.max_lost_s.is_finite()) {
            return Err(ConfigError::Key(
                "max_lost_s".into(),
                format!("{} is not a finite time >= 0", self.max_lost_s),
            ));
        }
        if !(self.depth_weight >= 0.0 && self.depth_weight.is_finite()) {
            return Err(ConfigError::Key("depth_weight".into(), format!("{} is not >= 0", self.depth_weight)));
        }
        if !(self.buffer_rate >= 0.0 && self.buffer_max >= 0.0 && self.buffer_max.is_finite()) {
            return Err(ConfigError::Key("buffer_rate".into(), "buffer_rate and buffer_max must be >= 0".into()));
        }
        if self.max_tracks == 0 || self.max_tracks > super::MAX_TRACKS {
            return Err(ConfigError::Key(
                "max_tracks".into(),
                format!("{} is not in 1..={}", self.max_tracks, super::MAX_TRACKS),
            ));
        }
        let n = self.noise;
        if !(n.meas > 0.0 && n.accel > 0.0 && n.init_vel > 0.0) {
            return Err(ConfigError::Key("noise".into(), "meas, accel and init_vel must be > 0".into()));
        }
        Ok(())
    }
}

/// A configuration error naming the key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Not valid TOML or an unknown/ill-typed key (the message names it).
    #[error("tracker config: {0}")]
    Toml(String),
    /// A key with a value out of range.
    #[error("tracker config key `{0}`: {1}")]
    Key(String, String),
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Patch {
    preset: Option<String>,
    mode: Option<Mode>,
    det_thresh: Option<f64>,
    track_thresh: Option<f64>,
    new_track_thresh: Option<f64>,
    #[serde(alias = "iou_threshold")]
    iou_thresh: Option<f64>,
    low_iou_thresh: Option<f64>,
    unconfirmed_iou_thresh: Option<f64>,
    min_hits: Option<u32>,
    #[serde(alias = "max_age_s")]
    max_lost_s: Option<f64>,
    max_age_frames: Option<u32>,
    fuse_score: Option<bool>,
    depth_weight: Option<f64>,
    buffer_rate: Option<f64>,
    buffer_max: Option<f64>,
    noise: Option<CvNoise>,
    max_tracks: Option<usize>,
}

impl Patch {
    fn apply(self, base: TrackerConfig) -> Result<TrackerConfig, ConfigError> {
        let mut c = match &self.preset {
            Some(p) => TrackerConfig::preset(p)
                .ok_or_else(|| ConfigError::Key("preset".into(), format!("unknown preset `{p}` (sort, default)")))?,
            None => base,
        };
        macro_rules! set {
            ($($k:ident),*) => { $( if let Some(v) = self.$k { c.$k = v; } )* };
        }
        set!(mode, det_thresh, track_thresh, new_track_thresh, iou_thresh, low_iou_thresh, unconfirmed_iou_thresh);
        set!(
            min_hits,
            max_lost_s,
            max_age_frames,
            fuse_score,
            depth_weight,
            buffer_rate,
            buffer_max,
            noise,
            max_tracks
        );
        c.validate()?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_overrides_and_rejects_unknown_keys() {
        let c =
            TrackerConfig::from_toml("[track]\npreset = \"sort\"\niou_thresh = 0.5\n", TrackerConfig::default_preset())
                .expect("valid");
        assert_eq!(c.mode, Mode::Sort);
        assert_eq!(c.iou_thresh, 0.5);
        let e = TrackerConfig::from_toml("iou_tresh = 0.5", TrackerConfig::sort()).expect_err("typo");
        assert!(e.to_string().contains("iou_tresh"), "{e}");
        // The daemon's `[tracker]` names are accepted as aliases.
        let c = TrackerConfig::from_toml(
            "[track]\niou_threshold = 0.4\nmax_age_s = 2.0\nmax_tracks = 64\n",
            TrackerConfig::default_preset(),
        )
        .expect("aliases");
        assert_eq!((c.iou_thresh, c.max_lost_s, c.max_tracks), (0.4, 2.0, 64));
        assert!(TrackerConfig::from_toml("max_tracks = 129", TrackerConfig::sort()).is_err());
        let e = TrackerConfig::from_toml("iou_thresh = 1.5", TrackerConfig::sort()).expect_err("range");
        assert!(e.to_string().contains("iou_thresh"), "{e}");
    }
}
