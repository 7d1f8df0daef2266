//! Camera extrinsics: the rigid transform from the world frame to the camera frame.

use super::{CameraPoint, GeometryError, WorldPoint};
use nalgebra::{Matrix3, Vector3};

/// World-to-camera transform, `p_cam = rotation * p_world + translation` (the convention of
/// `meta.json`'s `camera.world_to_camera`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation from world axes to camera axes (proper orthonormal).
    pub rotation: Matrix3<f64>,
    /// Translation in metres, expressed in the camera frame.
    pub translation: Vector3<f64>,
}

impl Pose {
    /// A pose from a rotation and translation; checks that the rotation is a proper rotation.
    pub fn new(rotation: Matrix3<f64>, translation: Vector3<f64>) -> Result<Self, GeometryError> {
        let ortho = (rotation.transpose() * rotation - Matrix3::identity()).norm();
        let det = rotation.determinant();
        if !ortho.is_finite() || ortho > 1e-6 || (det - 1.0).abs() > 1e-6 || !translation.iter().all(|c| c.is_finite())
        {
            return Err(GeometryError::BadRotation(ortho, det));
        }
        Ok(Self { rotation, translation })
    }

    /// The identity: camera and world frames coincide.
    pub fn identity() -> Self {
        Self { rotation: Matrix3::identity(), translation: Vector3::zeros() }
    }

    /// A camera at `eye` (world) looking at `target`, with the world's `up` direction appearing as
    /// "up" in the image (i.e. towards negative camera y).
    ///
    /// Returns `None` when `eye == target` or the view direction is parallel to `up`.
    pub fn look_at(eye: WorldPoint, target: WorldPoint, up: Vector3<f64>) -> Option<Self> {
        let z = (target.0 - eye.0).try_normalize(1e-12)?; // camera forward
        let x = z.cross(&up).try_normalize(1e-12)?; // camera right
        let y = z.cross(&x); // camera down
        // Rows of R are the camera axes expressed in world coordinates.
        let rotation = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let translation = -(rotation * eye.0);
        Some(Self { rotation, translation })
    }

    /// World point to camera frame.
    #[inline]
    pub fn to_camera(&self, p: &WorldPoint) -> CameraPoint {
        CameraPoint(self.rotation * p.0 + self.translation)
    }

    /// Camera point to world frame.
    #[inline]
    pub fn to_world(&self, p: &CameraPoint) -> WorldPoint {
        WorldPoint(self.rotation.transpose() * (p.0 - self.translation))
    }

    /// The camera's optical centre in world coordinates.
    #[inline]
    pub fn camera_center(&self) -> WorldPoint {
        WorldPoint(-(self.rotation.transpose() * self.translation))
    }

    /// Rotation as row-major 3x3 array (the `meta.json` layout).
    pub fn rotation_rows(&self) -> [[f64; 3]; 3] {
        let r = &self.rotation;
        [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]]
    }

    /// Builds a pose from the row-major `meta.json` layout.
    pub fn from_rows(rows: [[f64; 3]; 3], translation: [f64; 3]) -> Result<Self, GeometryError> {
        let r = Matrix3::from_fn(|i, j| rows[i][j]);
        Self::new(r, Vector3::from(translation))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_puts_target_on_optical_axis_and_up_at_negative_y() {
        let eye = WorldPoint::new(0.0, -3.0, 1.5);
        let target = WorldPoint::new(0.0, 0.0, 1.5);
        let pose = Pose::look_at(eye, target, Vector3::z()).unwrap();
        let c = pose.to_camera(&target);
        assert!(c.0.x.abs() < 1e-12 && c.0.y.abs() < 1e-12 && (c.0.z - 3.0).abs() < 1e-12);
        let above = pose.to_camera(&WorldPoint::new(0.0, 0.0, 2.5));
        assert!(above.0.y < 0.0, "world up must be image up (negative camera y)");
        let right = pose.to_camera(&WorldPoint::new(1.0, 0.0, 1.5));
        assert!(right.0.x > 0.0, "looking along +y with z up, +x world is to the right");
        let back = pose.to_world(&c);
        assert!((back.0 - target.0).norm() < 1e-12);
        assert!((pose.camera_center().0 - eye.0).norm() < 1e-12);
        let again = Pose::from_rows(pose.rotation_rows(), pose.translation.into()).unwrap();
        assert_eq!(again, pose);
    }

    #[test]
    fn rejects_non_rotations() {
        assert!(Pose::new(Matrix3::identity() * 2.0, Vector3::zeros()).is_err());
        let mirror = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        assert!(Pose::new(mirror, Vector3::zeros()).is_err());
    }
}
