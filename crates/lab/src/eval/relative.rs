//! `--depth relative-gt`: ground-truth depth turned into a relative inverse depth with unknown scale
//! and shift plus noise, so eq. 1-2 can be tested before any depth network exists.
//!
//! `R(u, v) = scale * (1 + low_freq * F(u, v) + pixel_noise * n) / D(u, v) + shift`, where `F` is a
//! smooth field fixed for the sequence (the slowly varying distortion real relative-depth networks
//! make) and `n` standard normal noise drawn per pixel and frame from a hash of (seed, frame, pixel),
//! so the result is deterministic. Pixels without depth become NaN.

use fme_core::geometry::Pixel;
use fme_core::metric::{RelativeMap, sample_median};
use fme_edge::sequence::DepthMap;

const MAX_RADIUS: usize = 4;

/// Parameters of the synthetic relative inverse depth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RelativeGtParams {
    /// Unknown scale applied to 1/D.
    pub scale: f64,
    /// Unknown shift added.
    pub shift: f64,
    /// Amplitude of the smooth multiplicative distortion (fraction of 1/D).
    pub low_freq: f64,
    /// Standard deviation of the per-pixel multiplicative noise (fraction of 1/D).
    pub pixel_noise: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for RelativeGtParams {
    fn default() -> Self {
        Self { scale: 0.8, shift: 0.05, low_freq: 0.03, pixel_noise: 0.01, seed: 1 }
    }
}

/// One SplitMix64 step as a hash of `z` (the crate's one generator, [`crate::rng`], counter-based
/// here so every pixel's noise is reproducible on its own).
#[inline]
fn splitmix(z: u64) -> u64 {
    crate::rng::mix(z.wrapping_add(0x9e37_79b9_7f4a_7c15))
}

/// Standard normal from a hash (Box-Muller on two uniforms).
#[inline]
fn normal(key: u64) -> f64 {
    let a = splitmix(key);
    let b = splitmix(a);
    let u1 = ((a >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (b >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[inline]
fn phase(p: &RelativeGtParams) -> f64 {
    (splitmix(p.seed) >> 11) as f64 / (1u64 << 53) as f64 * std::f64::consts::TAU
}

#[inline]
fn frame_key(p: &RelativeGtParams, frame: u32) -> u64 {
    splitmix(p.seed ^ (u64::from(frame) << 32))
}

/// Relative inverse depth at pixel `(x, y)` of a `w x h` map with depth `mm` (millimetres, 0 = none).
#[inline]
fn value(p: &RelativeGtParams, phase: f64, key: u64, mm: u16, (x, y): (usize, usize), (w, h): (usize, usize)) -> f32 {
    if mm == 0 {
        return f32::NAN;
    }
    let d = f64::from(mm) / 1000.0;
    let (fx, fy) = (x as f64 / w as f64, y as f64 / h as f64);
    let field = (std::f64::consts::TAU * (1.3 * fx + 0.4 * fy) + phase).sin()
        * (std::f64::consts::TAU * 0.7 * fy + 0.5 * phase).cos();
    let n = if p.pixel_noise > 0.0 { normal(key ^ ((y * w + x) as u64)) } else { 0.0 };
    (p.scale * (1.0 + p.low_freq * field + p.pixel_noise * n) / d + p.shift) as f32
}

/// Writes the relative inverse depth of `depth` (frame `frame`) into `out` (resized to fit).
pub fn relative_from_depth(p: &RelativeGtParams, depth: &DepthMap, frame: u32, out: &mut Vec<f32>) {
    let (w, h) = (depth.width as usize, depth.height as usize);
    let (ph, key) = (phase(p), frame_key(p, frame));
    out.clear();
    out.extend((0..w * h).map(|i| value(p, ph, key, depth.mm[i], (i % w, i / w), (w, h))));
}

/// The relative inverse depth at the pixel containing `px` (`None` outside or without depth).
pub fn relative_at(p: &RelativeGtParams, depth: &DepthMap, frame: u32, px: Pixel) -> Option<f64> {
    let (w, h) = (depth.width as usize, depth.height as usize);
    if !px.is_finite() || px.u < 0.0 || px.v < 0.0 || px.u as usize >= w || px.v as usize >= h {
        return None;
    }
    let (x, y) = (px.u as usize, px.v as usize);
    let v = value(p, phase(p), frame_key(p, frame), depth.mm[y * w + x], (x, y), (w, h));
    v.is_finite().then_some(f64::from(v))
}

/// Median of the relative inverse depth in the `(2r+1)^2` window around `px`, computed only there
/// (identical to sampling [`relative_from_depth`]'s map with [`fme_core::metric::sample_median`]).
pub fn sample_relative(p: &RelativeGtParams, depth: &DepthMap, frame: u32, px: Pixel, radius: usize) -> Option<f64> {
    let (w, h) = (depth.width as usize, depth.height as usize);
    if !px.is_finite() || px.u < 0.0 || px.v < 0.0 || px.u as usize >= w || px.v as usize >= h {
        return None;
    }
    let r = radius.min(MAX_RADIUS);
    let (cx, cy) = (px.u as usize, px.v as usize);
    let (x0, y0) = (cx.saturating_sub(r), cy.saturating_sub(r));
    let (x1, y1) = ((cx + r).min(w - 1), (cy + r).min(h - 1));
    let mut buf = [f32::NAN; (2 * MAX_RADIUS + 1) * (2 * MAX_RADIUS + 1)];
    let (ph, key) = (phase(p), frame_key(p, frame));
    let ww = x1 - x0 + 1;
    for y in y0..=y1 {
        for x in x0..=x1 {
            buf[(y - y0) * ww + (x - x0)] = value(p, ph, key, depth.mm[y * w + x], (x, y), (w, h));
        }
    }
    let n = ww * (y1 - y0 + 1);
    let map = RelativeMap { data: &buf[..n], width: ww, height: y1 - y0 + 1 };
    sample_median(&map, Pixel::new((cx - x0) as f64 + 0.5, (cy - y0) as f64 + 0.5), r, |_| true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noiseless_relative_depth_is_affine_in_inverse_depth_and_deterministic() {
        let mut depth = DepthMap::new(4, 2);
        depth.mm = vec![1000, 2000, 0, 4000, 500, 1000, 3000, 6000];
        let p = RelativeGtParams { low_freq: 0.0, pixel_noise: 0.0, ..Default::default() };
        let mut out = Vec::new();
        relative_from_depth(&p, &depth, 1, &mut out);
        assert!(out[2].is_nan());
        assert!((out[0] as f64 - (0.8 + 0.05)).abs() < 1e-6);
        assert!((out[3] as f64 - (0.8 / 4.0 + 0.05)).abs() < 1e-6);
        let noisy = RelativeGtParams::default();
        let (mut a, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        relative_from_depth(&noisy, &depth, 5, &mut a);
        relative_from_depth(&noisy, &depth, 5, &mut b);
        relative_from_depth(&noisy, &depth, 6, &mut c);
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        // Sampling in place equals sampling the full map.
        let full = RelativeMap::new(&a, 4, 2).unwrap();
        for px in [Pixel::new(0.5, 0.5), Pixel::new(3.2, 1.9), Pixel::new(2.5, 0.5)] {
            assert_eq!(sample_relative(&noisy, &depth, 5, px, 1), sample_median(&full, px, 1, |_| true));
        }
        assert_ne!(format!("{a:?}"), format!("{c:?}"));
        // Noise of a large sample is close to standard normal.
        let z: Vec<f64> = (0..20000u64).map(normal).collect();
        let m = z.iter().sum::<f64>() / z.len() as f64;
        let v = z.iter().map(|x| (x - m).powi(2)).sum::<f64>() / z.len() as f64;
        assert!(m.abs() < 0.03 && (v - 1.0).abs() < 0.05, "{m} {v}");
    }
}
