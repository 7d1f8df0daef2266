//! Procedural textures: value noise for floor and walls, a tileable caustic pattern, and a table of
//! Gaussian samples for sensor noise.

use crate::rng::{Rng, mix};

/// Smooth value noise in `[0, 1]` on the integer lattice, hashed with `seed`.
pub fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let h = |i: f64, j: f64| {
        let k = (i as i64 as u64).wrapping_mul(0x8CB9_2BA7_2F3D_8DD7)
            ^ (j as i64 as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
        (mix(k ^ seed) >> 11) as f64 / (1u64 << 53) as f64
    };
    let a = h(xi, yi) + (h(xi + 1.0, yi) - h(xi, yi)) * sx;
    let b = h(xi, yi + 1.0) + (h(xi + 1.0, yi + 1.0) - h(xi, yi + 1.0)) * sx;
    a + (b - a) * sy
}

/// Fractal value noise (4 octaves), in `[0, 1]`.
pub fn fbm(seed: u64, x: f64, y: f64) -> f64 {
    let (mut sum, mut amp, mut f, mut norm) = (0.0, 0.5, 1.0, 0.0);
    for o in 0..4u64 {
        sum += amp * value_noise(seed.wrapping_add(o), x * f, y * f);
        norm += amp;
        amp *= 0.5;
        f *= 2.03;
    }
    sum / norm
}

/// Side of the square caustic texture, texels (a power of two for cheap wrapping).
pub const CAUSTIC_SIZE: usize = 256;

/// A tileable caustic texture: bright thin network lines where Voronoi cells meet (`F2 - F1` small),
/// the look of sunlight focused by surface waves.
#[derive(Debug, Clone)]
pub struct Caustics {
    texels: Vec<f32>,
}

impl Caustics {
    /// Builds the texture with `cells x cells` jittered feature points.
    pub fn new(seed: u64) -> Self {
        let cells = 8usize;
        let mut rng = Rng::derive(seed, 0xCA05);
        let pts: Vec<(f64, f64)> = (0..cells * cells).map(|_| (rng.uniform(), rng.uniform())).collect();
        let n = CAUSTIC_SIZE;
        let mut texels = vec![0.0f32; n * n];
        for (k, t) in texels.iter_mut().enumerate() {
            let (u, v) = ((k % n) as f64 / n as f64 * cells as f64, (k / n) as f64 / n as f64 * cells as f64);
            let (cu, cv) = (u.floor() as i64, v.floor() as i64);
            let (mut d1, mut d2) = (f64::MAX, f64::MAX);
            for dj in -1..=1 {
                for di in -1..=1 {
                    let (ci, cj) = (cu + di, cv + dj);
                    let w = |c: i64| c.rem_euclid(cells as i64) as usize;
                    let (px, py) = pts[w(cj) * cells + w(ci)];
                    let d = ((ci as f64 + px - u).powi(2) + (cj as f64 + py - v).powi(2)).sqrt();
                    if d < d1 {
                        d2 = d1;
                        d1 = d;
                    } else if d < d2 {
                        d2 = d;
                    }
                }
            }
            *t = (-(d2 - d1) * 9.0).exp() as f32;
        }
        Self { texels }
    }

    /// Bilinear, wrapping sample at texture coordinates in texels.
    #[inline]
    pub fn sample(&self, u: f32, v: f32) -> f32 {
        let n = CAUSTIC_SIZE as i32;
        let (fu, fv) = (u.floor(), v.floor());
        let (au, av) = (u - fu, v - fv);
        let (i0, j0) = ((fu as i32) & (n - 1), (fv as i32) & (n - 1));
        let (i1, j1) = ((i0 + 1) & (n - 1), (j0 + 1) & (n - 1));
        let t = &self.texels;
        let n = n as usize;
        let (i0, j0, i1, j1) = (i0 as usize, j0 as usize, i1 as usize, j1 as usize);
        let a = t[j0 * n + i0] + (t[j0 * n + i1] - t[j0 * n + i0]) * au;
        let b = t[j1 * n + i0] + (t[j1 * n + i1] - t[j1 * n + i0]) * au;
        a + (b - a) * av
    }

    /// Caustic intensity in `[0, 1]` at a horizontal world position (metres) and time: the minimum of
    /// two layers drifting apart, so the network shimmers instead of sliding.
    #[inline]
    pub fn at(&self, x: f32, y: f32, t: f32) -> f32 {
        let s = CAUSTIC_SIZE as f32 / 1.6; // one tile = 1.6 m
        let a = self.sample(x * s + 21.0 * t, y * s + 9.0 * t);
        let b = self.sample(x * s * 1.13 - 13.0 * t + 77.0, y * s * 1.13 + 17.0 * t + 31.0);
        a.min(b)
    }
}

/// Length of the Gaussian table (a power of two).
pub const NOISE_TABLE: usize = 1 << 16;

/// Standard normal samples for sensor noise, indexed by a cheap per-pixel hash.
pub fn gaussian_table(seed: u64) -> Vec<f32> {
    let mut rng = Rng::derive(seed, 0x6A05);
    (0..NOISE_TABLE).map(|_| rng.normal() as f32).collect()
}
