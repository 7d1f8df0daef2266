//! # fme-core: frames in, activity out
//!
//! The pure core of fme: it turns timestamped frames into a swarm activity index, with no I/O but
//! the model files and no async runtime or argument parser. The stages follow the paper "Fish
//! Motion Estimation Using ML-based Relative Depth Estimation and Multi-Object Tracking" (Fang et
//! al.), one module per stage:
//!
//! | module | stage | paper |
//! |---|---|---|
//! | [`geometry`], [`units`] | pixel / camera / world frames, metres, seconds, m/s | sec. 3.1, Fig. 2 |
//! | [`infer`] | ONNX detector and relative-depth networks, reduced-rate scheduling | sec. 4.2, 4.3 |
//! | [`track`] | Kalman tracking-by-detection | sec. 4.2 |
//! | [`metric`] | relative inverse depth to metres from reference objects or the fish | eq. 1-2 |
//! | [`postprocess`] | box-fluctuation and depth-jump detectors with EWMA | eq. 3-4 |
//! | [`motion`] | world positions, per-fish 3D speed, swarm mean (activity index) | sec. 3.3, eq. 5 |
//! | [`familiarity`] | "detections look unlike fish": the detector out of its training range | - |
//! | [`pipeline`] | the stages chained on frame time; what every command runs | eq. 1-5 |
//! | [`calib`] | camera pose (and intrinsics) from measured reference objects (`fme calibrate`, the web page) | eq. 1-2 |
//!
//! Shared low-level pieces with no stage of their own: [`assign`] (the optimal assignment solver of
//! the tracker and the MOT metrics), [`detection`] (what the detector produces and the tracker
//! consumes), [`choice`] (the named options of the config file) and [`rng`] (the seeded generator).
//!
//! The layers above: `fme-edge` (config file, capture, outputs, daemon), `fme-lab` (synthetic data,
//! scoring) and the `fme` binary; docs/pipeline.md#layers.

#![warn(missing_docs)]

pub mod assign;
pub mod calib;
pub mod choice;
pub mod detection;
pub mod familiarity;
pub mod geometry;
pub mod infer;
pub mod metric;
pub mod motion;
pub mod pipeline;
pub mod postprocess;
pub mod rng;
pub mod track;
pub mod units;

/// The repository checkout this crate was built from: `models/`, `.ort/` and the test data live at
/// its top (a development build looks for ONNX Runtime there).
pub const REPO_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");
