//! Fixed-capacity multi-object tracker: constant-velocity Kalman filter and optimal assignment.
//!
//! Tracking-by-detection as in the paper's section 4.2 (detector + Kalman filter, thresholds found
//! by grid search, Tables 1 to 3), built so that a small board can run it on every camera frame:
//! capacities are constants ([`MAX_TRACKS`] tracks, [`MAX_DETS`] detections per frame), all memory
//! is reserved when the [`Tracker`] is created, and `predict`/`update` never allocate.
//!
//! ```
//! use fme_core::geometry::PixelBox;
//! use fme_core::track::{Detection, Tracker, TrackerConfig};
//! use fme_core::units::Seconds;
//! let mut tracker = Tracker::new(TrackerConfig::default_preset());
//! for k in 0..5 {
//!     let det = Detection::new(PixelBox::new(10.0 + 2.0 * k as f64, 20.0, 30.0, 15.0), 0.9);
//!     tracker.update(Seconds(k as f64 / 30.0), &[det]).expect("increasing time");
//! }
//! let out = tracker.outputs();
//! assert_eq!(out.len(), 1);
//! assert_eq!(out[0].id, 1);
//! ```
//!
//! # Presets
//! - `sort` ([`TrackerConfig::sort`]) reproduces SORT (abewley/sort) exactly: state
//!   `[cx, cy, area, aspect]` with its Q/R/P constants ([`kalman::SortKalman`]), one IoU stage over
//!   all detections (a direct match when every row and column has at most one IoU above the
//!   threshold, optimal assignment otherwise), `max_age = 1`, `min_hits = 3`, IoU 0.3, and its output
//!   rule `time_since_update < 1 and (hit_streak >= min_hits or frame_count <= min_hits)`.
//! - `default` ([`TrackerConfig::default_preset`]) is ByteTrack-style: a constant-velocity filter in
//!   real time ([`kalman::CvKalman`], `dt` from frame timestamps, so detection may run every k-th
//!   frame), three association stages (confirmed and lost tracks with high-score detections; tracked
//!   tracks with low-score detections, since occluded fish score low; tentative tracks with the
//!   remaining high-score detections), confirmation after `min_hits` hits, lost tracks kept for
//!   `max_age_s` seconds and recovered, optional depth term in the cost (`depth_weight`).
//!
//! # The paper's Table 1 as configuration keys
//! | paper | symbol | key | meaning here |
//! |---|---|---|---|
//! | Detection Thres | `T_d` | `det_threshold` | detections below are dropped |
//! | Tracking Thres | `T_t` | `track_threshold` | high/low score split of the two-stage association |
//! | Untracked Thres | `T_unt` | `new_track_threshold` | minimum score of an unmatched detection to start a track |
//! | Unconfirmed Thres | `T_unc` | `unconfirmed_iou_threshold` | minimum IoU to extend a tentative track |
//! | IoU Thres | `T_iou` | `iou_threshold` | minimum IoU in the first stage |
//! | Kernel Size `k`, Fusion Thres `T_f` | | - | HRNet heat-map settings of the detector, not tracker ones |
//!
//! The paper's chosen values for its Faster R-CNN tracker (Table 2: `T_d` 50%, `T_t` 50%, `T_unt`
//! 70%, `T_unc` 40%, `T_iou` 50%) are a point of the `fme tune` grid.

pub mod config;
pub mod kalman;
mod tracker;

pub use config::{Mode, TrackerConfig, TrackerConfigError, TrackerPreset};
pub use tracker::{Detection, MAX_DETS, MAX_TRACKS, Track, TrackError, Tracker, TrackerStats};
