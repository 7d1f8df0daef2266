//! Kalman filters for box tracks, on nalgebra static matrices (no heap).
//!
//! - [`SortKalman`]: the exact filter of SORT (Bewley et al. 2016, abewley/sort `KalmanBoxTracker`):
//!   state `[cx, cy, s, r, dcx, dcy, ds]` (centre, area, aspect ratio w/h, velocities per frame),
//!   measurement `[cx, cy, s, r]`, filterpy's predict and Joseph-form update, and its constants
//!   `R = diag(1, 1, 10, 10)`, `P0 = diag(10, 10, 10, 10, 1e4, 1e4, 1e4)`,
//!   `Q = diag(1, 1, 1, 1, 0.01, 0.01, 1e-4)`, and the clamp `ds = 0` when `s + ds <= 0`.
//! - [`CvKalman`]: a constant-velocity filter in real time for the `default` preset: state
//!   `[cx, cy, w, h, vcx, vcy, vw, vh]` in pixels and pixels per second, noise proportional to the box
//!   height (so that near and far fish are treated alike), process noise of a piecewise-constant
//!   acceleration over the actual `dt` between frame timestamps.

use crate::geometry::PixelBox;
use nalgebra::{SMatrix, SVector};

type V4 = SVector<f64, 4>;

/// SORT's 7-state filter. Time unit: one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SortKalman {
    /// State `[cx, cy, s, r, dcx, dcy, ds]`.
    pub x: SVector<f64, 7>,
    /// State covariance.
    pub p: SMatrix<f64, 7, 7>,
}

/// `[cx, cy, s = w h, r = w / h]` of a box (SORT's `convert_bbox_to_z`).
pub fn box_to_z(b: &PixelBox) -> V4 {
    V4::new(b.x + b.w / 2.0, b.y + b.h / 2.0, b.w * b.h, b.w / b.h)
}

/// Box of a `[cx, cy, s, r]` state (SORT's `convert_x_to_bbox`); NaN when `s r < 0`.
pub fn z_to_box(cx: f64, cy: f64, s: f64, r: f64) -> PixelBox {
    let w = (s * r).sqrt();
    let h = s / w;
    // Corners first, then size, in SORT's floating-point order (its output prints x2 - x1).
    let (x1, y1, x2, y2) = (cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0);
    PixelBox::new(x1, y1, x2 - x1, y2 - y1)
}

impl SortKalman {
    /// A filter initialised on a first box, with SORT's `P0`.
    pub fn new(b: &PixelBox) -> Self {
        let z = box_to_z(b);
        let mut x = SVector::<f64, 7>::zeros();
        x.fixed_rows_mut::<4>(0).copy_from(&z);
        let p = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::<f64, 7>::from([10.0, 10.0, 10.0, 10.0, 1e4, 1e4, 1e4]));
        Self { x, p }
    }

    /// Predicts `dt` frames ahead (SORT always uses 1): `x = F x`, `P = F P F' + Q`, after the
    /// area-velocity clamp.
    pub fn predict(&mut self, dt: f64) {
        if self.x[6] + self.x[2] <= 0.0 {
            self.x[6] = 0.0;
        }
        let mut f = SMatrix::<f64, 7, 7>::identity();
        f[(0, 4)] = dt;
        f[(1, 5)] = dt;
        f[(2, 6)] = dt;
        let q = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::<f64, 7>::from([1.0, 1.0, 1.0, 1.0, 0.01, 0.01, 1e-4]));
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
    }

    /// Corrects with a measured box (filterpy's update with the Joseph form of the covariance).
    pub fn update(&mut self, b: &PixelBox) {
        let z = box_to_z(b);
        let mut h = SMatrix::<f64, 4, 7>::zeros();
        for i in 0..4 {
            h[(i, i)] = 1.0;
        }
        let r = SMatrix::<f64, 4, 4>::from_diagonal(&V4::new(1.0, 1.0, 10.0, 10.0));
        let y = z - h * self.x;
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        let Some(si) = s.try_inverse() else { return };
        let k = pht * si;
        self.x += k * y;
        let ikh = SMatrix::<f64, 7, 7>::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
    }

    /// Current box estimate (NaN fields when the state is degenerate).
    pub fn bbox(&self) -> PixelBox {
        z_to_box(self.x[0], self.x[1], self.x[2], self.x[3])
    }
}

/// Noise parameters of [`CvKalman`], all relative to the box height `h` (pixels).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CvNoise {
    /// Standard deviation of a measured coordinate, as a fraction of `h`.
    pub meas: f64,
    /// Standard deviation of the acceleration, fraction of `h` per second squared.
    pub accel: f64,
    /// Initial standard deviation of the velocity, fraction of `h` per second.
    pub init_vel: f64,
}

impl Default for CvNoise {
    fn default() -> Self {
        Self { meas: 0.05, accel: 3.0, init_vel: 1.0 }
    }
}

/// Constant-velocity filter on `[cx, cy, w, h]` with velocities per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CvKalman {
    /// State `[cx, cy, w, h, vcx, vcy, vw, vh]`, pixels and pixels per second.
    pub x: SVector<f64, 8>,
    /// State covariance.
    pub p: SMatrix<f64, 8, 8>,
    /// Noise parameters.
    pub noise: CvNoise,
}

fn box_to_m(b: &PixelBox) -> V4 {
    V4::new(b.x + b.w / 2.0, b.y + b.h / 2.0, b.w, b.h)
}

impl CvKalman {
    /// A filter initialised on a first box with zero velocity.
    pub fn new(b: &PixelBox, noise: CvNoise) -> Self {
        let mut x = SVector::<f64, 8>::zeros();
        x.fixed_rows_mut::<4>(0).copy_from(&box_to_m(b));
        let h = b.h.max(1.0);
        let sp = 2.0 * noise.meas * h;
        let sv = noise.init_vel * h;
        let p = SMatrix::<f64, 8, 8>::from_diagonal(&SVector::<f64, 8>::from([
            sp * sp,
            sp * sp,
            sp * sp,
            sp * sp,
            sv * sv,
            sv * sv,
            sv * sv,
            sv * sv,
        ]));
        Self { x, p, noise }
    }

    /// Predicts `dt` seconds ahead with piecewise-constant white acceleration:
    /// `x' = F x`, `P' = F P F' + Q` with `F = [[I, dt I], [0, I]]` and
    /// `Q = q [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]` per coordinate, `q = (accel h)^2`. Written on the
    /// 4x4 blocks of `P` (the same result as the dense product, at a fraction of the work).
    pub fn predict(&mut self, dt: f64) {
        if dt <= 0.0 || !dt.is_finite() {
            return;
        }
        let h = self.x[3].max(1.0);
        let q = (self.noise.accel * h).powi(2);
        let dt2 = dt * dt;
        let (q11, q12, q22) = (q * dt2 * dt2 / 4.0, q * dt2 * dt / 2.0, q * dt2);
        for i in 0..4 {
            self.x[i] += dt * self.x[i + 4];
        }
        // Keep the size positive: a shrinking box must not flip.
        self.x[2] = self.x[2].max(1.0);
        self.x[3] = self.x[3].max(1.0);
        let p = self.p;
        let p11 = p.fixed_view::<4, 4>(0, 0);
        let p12 = p.fixed_view::<4, 4>(0, 4);
        let p21 = p.fixed_view::<4, 4>(4, 0);
        let p22 = p.fixed_view::<4, 4>(4, 4);
        let n12 = p12 + p22 * dt;
        let n11 = p11 + (p12 + p21) * dt + p22 * dt2;
        let n21 = p21 + p22 * dt;
        self.p.fixed_view_mut::<4, 4>(0, 0).copy_from(&n11);
        self.p.fixed_view_mut::<4, 4>(0, 4).copy_from(&n12);
        self.p.fixed_view_mut::<4, 4>(4, 0).copy_from(&n21);
        for i in 0..4 {
            self.p[(i, i)] += q11;
            self.p[(i, i + 4)] += q12;
            self.p[(i + 4, i)] += q12;
            self.p[(i + 4, i + 4)] += q22;
        }
    }

    /// Corrects with a measured box (`H = [I 0]`): `S = P11 + R`, `K = P[:, :4] S^-1`,
    /// `x += K (z - x[:4])`, `P -= K P[:4, :]`, symmetrised.
    pub fn update(&mut self, b: &PixelBox) {
        let z = box_to_m(b);
        let sd = self.noise.meas * self.x[3].max(1.0);
        let y = z - self.x.fixed_rows::<4>(0);
        let s = self.p.fixed_view::<4, 4>(0, 0) + SMatrix::<f64, 4, 4>::from_diagonal_element(sd * sd);
        let Some(si) = s.cholesky().map(|c| c.inverse()) else { return };
        let pht: SMatrix<f64, 8, 4> = self.p.fixed_columns::<4>(0).into_owned();
        let k = pht * si;
        self.x += k * y;
        let hp: SMatrix<f64, 4, 8> = self.p.fixed_rows::<4>(0).into_owned();
        self.p -= k * hp;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// Current box estimate.
    pub fn bbox(&self) -> PixelBox {
        PixelBox::new(self.x[0] - self.x[2] / 2.0, self.x[1] - self.x[3] / 2.0, self.x[2], self.x[3])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sort_box_round_trip() {
        let b = PixelBox::new(10.0, 20.0, 30.0, 60.0);
        let z = box_to_z(&b);
        let back = z_to_box(z[0], z[1], z[2], z[3]);
        assert!((back.x - b.x).abs() < 1e-9 && (back.w - b.w).abs() < 1e-9 && (back.h - b.h).abs() < 1e-9);
    }
}
