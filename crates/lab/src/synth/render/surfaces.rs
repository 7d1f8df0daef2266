//! Fish drawn into the frame: each part's ellipsoid and each fin's triangle ray-cast over its exact
//! box, z-tested against the pond and the other fish, coloured and lit by daylight and caustics.

use super::bounds::{ellipsoid_box, triangle_box};
use super::{FishPixels, FrameBuffers, NEAR, Renderer, mix3, smoothstep};
use crate::rng::mix;
use crate::synth::fish::{Ellipsoid, FishBody, Triangle};
use fme_core::geometry::PixelBox;
use nalgebra::{Matrix3, Vector3};

impl Renderer {
    fn pixel_range(&self, b: &PixelBox) -> Option<(usize, usize, usize, usize)> {
        let i0 = (b.x - 0.5).ceil().max(0.0);
        let i1 = (b.right() - 0.5).floor().min(f64::from(self.width) - 1.0);
        let j0 = (b.y - 0.5).ceil().max(0.0);
        let j1 = (b.bottom() - 0.5).floor().min(f64::from(self.height) - 1.0);
        if i0 > i1 || j0 > j1 {
            return None;
        }
        Some((i0 as usize, i1 as usize, j0 as usize, j1 as usize))
    }

    /// Z-tests one surface sample; counts alone/visible pixels.
    #[inline]
    fn plot(&self, idx: usize, id: u16, z: f64, buf: &mut FrameBuffers, out: &mut [FishPixels]) -> bool {
        if buf.stamp[idx] != id {
            buf.stamp[idx] = id;
            out[id as usize - 1].alone += 1;
        }
        if (z as f32) < buf.z[idx] {
            let old = buf.ids[idx];
            if old != id {
                out[id as usize - 1].visible += 1;
                if old != 0 {
                    out[old as usize - 1].visible -= 1;
                }
            }
            buf.z[idx] = z as f32;
            buf.ids[idx] = id;
            true
        } else {
            false
        }
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn draw_ellipsoid(
        &self,
        id: u16,
        body: &FishBody,
        e: &Ellipsoid,
        is_body: bool,
        t: f64,
        buf: &mut FrameBuffers,
        out: &mut [FishPixels],
    ) {
        let Some(b) = ellipsoid_box(&self.camera, e) else { return };
        let Some((i0, i1, j0, j1)) = self.pixel_range(&b) else { return };
        let axes_cam = self.camera.pose.rotation * e.axes;
        let inv_r = e.radii.map(|r| 1.0 / r);
        let m = Matrix3::from_diagonal(&inv_r) * axes_cam.transpose();
        let c = self.camera.pose.to_camera(&fme_core::geometry::WorldPoint(e.center)).0;
        let o = -(m * c);
        let cc = o.dot(&o) - 1.0;
        let (m0, m1, m2) = (m.column(0).into_owned(), m.column(1).into_owned(), m.column(2).into_owned());
        let up_row: Vector3<f64> = e.axes.row(2).transpose();
        let w = self.width as usize;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let idx = j * w + i;
                let [x, y] = self.bg.ray[idx];
                let d = m0 * f64::from(x) + m1 * f64::from(y) + m2;
                let a = d.dot(&d);
                let bb = o.dot(&d);
                let disc = bb * bb - a * cc;
                if disc < 0.0 {
                    continue;
                }
                let z = (-bb - disc.sqrt()) / a;
                if z <= NEAR {
                    continue;
                }
                if !self.plot(idx, id, z, buf, out) {
                    continue;
                }
                let s = o + d * z; // unit-sphere coordinates of the hit
                let n = s.component_mul(&inv_r);
                let n_up = up_row.dot(&n) / n.norm();
                let h = s.z;
                let mut col = mix3(body.belly, body.flank, smoothstep(-0.85, -0.25, h));
                col = mix3(col, body.back, smoothstep(-0.1, 0.55, h));
                if is_body {
                    // Spots on the back, a dark eye near the snout.
                    if h > 0.05 {
                        let cell = ((s.x * 11.0).floor() as i64 as u64)
                            ^ (((s.z * 6.0 + s.y * 6.0).floor() as i64 as u64) << 20);
                        if mix(cell ^ body.pattern) % 100 < 14 {
                            col = col.map(|v| v * 0.45);
                        }
                    }
                    if s.x > 0.8 && (s.z - 0.12).abs() < 0.13 && s.y.abs() > 0.3 {
                        col = [0.04, 0.04, 0.05];
                    }
                }
                buf.col[idx] = self.lit(col, z, f64::from(x), f64::from(y), n_up, t);
            }
        }
    }

    pub(super) fn draw_triangle(
        &self,
        id: u16,
        body: &FishBody,
        tri: &Triangle,
        shade: f64,
        buf: &mut FrameBuffers,
        out: &mut [FishPixels],
    ) {
        let v: [Vector3<f64>; 3] = tri.v.map(|p| self.camera.pose.to_camera(&fme_core::geometry::WorldPoint(p)).0);
        if v.iter().any(|p| p.z <= NEAR) {
            return;
        }
        let Some(b) = triangle_box(&self.camera, &tri.v) else { return };
        let Some((i0, i1, j0, j1)) = self.pixel_range(&b) else { return };
        let e1 = v[1] - v[0];
        let e2 = v[2] - v[0];
        let normal_w = self.cam_to_world * e1.cross(&e2);
        let n_up = (normal_w.z / normal_w.norm().max(1e-12)).abs();
        let col = body.back.map(|c| c * shade);
        let tvec = -v[0];
        let w = self.width as usize;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let idx = j * w + i;
                let [x, y] = self.bg.ray[idx];
                let d = Vector3::new(f64::from(x), f64::from(y), 1.0);
                let p = d.cross(&e2);
                let det = e1.dot(&p);
                if det.abs() < 1e-15 {
                    continue;
                }
                let inv = 1.0 / det;
                let u = tvec.dot(&p) * inv;
                if !(0.0..=1.0).contains(&u) {
                    continue;
                }
                let q = tvec.cross(&e1);
                let vv = d.dot(&q) * inv;
                if vv < 0.0 || u + vv > 1.0 {
                    continue;
                }
                let z = e2.dot(&q) * inv;
                if z <= NEAR || !self.plot(idx, id, z, buf, out) {
                    continue;
                }
                buf.col[idx] = self.lit(col, z, f64::from(x), f64::from(y), n_up, t_zero());
            }
        }
    }

    /// Daylight from above, dimmer with depth, plus caustics on up-facing surfaces.
    #[inline]
    fn lit(&self, col: [f64; 3], z: f64, x: f64, y: f64, n_up: f64, t: f64) -> [f32; 3] {
        let p = self.cam_to_world * Vector3::new(x * z, y * z, z) + self.eye;
        let below = (self.surface_z - p.z).max(0.0);
        let mut light = (-self.light_k * below).exp() * (0.45 + 0.55 * n_up.max(0.0)) + 0.08;
        if n_up > 0.2 && t >= 0.0 {
            let amp = 1.1 * (-self.caustic_k * below).exp() * n_up;
            light *= 1.0 + amp * f64::from(self.caustics.at(p.x as f32, p.y as f32, t as f32)) * 1.6;
        }
        col.map(|c| (c * light) as f32)
    }
}

/// Fins get no caustics (they are thin and mostly vertical).
#[inline]
fn t_zero() -> f64 {
    -1.0
}
