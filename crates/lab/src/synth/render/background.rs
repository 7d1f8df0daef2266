//! The static scene seen through each pixel, cast once per sequence: the pond's floor, walls and
//! surface and the reference cubes, their lit colour, the water between them and the camera, where
//! caustics fall on them, and the vignette. Every frame starts from it.

use super::{mix3, smoothstep};
use crate::synth::texture::{fbm, value_noise};
use fme_core::geometry::{Intrinsics, Pixel};
use fme_edge::sequence::ReferenceObject;
use nalgebra::{Matrix3, Vector3};

/// The static pond and cubes per pixel, row-major.
#[derive(Debug, Clone)]
pub(super) struct Background {
    /// Undistorted ray per pixel: camera x / z and y / z (lens distortion rendered exactly).
    pub ray: Vec<[f32; 2]>,
    /// Length of the ray per metre of camera z.
    pub ray_len: Vec<f32>,
    /// Camera z of the pond or cube surface, metres.
    pub z: Vec<f32>,
    /// Transmission of the water between the surface and the camera, per channel.
    pub trans: Vec<[f32; 3]>,
    /// Lit, unattenuated colour `J` of the surface.
    pub j: Vec<[f32; 3]>,
    /// Caustic coordinates (metres) and amplitude.
    pub caustic: Vec<[f32; 3]>,
    /// Vignetting factor.
    pub vignette: Vec<f32>,
}

/// What casting the background needs of the camera, pond, cubes and water.
pub(super) struct Caster<'a> {
    pub cam_to_world: Matrix3<f64>,
    /// Camera centre, world metres (inside the pond).
    pub eye: Vector3<f64>,
    /// The pond box, from the origin to `size`.
    pub size: Vector3<f64>,
    pub cubes: &'a [ReferenceObject],
    pub atten: [f64; 3],
    pub light_k: f64,
    pub caustic_k: f64,
    pub surface_z: f64,
    pub seed: u64,
    pub wall_seed: u64,
}

/// The nearest static surface along a ray: its ray parameter, the axis its face is normal to and
/// the cube it belongs to (`None`: the pond).
#[derive(Debug, Clone, Copy)]
struct Hit {
    t: f64,
    axis: usize,
    cube: Option<usize>,
}

/// One pixel of the background (the fields of [`Background`] but the ray and vignette).
#[derive(Debug, Clone, Copy)]
struct Sample {
    z: f32,
    trans: [f32; 3],
    j: [f32; 3],
    caustic: [f32; 3],
}

impl Background {
    /// Casts every pixel's ray through `k` into the scene of `caster`.
    pub(super) fn cast(caster: &Caster, k: &Intrinsics, width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        let mut bg = Self {
            ray: Vec::with_capacity(n),
            ray_len: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            trans: Vec::with_capacity(n),
            j: Vec::with_capacity(n),
            caustic: Vec::with_capacity(n),
            vignette: Vec::with_capacity(n),
        };
        for j in 0..height {
            for i in 0..width {
                let r = k.ray(Pixel::new(f64::from(i) + 0.5, f64::from(j) + 0.5));
                bg.ray.push([r.x as f32, r.y as f32]);
                bg.ray_len.push(r.norm() as f32);
                let s = caster.sample(r);
                bg.j.push(s.j);
                bg.z.push(s.z);
                bg.trans.push(s.trans);
                bg.caustic.push(s.caustic);
                bg.vignette.push(vignette(i, j, width, height));
            }
        }
        bg
    }
}

/// Darker towards the corners.
fn vignette(i: u32, j: u32, width: u32, height: u32) -> f32 {
    let (du, dv) = ((f64::from(i) + 0.5) / f64::from(width) - 0.5, (f64::from(j) + 0.5) / f64::from(height) - 0.5);
    (1.0 - 0.55 * (du * du + dv * dv)) as f32
}

impl Caster<'_> {
    /// The background along camera ray `r` (camera z = 1).
    fn sample(&self, r: Vector3<f64>) -> Sample {
        let d = self.cam_to_world * r;
        let Hit { t, axis, cube } = self.nearest(&d);
        let p = self.eye + d * t;
        let range = t * r.norm();
        let up_facing: f64 = match (cube, axis) {
            (_, 2) if d.z < 0.0 => 1.0, // floor or cube top
            (_, 2) => -1.0,             // water surface seen from below
            _ => 0.0,
        };
        let albedo = self.albedo(cube, axis, up_facing, &p);
        let light = (-self.light_k * (self.surface_z - p.z)).exp() * (0.6 + 0.4 * up_facing.max(0.0));
        let light = if up_facing < 0.0 { 1.0 } else { light };
        let amp = if up_facing < 0.0 {
            0.0
        } else {
            1.1 * (-self.caustic_k * (self.surface_z - p.z)).exp() * (0.15 + 0.85 * up_facing.max(0.0))
        };
        let (cx, cy) = match axis {
            2 => (p.x, p.y),
            0 => (p.y, p.z * 0.7),
            _ => (p.x, p.z * 0.7),
        };
        Sample {
            z: t as f32,
            trans: [0, 1, 2].map(|c| (-self.atten[c] * range).exp() as f32),
            j: albedo.map(|v| (v * light) as f32),
            caustic: [cx as f32, cy as f32, amp as f32],
        }
    }

    /// The nearest of the pond's exit face and the cubes along world direction `d`.
    fn nearest(&self, d: &Vector3<f64>) -> Hit {
        let (mut t, mut axis) = self.pond_exit(d);
        let mut cube = None;
        for (ci, c) in self.cubes.iter().enumerate() {
            if let Some((t0, ax)) = self.cube_entry(c, d)
                && t0 < t
            {
                t = t0;
                axis = ax;
                cube = Some(ci);
            }
        }
        Hit { t, axis, cube }
    }

    /// Exit point of the pond box (the camera is inside it): ray parameter and face axis.
    fn pond_exit(&self, d: &Vector3<f64>) -> (f64, usize) {
        let (s, eye) = (self.size, self.eye);
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
        (t, axis)
    }

    /// Where the ray enters cube `c` in front of the camera (slab test): ray parameter and face axis.
    fn cube_entry(&self, c: &ReferenceObject, d: &Vector3<f64>) -> Option<(f64, usize)> {
        let eye = self.eye;
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
        (t0 <= t1 && t0 > 0.0).then_some((t0, ax))
    }

    /// Surface colour at world point `p`: a painted cube, the sandy floor, the sky through the
    /// surface (Snell's window) or an algae-grown concrete wall.
    fn albedo(&self, cube: Option<usize>, axis: usize, up_facing: f64, p: &Vector3<f64>) -> [f64; 3] {
        let seed = self.seed;
        if let Some(ci) = cube {
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
            let (wall_seed, s) = (self.wall_seed, self.size);
            let (a, b) = if axis == 0 { (p.y, p.z) } else { (p.x, p.z) };
            let g = 0.7 + 0.45 * fbm(wall_seed, a * 1.7, b * 1.7);
            let algae = smoothstep(0.35, 0.7, fbm(wall_seed ^ 1, a * 0.9, b * 2.2) + 0.35 - p.z / s.z * 0.6);
            mix3([0.50 * g, 0.52 * g, 0.48 * g], [0.20 * g, 0.32 * g, 0.14 * g], algae)
        }
    }
}
