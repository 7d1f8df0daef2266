//! Multi-object tracking metrics (MOTA, MOTP, IDF1, ID switches) with MOTChallenge devkit conventions.
//!
//! [`io`] reads and writes MOTChallenge text files with errors that name file and line;
//! [`metrics`] accumulates frames and computes the CLEAR MOT and identity metrics exactly as
//! py-motmetrics 1.4.0 does (checked by `scripts/check_motmetrics.py`).

pub mod hota;
pub mod metrics;

pub use hota::{Hota, HotaAccumulator};

pub use metrics::{MotAccumulator, MotMetrics};
