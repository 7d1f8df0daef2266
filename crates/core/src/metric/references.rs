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

    /// Leaves out the first `n` references from now on (hidden or fouled beyond use).
    pub fn drop_first(&mut self, n: usize) {
        let keep: heapless::Vec<(Pixel, Metres), MAX_REFERENCES> = self.points.iter().skip(n).copied().collect();
        self.points = keep;
    }

    /// Makes the recorded depth of the first `n` references wrong from now on, each by its own
    /// factor between 0.7 and 1.3 (deterministic): as if they moved with the net, or a fouled cube
    /// were read where it no longer is. For testing the fits (`fme eval --move-refs`).
    pub fn misplace_first(&mut self, n: usize) {
        for (k, p) in self.points.iter_mut().take(n).enumerate() {
            // Golden-ratio steps spread the factors over the range without repeating.
            let u = ((k as f64 + 1.0) * 0.618_033_988_75).fract();
            p.1 = Metres(p.1.0 * (0.7 + 0.6 * u));
        }
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

/// The image footprints of the reference objects (axis-aligned cubes), for telling the detector's
/// false positives on them from fish: a reference cube looks enough like a small fish to be detected.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReferenceFootprints {
    boxes: heapless::Vec<crate::geometry::PixelBox, MAX_REFERENCES>,
}

impl ReferenceFootprints {
    /// The bounding box of each cube's eight projected corners (cubes behind the camera are left out).
    pub fn project(camera: &Camera, cubes: impl IntoIterator<Item = (WorldPoint, Metres)>) -> Self {
        let mut out = Self::default();
        for (c, size) in cubes {
            let h = 0.5 * size.0;
            let (mut u0, mut v0, mut u1, mut v1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
            let mut ok = true;
            for k in 0..8 {
                let d = |bit: usize| if k & bit == 0 { -h } else { h };
                let p = WorldPoint::new(c.0.x + d(1), c.0.y + d(2), c.0.z + d(4));
                match camera.world_to_pixel(&p) {
                    Ok(px) => {
                        (u0, v0, u1, v1) = (u0.min(px.u), v0.min(px.v), u1.max(px.u), v1.max(px.v));
                    }
                    Err(_) => ok = false,
                }
            }
            if ok && out.boxes.push(crate::geometry::PixelBox::new(u0, v0, u1 - u0, v1 - v0)).is_err() {
                break;
            }
        }
        out
    }

    /// Whether a detection is most likely a reference cube: its centre lies within a cube's
    /// footprint widened by one footprint on every side, and it is at most four times the footprint's
    /// area (a fish passing in front of a cube is nearer, so larger, and is kept).
    pub fn covers(&self, det: &crate::geometry::PixelBox) -> bool {
        let c = det.center();
        self.boxes.iter().any(|r| {
            c.u >= r.x - r.w
                && c.u <= r.x + 2.0 * r.w
                && c.v >= r.y - r.h
                && c.v <= r.y + 2.0 * r.h
                && det.area() <= 4.0 * r.area()
        })
    }

    /// Number of footprints.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
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
        // A 0.1 m cube 2 m ahead: about 0.1 * 320 / 2 = 16 px wide at the image centre.
        let f = ReferenceFootprints::project(&camera, [(WorldPoint::new(0.0, 0.0, 2.0), Metres(0.1))]);
        assert_eq!(f.len(), 1);
        assert!(f.covers(&crate::geometry::PixelBox::new(312.0, 184.0, 16.0, 16.0)), "the cube itself");
        assert!(!f.covers(&crate::geometry::PixelBox::new(270.0, 170.0, 100.0, 40.0)), "a near fish in front of it");
        assert!(!f.covers(&crate::geometry::PixelBox::new(100.0, 100.0, 16.0, 16.0)), "elsewhere");
    }

    #[test]
    fn misplaced_references_are_each_off_by_their_own_factor() {
        let camera = Camera {
            intrinsics: Intrinsics::from_hfov(640, 384, 90.0).unwrap(),
            pose: Pose::new(Matrix3::identity(), Vector3::zeros()).unwrap(),
        };
        let pts = (0..5).map(|i| WorldPoint::new(0.1 * f64::from(i), 0.0, 2.0));
        let mut r = ReferencePoints::project(&camera, pts, 640, 384);
        r.misplace_first(3);
        let d: Vec<f64> = r.iter().map(|(_, d)| d.0 / 2.0).collect();
        assert!(d[..3].iter().all(|k| (0.7..=1.3).contains(k) && (k - 1.0).abs() > 0.01), "{d:?}");
        assert!(d[0] != d[1] && d[1] != d[2], "{d:?}");
        assert_eq!(&d[3..], &[1.0, 1.0]);
    }
}
