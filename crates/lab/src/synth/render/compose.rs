//! Image formation over a whole frame: water attenuation and veil, caustics on the pond, marine
//! snow, forward scattering, vignetting and sensor noise.

use super::{FrameBuffers, Renderer};
use crate::rng::{Rng, mix};
use crate::synth::texture::NOISE_TABLE;
use nalgebra::Vector3;

/// A drifting particle of marine snow.
#[derive(Debug, Clone, Copy)]
pub(super) struct Snow {
    p0: Vector3<f64>,
    v: Vector3<f64>,
    size: f64,
    bright: f32,
}

/// The marine snow of a pond of `size` (metres): more particles the more turbid the water.
pub(super) fn marine_snow(seed: u64, size: Vector3<f64>, turbid: f64) -> Vec<Snow> {
    let s = size;
    let mut rng = Rng::derive(seed, 0x5A0);
    let count = (250.0 + 500.0 * turbid) as usize;
    (0..count)
        .map(|_| Snow {
            p0: Vector3::new(rng.range(0.0, s.x), rng.range(0.0, s.y), rng.range(0.0, s.z)),
            v: Vector3::new(rng.range(-0.03, 0.03), rng.range(-0.03, 0.03), -rng.range(0.005, 0.03)),
            size: rng.range(0.0015, 0.005),
            bright: rng.range(0.35, 0.9) as f32,
        })
        .collect()
}

impl Renderer {
    /// Water, caustics on the pond, snow, vignette, noise; writes `buf.rgb`.
    pub(super) fn compose(&self, frame: u32, t: f64, buf: &mut FrameBuffers) {
        let veil = self.veil;
        let tf = t as f32;
        for idx in 0..buf.z.len() {
            let c = if buf.ids[idx] == 0 {
                let [cx, cy, amp] = self.bg.caustic[idx];
                let j = self.bg.j[idx];
                let k = if amp > 0.003 { 1.0 + amp * self.caustics.at(cx, cy, tf) * 1.6 } else { 1.0 };
                let tr = self.bg.trans[idx];
                [0, 1, 2].map(|ch| j[ch] * k * tr[ch] + veil[ch] * (1.0 - tr[ch]))
            } else {
                let range = buf.z[idx] * self.bg.ray_len[idx];
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
            let v = self.bg.vignette[idx];
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
                let range = buf.z[idx] * self.bg.ray_len[idx];
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
