//! Sections of the pipeline stages: `[detector]`, `[depth]`, `[tracker]`, `[postprocess]`, `[motion]`.
//!
//! **Integration point.** These are the daemon's placeholders, kept small and isolated on purpose:
//! the stage modules define their own serde sections (`infer::{DetectorConfig, DepthConfig,
//! ScheduleConfig, RuntimeConfig}`, `track::TrackerConfig`, `motion::MotionConfig`, the
//! post-processing config). At integration, replace the field types in [`super::Config`] with
//! theirs, call their `validate` from [`super::Config::validate`] (mapping the key they name to a
//! line with [`super::find_key_line`]) and update `config/fme.toml`. The daemon itself reads only
//! `motion.smoothing_s` and `motion.body_length_m` (for the stand-in pipeline).

use serde::Deserialize;
use std::path::PathBuf;


