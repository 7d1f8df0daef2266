//! Reference objects as a fixed camera sees them: the pixel where each is sampled and its known
//! depth (the inputs of the paper's eq. 1).

use super::{MAX_REFERENCES, ReferencePair, References};
use crate::geometry::{Camera, Pixel, WorldPoint};
use crate::units::Metres;

/// The reference objects visible to a fixed camera, projected once: pixel and true depth (camera z).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReferencePoints {
    points: heapless::Vec<(Pixel, Metres), MAX_REFERENCES>,
}

impl ReferencePoints {
    /// Projects world points (the surfaces a depth map sees, e.g. the camera-facing face centres)
    /// into a `width x height` image; points behind the camera or outside the image are left out,
    /// as are any beyond [`MAX_REFERENCES`].
    pub fn project(camera: &Camera, points: impl IntoIterator<Item = WorldPoint>, width: u32, height: u32) -> Self {
        let mut out = Self::default();
        for p in points {
            let Ok(px) = camera.world_to_pixel(&p) else { continue };
            let depth = camera.pose.to_camera(&p).depth();
            let inside = px.u >= 0.0 && px.v >= 0.0 && px.u < f64::from(width) && px.v < f64::from(height);
            if inside && depth.0 > 0.0 && out.points.push((px, depth)).is_err() {
                break;
            }
        }
        out
    }

    /// Number of visible references.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether no reference is visible.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Pixel and true depth of each visible reference.
    pub fn iter(&self) -> impl Iterator<Item = (Pixel, Metres)> + '_ {
        self.points.iter().copied()
    }

    /// The pairs for a fit: `sample(pixel)` returns the relative inverse depth there (`None`:
    /// hidden or off the map, left out).
    pub fn pairs(&self, mut sample: impl FnMut(Pixel) -> Option<f64>) -> References {
        let mut refs = References::new();
        for &(px, depth) in &self.points {
            if let Some(relative) = sample(px).filter(|r| r.is_finite()) {
                let _ = refs.push(ReferencePair { relative, depth });
            }
        }
        refs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use nalgebra::{Matrix3, Vector3};

    #[test]
    fn projects_visible_points_and_drops_the_rest() {
        let camera = Camera {
            intrinsics: Intrinsics::from_hfov(640, 384, 90.0).unwrap(),
            pose: Pose::new(Matrix3::identity(), Vector3::zeros()).unwrap(),
        };
        // Camera frame = world frame here (identity pose): z forward.
        let pts = [WorldPoint::new(0.0, 0.0, 2.0), WorldPoint::new(0.0, 0.0, -2.0), WorldPoint::new(50.0, 0.0, 1.0)];
        let r = ReferencePoints::project(&camera, pts, 640, 384);
        assert_eq!(r.len(), 1);
        let (px, d) = r.iter().next().unwrap();
        assert!((px.u - 320.0).abs() < 1e-9 && (px.v - 192.0).abs() < 1e-9);
        assert!((d.0 - 2.0).abs() < 1e-12);
        let pairs = r.pairs(|_| Some(0.5));
        assert_eq!(pairs.len(), 1);
        assert!(r.pairs(|_| None).is_empty());
        assert!(r.pairs(|_| Some(f64::NAN)).is_empty());
    }
}
