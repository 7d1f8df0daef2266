//! World positions, per-fish 3D speed and the swarm activity index (paper section 3.3, eq. 5).
//!
//! [`ActivityEstimator`] is the per-frame API the daemon and `fme eval` call: give it the frame's
//! timestamp and the tracked boxes (with depth, or a function that samples depth at the corrected box
//! centre) and it returns an [`SwarmEstimate`]: the swarm's mean 3D speed (eq. 5), the number of
//! fish, a 95% interval of the mean, an EWMA-smoothed value and the mean speed in body lengths/s.
//!
//! Per track it runs the post-processing of [`crate::postprocess`], lifts the corrected box centre
//! with the corrected depth into the camera frame through [`crate::geometry::Camera`] (speeds are the
//! same in the world frame; positions are reported there), and computes the speed over the span from
//! real timestamps: with [`AlongRay::Depth`] the paper's `v = |P_t - P_ref| / (t - t_ref)`, with
//! [`AlongRay::Heading`] (the default, [`heading`]) the speed across the image over the box's
//! foreshortening. All per-track state is fixed-size and the track table is allocated once, at
//! construction: steady-state updates never touch the heap.

mod config;
mod estimator;
pub mod heading;
mod span;
mod stats;

pub use config::{MotionConfig, SpeedMethod};
pub use estimator::{ActivityEstimator, Fish, MAX_FISH, Observation, SwarmEstimate};
pub use heading::AlongRay;
pub use stats::{mean_ci95, student_t975};
