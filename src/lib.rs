//! # fme: fish motion estimation for an underwater camera box
//!
//! A pure, allocation-free core that turns timestamped frames into a swarm activity index, with I/O
//! adapters at the edges. The stages follow the paper "Fish Motion Estimation Using ML-based Relative
//! Depth Estimation and Multi-Object Tracking" (Fang et al.), one module per stage:
//!
//! | module | stage | paper |
//! |---|---|---|
//! | [`geometry`], [`units`] | pixel / camera / world frames, metres, seconds, m/s | sec. 3.1, Fig. 2 |
//! | [`calib`] | camera pose (and intrinsics) from measured reference objects: `fme calibrate` | eq. 1-2 |
//! | [`sequence`] | MOTChallenge sequences with fme's ground-truth extras | sec. 4.1 |
//! | [`synth`] | synthetic underwater scenes with exact ground truth | sec. 4.1, 4.4 |
//! | [`infer`] | ONNX detector and relative-depth networks, reduced-rate scheduling | sec. 4.2, 4.3 |
//! | [`track`] | Kalman tracking-by-detection | sec. 4.2 |
//! | [`metric`] | relative inverse depth to metres from reference objects | eq. 1-2 |
//! | [`postprocess`] | box-fluctuation and depth-jump detectors with EWMA | eq. 3-4 |
//! | [`motion`] | world positions, per-fish 3D speed, swarm mean (activity index) | sec. 3.3, eq. 5 |
//! | [`familiarity`] | "detections look unlike fish": the detector out of its training range | - |
//! | [`pipeline`] | the stages chained on frame time; what every command runs | eq. 1-5 |
//! | [`eval`], [`mot`] | speed, depth and tracking metrics against ground truth | sec. 4.5 |
//! | [`config`], [`status`] | the one configuration; health and fault codes shared by the edges | - |
//! | [`capture`], [`output`], [`console`], [`service`] | the edge daemon | - |
//! | [`history`] | a daily CSV row per output update, hourly summaries, day plots | - |
//!
//! Shared low-level pieces with no stage of their own: [`assign`] (the optimal assignment solver of
//! the tracker and the MOT metrics), [`detection`] (what the detector produces and the tracker
//! consumes) and [`rng`] (the seeded generator of all synthetic data).

#![warn(missing_docs)]

pub mod assign;
pub mod backoff;
pub mod calib;
pub mod capture;
pub mod civil;
pub mod cli;
pub mod config;
pub mod console;
pub mod detection;
pub mod draw;
pub mod eval;
pub mod familiarity;
pub mod geometry;
pub mod history;
pub mod infer;
pub mod metric;
pub mod mot;
pub mod motion;
pub mod output;
pub mod pipeline;
pub mod postprocess;
pub mod record;
pub mod rng;
pub mod sequence;
pub mod service;
pub mod status;
pub mod synth;
pub mod track;
pub mod units;
