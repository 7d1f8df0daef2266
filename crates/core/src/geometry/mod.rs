//! Coordinate frames and the camera model.
//!
//! Three frames, three types, no implicit conversion between them:
//! - [`Pixel`]: image plane, `u` right, `v` down, origin at the top-left corner of the top-left pixel.
//! - [`CameraPoint`]: OpenCV camera frame in metres, x right, y down, z forward. Depth is `z`, not the
//!   ray length.
//! - [`WorldPoint`]: right-handed world frame in metres, z up.
//!
//! [`Intrinsics`] maps camera <-> pixel (pinhole with Brown-Conrady distortion, as OpenCV), [`Pose`]
//! maps world <-> camera (`p_cam = R * p_world + t`), and [`Camera`] combines them. These implement the
//! PCS/CCS/WCS conversions of the paper (section 3.1, Fig. 2).

mod angles;
mod bbox;
mod camera;
mod points;
mod pose;

pub use angles::{angle_between, apparent_length};
pub use bbox::PixelBox;
pub use camera::{Camera, Intrinsics};
pub use points::{CameraPoint, Pixel, WorldPoint};
pub use pose::Pose;

/// Errors of the camera model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A point at or behind the camera plane cannot be projected.
    #[error("point is behind the camera (z = {0} m)")]
    BehindCamera(f64),
    /// Depth must be positive and finite to lift a pixel into 3D.
    #[error("depth must be positive and finite, got {0}")]
    BadDepth(f64),
    /// Intrinsics that cannot describe a camera.
    #[error("invalid intrinsics: {0}")]
    BadIntrinsics(&'static str),
    /// A rotation matrix that is not orthonormal with determinant +1.
    #[error("rotation is not a proper rotation matrix (|R^T R - I| = {0:.3e}, det = {1:.6})")]
    BadRotation(f64, f64),
}
