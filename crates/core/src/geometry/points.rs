//! Point types of the three coordinate frames.

use crate::units::Metres;
use nalgebra::Vector3;

/// A position on the image plane in pixels (`u` right, `v` down, origin top-left).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Pixel {
    /// Horizontal coordinate, pixels, increasing to the right.
    pub u: f64,
    /// Vertical coordinate, pixels, increasing downwards.
    pub v: f64,
}

impl Pixel {
    /// A pixel position.
    #[inline]
    pub const fn new(u: f64, v: f64) -> Self {
        Self { u, v }
    }
    /// True when both coordinates are finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.u.is_finite() && self.v.is_finite()
    }
}

/// A point in the OpenCV camera frame, metres (x right, y down, z forward).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPoint(pub Vector3<f64>);

impl CameraPoint {
    /// A camera-frame point from its coordinates in metres.
    #[inline]
    pub fn new(x: f64, y: f64, z: f64) -> Self {
        Self(Vector3::new(x, y, z))
    }
    /// Depth as used throughout fme: the camera z coordinate (not the ray length).
    #[inline]
    pub fn depth(&self) -> Metres {
        Metres(self.0.z)
    }
    /// Distance from the optical centre (the ray length, used by the water model).
    #[inline]
    pub fn range(&self) -> Metres {
        Metres(self.0.norm())
    }
}

/// A point in the world frame, metres (right-handed, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldPoint(pub Vector3<f64>);

impl WorldPoint {
    /// A world-frame point from its coordinates in metres.
    #[inline]
    pub fn new(x: f64, y: f64, z: f64) -> Self {
        Self(Vector3::new(x, y, z))
    }
    /// Euclidean distance between two world points.
    #[inline]
    pub fn distance(&self, other: &WorldPoint) -> Metres {
        Metres((self.0 - other.0).norm())
    }
    /// True when all coordinates are finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.0.iter().all(|c| c.is_finite())
    }
}
