//! # fme: fish motion estimation for an underwater camera box
//!
//! The binary's library: the command line ([`cli`]) over three crates, re-exported here so the
//! integration tests and benchmarks name every module as `fme::<module>`:
//!
//! - `fme-core`: the pure pipeline (units, geometry, infer, track, metric, postprocess, motion,
//!   familiarity, pipeline, the calibration solver);
//! - `fme-edge`: the configuration file, capture, outputs, console, history, black box, daemon;
//! - `fme-lab`: synthetic data, scoring, the tracker's tuning (`fme::calib` and `fme::rng` come
//!   through it from `fme-core`).
//!
//! The layers and their rules: docs/pipeline.md#layers.

#![warn(missing_docs)]

pub use fme_core::{
    assign, choice, detection, familiarity, geometry, infer, metric, motion, pipeline, postprocess, track, units,
};
pub use fme_edge::{
    backoff, calibration, capture, civil, config, console, draw, history, output, record, sequence, service, status,
    web,
};
pub use fme_lab::{calib, eval, mot, rng, synth, tune};

pub mod cli;
