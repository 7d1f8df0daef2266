//! # fme-lab: measuring the pipeline
//!
//! The offline tools: synthetic scenes with exact ground truth, tracking and speed scores against
//! it, and the tracker's parameter search. Built on the
//! core's pipeline and the edge's sequence format and configuration, so what `fme eval` scores is
//! what the PLC receives.
//!
//! | module | job | paper |
//! |---|---|---|
//! | [`synth`] | synthetic underwater scenes with exact ground truth | sec. 4.1, 4.4 |
//! | [`eval`] | speed, depth and tracking scores of the pipeline against ground truth | sec. 4.5 |
//! | [`mot`] | MOTChallenge tracking metrics (CLEAR MOT, IDF1, HOTA) | sec. 4.5 |
//! | [`calib`] | camera pose (and intrinsics) from measured reference objects (lives in `fme_core::calib`: the web page's Calibrate solves with it too) | eq. 1-2 |
//! | [`tune`] | the tracker's parameters scored on synthetic detections (`fme tune`) | - |
//! | [`rng`] | the seeded generator of all synthetic data (`fme_core::rng`: the calibration solver draws from it) | - |

#![warn(missing_docs)]

pub use fme_core::calib;
pub mod eval;
pub mod mot;
pub use fme_core::rng;
pub mod synth;
pub mod tune;
