//! Software renderer: ray-cast pond, reference cubes and fish per pixel, then underwater image
//! formation `I_c = J_c exp(-b_c d) + B_c (1 - exp(-b_c d))` (`d` the ray length), caustics that fade
//! with depth, marine snow, vignetting and sensor noise.
//!
//! Depth is the camera z of the nearest surface (pond, cube or fish), exactly as the ray caster
//! found it, so the depth maps agree with the geometry to the millimetre rounding.

use super::fish::{Ellipsoid, FishBody, FishShape, FishState, PART_BODY, Triangle};
use super::scene::Pond;
use super::texture::{Caustics, NOISE_TABLE, fbm, gaussian_table, value_noise};
use super::water::WaterType;
use crate::rng::{Rng, mix};
use fme_core::geometry::{Camera, Pixel, PixelBox};
use fme_edge::sequence::{DepthMap, ReferenceObject};
use nalgebra::{Matrix3, Vector3};

/// Nearest camera z a fish may have to be drawn, metres.
const NEAR: f64 = 0.05;

/// What the renderer reports about one fish in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FishPixels {
    /// Amodal box of the whole fish (tail and fins included), not clipped to the image.
    pub bbox: PixelBox,
    /// Pixels the fish covers when rendered alone (inside the image).
    pub alone: u32,
    /// Pixels where the fish is the nearest surface.
    pub visible: u32,
}

impl FishPixels {
    /// Visible pixels / pixels of the fish alone (0 when it is outside the image).
    pub fn visibility(&self) -> f64 {
        if self.alone == 0 { 0.0 } else { f64::from(self.visible) / f64::from(self.alone) }
    }
}

/// Per-frame working buffers (one set per worker thread).
#[derive(Debug, Clone)]
pub struct FrameBuffers {
    /// Camera z of the nearest surface per pixel, metres.
    pub z: Vec<f32>,
    /// Fish id per pixel (fish index + 1), 0 for pond or cube.
    pub ids: Vec<u16>,
    /// Unattenuated colour `J` of fish pixels.
    col: Vec<[f32; 3]>,
    stamp: Vec<u16>,
    /// Final colour, 8-bit RGB, row-major.
    pub rgb: Vec<u8>,
    light: Vec<[f32; 3]>,
    tmp: Vec<[f32; 3]>,
}

impl FrameBuffers {
    /// Buffers for `width x height` frames.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            z: vec![0.0; n],
            ids: vec![0; n],
            col: vec![[0.0; 3]; n],
            stamp: vec![0; n],
            rgb: vec![0; n * 3],
            light: vec![[0.0; 3]; n],
            tmp: vec![[0.0; 3]; n],
        }
    }

    /// The depth map of the last rendered frame (millimetres of camera z).
    pub fn depth_map(&self, width: u32, height: u32) -> DepthMap {
        DepthMap { width, height, mm: self.z.iter().map(|&z| DepthMap::encode(f64::from(z))).collect() }
    }
}

/// A drifting particle of marine snow.
#[derive(Debug, Clone, Copy)]
struct Snow {
    p0: Vector3<f64>,
    v: Vector3<f64>,
    size: f64,
    bright: f32,
}

/// The renderer of one sequence: camera, water and the static pond, precomputed per pixel.
#[derive(Debug, Clone)]
pub struct Renderer {
    width: u32,
    height: u32,
    camera: Camera,
    cam_to_world: Matrix3<f64>,
    eye: Vector3<f64>,
    atten: [f32; 3],
    veil: [f32; 3],
    light_k: f64,
    caustic_k: f64,
    surface_z: f64,
    ray: Vec<[f32; 2]>,
    ray_len: Vec<f32>,
    bg_z: Vec<f32>,
    bg_trans: Vec<[f32; 3]>,
    bg_j: Vec<[f32; 3]>,
    /// Caustic coordinates (metres) and amplitude for static pixels.
    bg_caustic: Vec<[f32; 3]>,
    vignette: Vec<f32>,
    caustics: Caustics,
    noise: Vec<f32>,
    noise_sigma: f32,
    scatter_k: f32,
    snow: Vec<Snow>,
    pond: Pond,
    seed: u64,
}

#[inline]
fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[inline]
fn mix3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

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
fn triangle_box(camera: &Camera, v: &[Vector3<f64>; 3]) -> Option<PixelBox> {
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

impl Renderer {
    /// Precomputes rays (undistorted per pixel, so lens distortion is rendered exactly), the static
    /// pond and cubes, textures and marine snow.
    pub fn new(
        camera: Camera,
        width: u32,
        height: u32,
        pond: Pond,
        water: WaterType,
        cubes: &[ReferenceObject],
        seed: u64,
    ) -> Self {
        let n = width as usize * height as usize;
        let k = camera.intrinsics;
        let cam_to_world = camera.pose.rotation.transpose();
        let eye = camera.pose.camera_center().0;
        let atten = water.attenuation();
        let light_k = 0.45 * water.light_decay();
        let caustic_k = 0.3 + 0.9 * water.light_decay();
        let surface_z = pond.size.z;
        let mut ray = Vec::with_capacity(n);
        let mut ray_len = Vec::with_capacity(n);
        let mut bg_z = Vec::with_capacity(n);
        let mut bg_trans = Vec::with_capacity(n);
        let mut bg_j = Vec::with_capacity(n);
        let mut bg_caustic = Vec::with_capacity(n);
        let mut vignette = Vec::with_capacity(n);
        let s = pond.size;
        let wall_seed = seed ^ 0x3A11;
        for j in 0..height {
            for i in 0..width {
                let r = k.ray(Pixel::new(f64::from(i) + 0.5, f64::from(j) + 0.5));
                ray.push([r.x as f32, r.y as f32]);
                ray_len.push(r.norm() as f32);
                let d = cam_to_world * r;
                // Exit point of the pond box (the camera is inside it).
                let (mut t, mut axis) = (f64::MAX, 2usize);
                for a in 0..3 {
                    let ta = if d[a] > 1e-12 {
                        (s[a] - eye[a]) / d[a]
                    } else if d[a] < -1e-12 {
                        -eye[a] / d[a]
                    } else {
                        f64::MAX
                    };
                    if ta < t {
                        t = ta;
                        axis = a;
                    }
                }
                let mut hit_cube = None;
                for (ci, c) in cubes.iter().enumerate() {
                    let h = c.size_m * 0.5;
                    let (mut t0, mut t1, mut ax) = (0.0f64, f64::MAX, 0usize);
                    for a in 0..3 {
                        if d[a].abs() < 1e-12 {
                            if (eye[a] - c.center_w[a]).abs() > h {
                                t0 = f64::MAX;
                            }
                            continue;
                        }
                        let ta = (c.center_w[a] - h - eye[a]) / d[a];
                        let tb = (c.center_w[a] + h - eye[a]) / d[a];
                        let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
                        if lo > t0 {
                            t0 = lo;
                            ax = a;
                        }
                        t1 = t1.min(hi);
                    }
                    if t0 <= t1 && t0 > 0.0 && t0 < t {
                        t = t0;
                        axis = ax;
                        hit_cube = Some(ci);
                    }
                }
                let p = eye + d * t;
                let range = t * r.norm();
                let up_facing: f64 = match (hit_cube, axis) {
                    (_, 2) if d.z < 0.0 => 1.0, // floor or cube top
                    (_, 2) => -1.0,             // water surface seen from below
                    _ => 0.0,
                };
                let albedo: [f64; 3] = if let Some(ci) = hit_cube {
                    let shade = if up_facing > 0.0 { 1.0 } else { 0.8 };
                    let base = [[0.95, 0.78, 0.18], [0.92, 0.92, 0.88], [0.95, 0.45, 0.15]][ci % 3];
                    base.map(|v| v * shade)
                } else if axis == 2 && up_facing > 0.0 {
                    // Sandy floor with gravel.
                    let g = 0.65 + 0.55 * fbm(seed ^ 0xF1, p.x * 2.5, p.y * 2.5);
                    let grit = 0.85 + 0.3 * value_noise(seed ^ 0xF2, p.x * 60.0, p.y * 60.0);
                    [0.58 * g * grit, 0.54 * g * grit, 0.42 * g * grit]
                } else if axis == 2 {
                    // Snell's window: bright sky through the surface.
                    [1.6, 1.7, 1.7]
                } else {
                    // Concrete walls, algae growing from the floor.
                    let (a, b) = if axis == 0 { (p.y, p.z) } else { (p.x, p.z) };
                    let g = 0.7 + 0.45 * fbm(wall_seed, a * 1.7, b * 1.7);
                    let algae = smoothstep(0.35, 0.7, fbm(wall_seed ^ 1, a * 0.9, b * 2.2) + 0.35 - p.z / s.z * 0.6);
                    mix3([0.50 * g, 0.52 * g, 0.48 * g], [0.20 * g, 0.32 * g, 0.14 * g], algae)
                };
                let light = (-light_k * (surface_z - p.z)).exp() * (0.6 + 0.4 * up_facing.max(0.0));
                let light = if up_facing < 0.0 { 1.0 } else { light };
                bg_j.push(albedo.map(|v| (v * light) as f32));
                bg_z.push(t as f32);
                bg_trans.push([0, 1, 2].map(|c| (-atten[c] * range).exp() as f32));
                let amp = if up_facing < 0.0 {
                    0.0
                } else {
                    1.1 * (-caustic_k * (surface_z - p.z)).exp() * (0.15 + 0.85 * up_facing.max(0.0))
                };
                let (cx, cy) = match axis {
                    2 => (p.x, p.y),
                    0 => (p.y, p.z * 0.7),
                    _ => (p.x, p.z * 0.7),
                };
                bg_caustic.push([cx as f32, cy as f32, amp as f32]);
                let (du, dv) =
                    ((f64::from(i) + 0.5) / f64::from(width) - 0.5, (f64::from(j) + 0.5) / f64::from(height) - 0.5);
                vignette.push((1.0 - 0.55 * (du * du + dv * dv)) as f32);
            }
        }
        let turbid = water.light_decay();
        let mut rng = Rng::derive(seed, 0x5A0);
        let count = (250.0 + 500.0 * turbid) as usize;
        let snow = (0..count)
            .map(|_| Snow {
                p0: Vector3::new(rng.range(0.0, s.x), rng.range(0.0, s.y), rng.range(0.0, s.z)),
                v: Vector3::new(rng.range(-0.03, 0.03), rng.range(-0.03, 0.03), -rng.range(0.005, 0.03)),
                size: rng.range(0.0015, 0.005),
                bright: rng.range(0.35, 0.9) as f32,
            })
            .collect();
        Self {
            width,
            height,
            camera,
            cam_to_world,
            eye,
            atten: atten.map(|v| v as f32),
            veil: water.veil().map(|v| v as f32),
            light_k,
            caustic_k,
            surface_z,
            ray,
            ray_len,
            bg_z,
            bg_trans,
            bg_j,
            bg_caustic,
            vignette,
            caustics: Caustics::new(seed),
            noise: gaussian_table(seed),
            noise_sigma: (0.010 + 0.012 * turbid) as f32,
            scatter_k: (0.45 * turbid) as f32,
            snow,
            pond,
            seed,
        }
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Renders one frame at time `t` (seconds) into `buf`; returns what each fish covers.
    pub fn render(
        &self,
        frame: u32,
        t: f64,
        bodies: &[FishBody],
        states: &[FishState],
        buf: &mut FrameBuffers,
    ) -> Vec<FishPixels> {
        buf.z.copy_from_slice(&self.bg_z);
        buf.ids.fill(0);
        buf.stamp.fill(0);
        let mut out = Vec::with_capacity(bodies.len());
        for (i, (body, state)) in bodies.iter().zip(states).enumerate() {
            let shape = FishShape::new(body, state);
            let Some(bbox) = fish_box(&self.camera, &shape) else {
                out.push(FishPixels { bbox: PixelBox::default(), alone: 0, visible: 0 });
                continue;
            };
            out.push(FishPixels { bbox, alone: 0, visible: 0 });
            let id = i as u16 + 1;
            for (pi, e) in shape.parts.iter().enumerate() {
                self.draw_ellipsoid(id, body, e, pi == PART_BODY, t, buf, &mut out);
            }
            for (fi, tri) in shape.fins.iter().enumerate() {
                let shade = if fi == 2 { 0.7 } else { 0.85 };
                self.draw_triangle(id, body, tri, shade, buf, &mut out);
            }
        }
        self.compose(frame, t, buf);
        out
    }

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
    fn draw_ellipsoid(
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
                let [x, y] = self.ray[idx];
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

    fn draw_triangle(
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
                let [x, y] = self.ray[idx];
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

    /// Water, caustics on the pond, snow, vignette, noise; writes `buf.rgb`.
    fn compose(&self, frame: u32, t: f64, buf: &mut FrameBuffers) {
        let veil = self.veil;
        let tf = t as f32;
        for idx in 0..buf.z.len() {
            let c = if buf.ids[idx] == 0 {
                let [cx, cy, amp] = self.bg_caustic[idx];
                let j = self.bg_j[idx];
                let k = if amp > 0.003 { 1.0 + amp * self.caustics.at(cx, cy, tf) * 1.6 } else { 1.0 };
                let tr = self.bg_trans[idx];
                [0, 1, 2].map(|ch| j[ch] * k * tr[ch] + veil[ch] * (1.0 - tr[ch]))
            } else {
                let range = buf.z[idx] * self.ray_len[idx];
                let j = buf.col[idx];
                [0, 1, 2].map(|ch| {
                    let tr = (-self.atten[ch] * range).exp();
                    j[ch] * tr + veil[ch] * (1.0 - tr)
                })
            };
            buf.light[idx] = c;
        }
        self.draw_snow(t, buf);
        self.forward_scatter(buf);
        let seed = mix(self.seed ^ (u64::from(frame) << 32));
        let sigma = self.noise_sigma;
        let mask = (NOISE_TABLE - 1) as u64;
        for idx in 0..buf.z.len() {
            let v = self.vignette[idx];
            let h = mix(seed.wrapping_add(idx as u64));
            let c = buf.light[idx];
            for (ch, &cv) in c.iter().enumerate() {
                let g = self.noise[((h >> (16 * ch)) & mask) as usize];
                let val = cv * v + g * sigma;
                buf.rgb[idx * 3 + ch] = (val.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            }
        }
    }

    /// Forward scattering and lens softness: a 3x3 binomial blur blended in more strongly the
    /// longer the ray and the more turbid the water (also hides the ray caster's hard edges).
    fn forward_scatter(&self, buf: &mut FrameBuffers) {
        let (w, h) = (self.width as usize, self.height as usize);
        for j in 0..h {
            let row = &buf.light[j * w..(j + 1) * w];
            let out = &mut buf.tmp[j * w..(j + 1) * w];
            for i in 0..w {
                let (l, r) = (row[i.saturating_sub(1)], row[(i + 1).min(w - 1)]);
                let c = row[i];
                out[i] = [0, 1, 2].map(|ch| 0.25 * (l[ch] + r[ch]) + 0.5 * c[ch]);
            }
        }
        let k = self.scatter_k;
        for j in 0..h {
            let (up, down) = (j.saturating_sub(1), (j + 1).min(h - 1));
            for i in 0..w {
                let idx = j * w + i;
                let (a, b, c) = (buf.tmp[up * w + i], buf.tmp[down * w + i], buf.tmp[idx]);
                let range = buf.z[idx] * self.ray_len[idx];
                let wgt = (0.3 + k * range).min(0.85);
                let cur = &mut buf.light[idx];
                for ch in 0..3 {
                    let blur = 0.25 * (a[ch] + b[ch]) + 0.5 * c[ch];
                    cur[ch] += (blur - cur[ch]) * wgt;
                }
            }
        }
    }

    /// Marine snow: small, defocused bright particles drifting and sinking, attenuated by the water
    /// like everything else, hidden behind nearer surfaces.
    fn draw_snow(&self, t: f64, buf: &mut FrameBuffers) {
        let s = self.pond.size;
        let k = &self.camera.intrinsics;
        let (w, h) = (self.width as i64, self.height as i64);
        for p in &self.snow {
            let mut q = p.p0 + p.v * t;
            for a in 0..3 {
                q[a] = q[a].rem_euclid(s[a]);
            }
            let c = self.camera.pose.rotation * q + self.camera.pose.translation;
            if c.z < 0.15 {
                continue;
            }
            let Ok(px) = k.project(&fme_core::geometry::CameraPoint(c)) else { continue };
            let (u, v) = (px.u, px.v);
            // Defocus: the lens is focused at about 2 m.
            let radius = (k.fx * p.size / c.z + 3.0 * (1.0 / c.z - 0.5).abs()).clamp(0.6, 6.0);
            let range = c.norm();
            let r2 = radius * radius;
            let lum: [f32; 3] = [0, 1, 2].map(|ch| {
                let tr = (-self.atten[ch] * range as f32).exp();
                0.95 * tr + self.veil[ch] * (1.0 - tr)
            });
            let (iu, iv) = (u.floor() as i64, v.floor() as i64);
            let reach = radius.ceil() as i64 + 1;
            for j in (iv - reach).max(0)..=(iv + reach).min(h - 1) {
                for i in (iu - reach).max(0)..=(iu + reach).min(w - 1) {
                    let idx = (j * w + i) as usize;
                    if f64::from(buf.z[idx]) < c.z {
                        continue;
                    }
                    let (du, dv) = (i as f64 + 0.5 - u, j as f64 + 0.5 - v);
                    let d2 = du * du + dv * dv;
                    if d2 > r2 {
                        continue;
                    }
                    let alpha = p.bright * (1.0 - (d2 / r2) as f32).powi(2) * (0.9 / (radius as f32).max(1.0));
                    for (cur, l) in buf.light[idx].iter_mut().zip(lum) {
                        *cur += (l - *cur) * alpha.min(1.0);
                    }
                }
            }
        }
    }
}

/// Fins get no caustics (they are thin and mostly vertical).
#[inline]
fn t_zero() -> f64 {
    -1.0
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
