//! Pinhole intrinsics with OpenCV's Brown-Conrady distortion, and the full camera.

use super::{CameraPoint, GeometryError, Pixel, Pose, WorldPoint};
use crate::units::Metres;
use nalgebra::Vector3;

/// Pinhole intrinsics in pixels plus distortion `[k1, k2, p1, p2, k3]` (OpenCV order).
///
/// Pixel centres sit at integer + 0.5 coordinates: the principal point of a `W x H` image without
/// offset is `(W/2, H/2)`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u, pixels.
    pub cx: f64,
    /// Principal point v, pixels.
    pub cy: f64,
    /// Radial/tangential distortion `[k1, k2, p1, p2, k3]`.
    #[serde(default)]
    pub distortion: [f64; 5],
}

impl Intrinsics {
    /// Intrinsics from the horizontal field of view (degrees), square pixels, centred principal point.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Result<Self, GeometryError> {
        if width == 0 || height == 0 {
            return Err(GeometryError::BadIntrinsics("image size must be positive"));
        }
        if !hfov_deg.is_finite() || hfov_deg <= 1.0 || hfov_deg >= 179.0 {
            return Err(GeometryError::BadIntrinsics("horizontal field of view must be within (1, 179) degrees"));
        }
        let f = (width as f64 * 0.5) / (hfov_deg.to_radians() * 0.5).tan();
        Ok(Self { fx: f, fy: f, cx: width as f64 * 0.5, cy: height as f64 * 0.5, distortion: [0.0; 5] })
    }

    /// Checks the values can describe a camera.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let all = [self.fx, self.fy, self.cx, self.cy];
        if !all.iter().chain(self.distortion.iter()).all(|v| v.is_finite()) {
            return Err(GeometryError::BadIntrinsics("non-finite value"));
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(GeometryError::BadIntrinsics("focal lengths must be positive"));
        }
        Ok(())
    }

    /// True when any distortion coefficient is non-zero.
    #[inline]
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|&k| k != 0.0)
    }

    /// Applies distortion to normalised image coordinates (x/z, y/z).
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (xd, yd)
    }

    /// Removes distortion from normalised coordinates by fixed-point iteration (as OpenCV's
    /// `undistortPoints`), accurate to well below a hundredth of a pixel for moderate distortion.
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if !self.has_distortion() {
            return (xd, yd);
        }
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            let nx = (xd - dx) / radial;
            let ny = (yd - dy) / radial;
            let done = (nx - x).abs() < 1e-12 && (ny - y).abs() < 1e-12;
            x = nx;
            y = ny;
            if done {
                break;
            }
        }
        (x, y)
    }

    /// Camera point to pixel (with distortion). Fails for points at or behind the camera plane.
    #[inline]
    pub fn project(&self, p: &CameraPoint) -> Result<Pixel, GeometryError> {
        let z = p.0.z;
        // NaN fails this test too, so it is rejected with the points behind the camera.
        if z.is_nan() || z <= 1e-9 {
            return Err(GeometryError::BehindCamera(z));
        }
        let (x, y) = self.distort(p.0.x / z, p.0.y / z);
        Ok(Pixel::new(self.fx * x + self.cx, self.fy * y + self.cy))
    }

    /// Pixel plus depth (camera z) to a camera point: the inverse of [`Intrinsics::project`].
    #[inline]
    pub fn unproject(&self, px: Pixel, depth: Metres) -> Result<CameraPoint, GeometryError> {
        let d = depth.get();
        if !d.is_finite() || d <= 0.0 {
            return Err(GeometryError::BadDepth(d));
        }
        let (x, y) = self.undistort((px.u - self.cx) / self.fx, (px.v - self.cy) / self.fy);
        Ok(CameraPoint(Vector3::new(x * d, y * d, d)))
    }

    /// Unit-depth ray direction (x/z, y/z, 1) through a pixel, in the camera frame.
    #[inline]
    pub fn ray(&self, px: Pixel) -> Vector3<f64> {
        let (x, y) = self.undistort((px.u - self.cx) / self.fx, (px.v - self.cy) / self.fy);
        Vector3::new(x, y, 1.0)
    }
}

/// A calibrated camera: intrinsics plus world-to-camera pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Pinhole model and distortion.
    pub intrinsics: Intrinsics,
    /// World-to-camera transform.
    pub pose: Pose,
}

impl Camera {
    /// World point to pixel.
    #[inline]
    pub fn world_to_pixel(&self, p: &WorldPoint) -> Result<Pixel, GeometryError> {
        self.intrinsics.project(&self.pose.to_camera(p))
    }

    /// Pixel and depth (camera z, metres) to a world point.
    #[inline]
    pub fn pixel_to_world(&self, px: Pixel, depth: Metres) -> Result<WorldPoint, GeometryError> {
        Ok(self.pose.to_world(&self.intrinsics.unproject(px, depth)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(distortion: [f64; 5]) -> Camera {
        let mut k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        k.distortion = distortion;
        let pose =
            Pose::look_at(WorldPoint::new(3.0, -0.5, 1.5), WorldPoint::new(3.0, 3.0, 1.2), Vector3::z()).unwrap();
        Camera { intrinsics: k, pose }
    }

    #[test]
    fn hfov_gives_expected_focal_length() {
        let k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        assert!((k.fx - 320.0).abs() < 1e-9);
        assert_eq!((k.cx, k.cy), (320.0, 192.0));
        assert!(Intrinsics::from_hfov(0, 10, 60.0).is_err());
        assert!(Intrinsics::from_hfov(10, 10, 180.0).is_err());
    }

    #[test]
    fn world_pixel_round_trip_with_and_without_distortion() {
        for dist in [[0.0; 5], [-0.12, 0.03, 0.001, -0.0005, 0.0]] {
            let c = cam(dist);
            for p in [WorldPoint::new(3.2, 2.0, 0.8), WorldPoint::new(1.9, 3.5, 2.2), WorldPoint::new(4.0, 1.0, 1.5)] {
                let px = c.world_to_pixel(&p).unwrap();
                let depth = c.pose.to_camera(&p).depth();
                let back = c.pixel_to_world(px, depth).unwrap();
                assert!((back.0 - p.0).norm() < 1e-8, "{dist:?}: {p:?} -> {px:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn rejects_points_behind_and_bad_depth() {
        let k = Intrinsics::from_hfov(640, 384, 60.0).unwrap();
        assert!(matches!(k.project(&CameraPoint::new(0.0, 0.0, -1.0)), Err(GeometryError::BehindCamera(_))));
        assert!(matches!(k.unproject(Pixel::new(1.0, 1.0), Metres(f64::NAN)), Err(GeometryError::BadDepth(_))));
        assert!(matches!(k.unproject(Pixel::new(1.0, 1.0), Metres(0.0)), Err(GeometryError::BadDepth(_))));
    }
}
