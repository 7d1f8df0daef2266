//! Exact amodal screen boxes: of an ellipsoid (closed form, or sampled under lens distortion), of a
//! flat fin and of a whole posed fish.

use super::NEAR;
use crate::synth::fish::{Ellipsoid, FishShape};
use fme_core::geometry::{Camera, PixelBox};
use nalgebra::{Matrix3, Vector3};

/// Exact screen box of an ellipsoid under a pinhole camera (Sigg et al. 2006): with `T = K [M | c]`
/// mapping the unit sphere to the image, `u_c = <r0, r2> / <r2, r2>` and
/// `half = sqrt(u_c^2 - <r0, r0> / <r2, r2>)` in the Minkowski product `diag(1, 1, 1, -1)`.
///
/// With lens distortion the silhouette is no longer an ellipse: the box is then taken over 256
/// points of the contour generator (the circle where rays from the camera touch the unit sphere),
/// distorted and projected; the sampling error is below 1e-4 of the silhouette size.
pub fn ellipsoid_box(camera: &Camera, e: &Ellipsoid) -> Option<PixelBox> {
    if camera.intrinsics.has_distortion() {
        return distorted_ellipsoid_box(camera, e);
    }
    let k = &camera.intrinsics;
    let r = camera.pose.rotation;
    let c = camera.pose.to_camera(&fme_core::geometry::WorldPoint(e.center)).0;
    if c.z - e.radii.max() <= NEAR {
        return None;
    }
    let m = r * e.axes * Matrix3::from_diagonal(&e.radii);
    let row = |i: usize| -> [f64; 4] {
        let kk = match i {
            0 => [k.fx, 0.0, k.cx],
            1 => [0.0, k.fy, k.cy],
            _ => [0.0, 0.0, 1.0],
        };
        let mut out = [0.0; 4];
        for j in 0..3 {
            out[j] = kk[0] * m[(0, j)] + kk[1] * m[(1, j)] + kk[2] * m[(2, j)];
        }
        out[3] = kk[0] * c.x + kk[1] * c.y + kk[2] * c.z;
        out
    };
    let dot = |a: &[f64; 4], b: &[f64; 4]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - a[3] * b[3];
    let (r0, r1, r2) = (row(0), row(1), row(2));
    let d = dot(&r2, &r2);
    let uc = dot(&r0, &r2) / d;
    let vc = dot(&r1, &r2) / d;
    let hu = (uc * uc - dot(&r0, &r0) / d).max(0.0).sqrt();
    let hv = (vc * vc - dot(&r1, &r1) / d).max(0.0).sqrt();
    Some(PixelBox::new(uc - hu, vc - hv, 2.0 * hu, 2.0 * hv))
}

fn distorted_ellipsoid_box(camera: &Camera, e: &Ellipsoid) -> Option<PixelBox> {
    let c = camera.pose.to_camera(&fme_core::geometry::WorldPoint(e.center)).0;
    if c.z - e.radii.max() <= NEAR {
        return None;
    }
    // Unit-sphere space of the ellipsoid: s = diag(1/r) A^T (p - centre), A its world axes.
    let eye = camera.pose.camera_center().0;
    let o = (e.axes.transpose() * (eye - e.center)).component_div(&e.radii);
    let d = o.norm();
    if d <= 1.0 {
        return None;
    }
    let n = o / d;
    let (ca, sa) = (1.0 / d, (1.0 - 1.0 / (d * d)).sqrt());
    let a = n.cross(&if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() }).normalize();
    let b = n.cross(&a);
    let mut bx = None;
    for k in 0..256 {
        let th = f64::from(k) / 256.0 * std::f64::consts::TAU;
        let s = n * ca + (a * th.cos() + b * th.sin()) * sa;
        let p = e.center + e.axes * s.component_mul(&e.radii);
        let px = camera.world_to_pixel(&fme_core::geometry::WorldPoint(p)).ok()?;
        bx = Some(union(bx, PixelBox::new(px.u, px.v, 0.0, 0.0)));
    }
    bx
}

/// Box of a flat triangle; with distortion its edges bend, so they are sampled.
pub(super) fn triangle_box(camera: &Camera, v: &[Vector3<f64>; 3]) -> Option<PixelBox> {
    let steps = if camera.intrinsics.has_distortion() { 16 } else { 1 };
    let mut b = None;
    for k in 0..3 {
        let (p, q) = (v[k], v[(k + 1) % 3]);
        for s in 0..steps {
            let x = p + (q - p) * (f64::from(s) / f64::from(steps));
            let cp = camera.pose.to_camera(&fme_core::geometry::WorldPoint(x));
            if cp.0.z <= NEAR {
                return None;
            }
            let px = camera.intrinsics.project(&cp).ok()?;
            b = Some(union(b, PixelBox::new(px.u, px.v, 0.0, 0.0)));
        }
    }
    b
}

fn union(a: Option<PixelBox>, b: PixelBox) -> PixelBox {
    match a {
        None => b,
        Some(a) => {
            let (x0, y0) = (a.x.min(b.x), a.y.min(b.y));
            PixelBox::new(x0, y0, a.right().max(b.right()) - x0, a.bottom().max(b.bottom()) - y0)
        }
    }
}

/// Amodal box of a posed fish: the union of its parts' exact boxes and its fins' corners.
/// `None` when any part is at or behind the camera plane.
pub fn fish_box(camera: &Camera, shape: &FishShape) -> Option<PixelBox> {
    let mut b = None;
    for e in &shape.parts {
        b = Some(union(b, ellipsoid_box(camera, e)?));
    }
    for t in &shape.fins {
        b = Some(union(b, triangle_box(camera, &t.v)?));
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use fme_core::geometry::{Intrinsics, Pose, WorldPoint};

    #[test]
    fn exact_ellipsoid_box_matches_dense_surface_sampling() {
        let camera = Camera {
            intrinsics: Intrinsics::from_hfov(640, 384, 100.0).unwrap(),
            pose: Pose::look_at(WorldPoint::new(3.0, 0.05, 1.5), WorldPoint::new(3.0, 4.0, 0.5), Vector3::z()).unwrap(),
        };
        let axes = *nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1).matrix();
        let e = Ellipsoid { center: Vector3::new(2.2, 1.6, 1.1), axes, radii: Vector3::new(0.15, 0.03, 0.05) };
        let b = ellipsoid_box(&camera, &e).unwrap();
        let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        let n = 400;
        for a in 0..n {
            for k in 0..=n / 2 {
                let (th, ph) =
                    (a as f64 / n as f64 * std::f64::consts::TAU, k as f64 / (n / 2) as f64 * std::f64::consts::PI);
                let s = Vector3::new(ph.sin() * th.cos(), ph.sin() * th.sin(), ph.cos());
                let p = e.center + e.axes * s.component_mul(&e.radii);
                let px = camera.world_to_pixel(&WorldPoint(p)).unwrap();
                (u0, u1, v0, v1) = (u0.min(px.u), u1.max(px.u), v0.min(px.v), v1.max(px.v));
            }
        }
        for (got, want) in [(b.x, u0), (b.right(), u1), (b.y, v0), (b.bottom(), v1)] {
            assert!((got - want).abs() < 0.02, "box {b:?} vs sampled {u0} {u1} {v0} {v1}");
        }
    }
}
