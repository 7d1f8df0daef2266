//! Software renderer: ray-cast pond, reference cubes and fish per pixel, then underwater image
//! formation `I_c = J_c exp(-b_c d) + B_c (1 - exp(-b_c d))` (`d` the ray length), caustics that fade
//! with depth, marine snow, vignetting and sensor noise.
//!
//! Depth is the camera z of the nearest surface (pond, cube or fish), exactly as the ray caster
//! found it, so the depth maps agree with the geometry to the millimetre rounding.
//!
//! | file | what |
//! |---|---|
//! | `bounds.rs` | exact amodal screen boxes of ellipsoids, fins and whole fish |
//! | `background.rs` | the static pond and cubes seen through each pixel, cast once per sequence |
//! | `surfaces.rs` | fish parts and fins drawn into the frame: z-test, colour, daylight |
//! | `compose.rs` | image formation over the frame: water, caustics, snow, blur, vignette, noise |

mod background;
mod bounds;
mod compose;
mod surfaces;

pub use bounds::{ellipsoid_box, fish_box};

use super::fish::{FishBody, FishShape, FishState, PART_BODY};
use super::scene::Pond;
use super::texture::{Caustics, gaussian_table};
use super::water::WaterType;
use background::Background;
use compose::{Snow, marine_snow};
use fme_core::geometry::{Camera, PixelBox};
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
    /// The static scene per pixel, cast once.
    bg: Background,
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
        let cam_to_world = camera.pose.rotation.transpose();
        let eye = camera.pose.camera_center().0;
        let atten = water.attenuation();
        let light_k = 0.45 * water.light_decay();
        let caustic_k = 0.3 + 0.9 * water.light_decay();
        let surface_z = pond.size.z;
        let caster = background::Caster {
            cam_to_world,
            eye,
            size: pond.size,
            cubes,
            atten,
            light_k,
            caustic_k,
            surface_z,
            seed,
            wall_seed: seed ^ 0x3A11,
        };
        let bg = Background::cast(&caster, &camera.intrinsics, width, height);
        let turbid = water.light_decay();
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
            bg,
            caustics: Caustics::new(seed),
            noise: gaussian_table(seed),
            noise_sigma: (0.010 + 0.012 * turbid) as f32,
            scatter_k: (0.45 * turbid) as f32,
            snow: marine_snow(seed, pond.size, turbid),
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
        buf.z.copy_from_slice(&self.bg.z);
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
}
