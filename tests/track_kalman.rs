//! Kalman predict/update numerics against hand-derived values.

use fme::geometry::PixelBox;
use fme::track::kalman::{CvKalman, CvNoise, SortKalman};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

#[test]
fn sort_filter_matches_filterpy_by_hand() {
    // Box centre (20, 40), area 400 (20 x 20), aspect 1.
    let mut k = SortKalman::new(&PixelBox::new(10.0, 30.0, 20.0, 20.0));
    k.predict(1.0);
    // P = F P0 F' + Q: position variance 10 + 1e4 + 1, cross term 1e4, velocity 1e4 + 0.01.
    assert!(close(k.p[(0, 0)], 10011.0, 1e-12));
    assert!(close(k.p[(0, 4)], 1e4, 1e-12));
    assert!(close(k.p[(4, 4)], 10000.01, 1e-12));
    assert!(close(k.p[(6, 6)], 10000.0001, 1e-12));
    assert!(close(k.p[(3, 3)], 11.0, 1e-12));
    // Measure the centre 10 px to the right.
    k.update(&PixelBox::new(20.0, 30.0, 20.0, 20.0));
    let s = 10011.0 + 1.0;
    assert!(close(k.x[0], 20.0 + 10.0 * 10011.0 / s, 1e-12), "{}", k.x[0]);
    assert!(close(k.x[4], 10.0 * 1e4 / s, 1e-12), "{}", k.x[4]);
    // Joseph form equals (I - KH) P for the optimal gain: P00 = 10011 * 1 / s.
    assert!(close(k.p[(0, 0)], 10011.0 / s, 1e-9), "{}", k.p[(0, 0)]);
    assert!(close(k.x[1], 40.0, 1e-12));
}

#[test]
fn sort_area_velocity_clamp() {
    let mut k = SortKalman::new(&PixelBox::new(0.0, 0.0, 10.0, 10.0));
    k.x[6] = -150.0; // s + ds = -50 <= 0
    k.predict(1.0);
    assert_eq!(k.x[6], 0.0);
    assert_eq!(k.x[2], 100.0);
}

#[test]
fn cv_filter_learns_velocity_and_uses_real_dt() {
    let noise = CvNoise::default();
    let mut k = CvKalman::new(&PixelBox::new(0.0, 0.0, 20.0, 40.0), noise);
    // Moves at 60 px/s in x, sampled at 10 Hz.
    for i in 1..40 {
        let t = i as f64 * 0.1;
        k.predict(0.1);
        k.update(&PixelBox::new(60.0 * t, 0.0, 20.0, 40.0));
    }
    assert!(close(k.x[4], 60.0, 0.02), "vx {}", k.x[4]);
    // Half a second ahead the centre moves 30 px, whatever the detection rate was.
    let cx = k.x[0];
    let var0 = k.p[(0, 0)];
    k.predict(0.5);
    assert!((k.x[0] - cx - 30.0).abs() < 1.0, "{}", k.x[0] - cx);
    assert!(k.p[(0, 0)] > var0, "uncertainty must grow");
    // A zero or negative dt is a no-op.
    let before = k;
    k.predict(0.0);
    k.predict(-1.0);
    assert_eq!(before, k);
}

#[test]
fn cv_block_formulas_equal_the_dense_kalman_equations() {
    use nalgebra::{SMatrix, SVector};
    let mut k = CvKalman::new(&PixelBox::new(5.0, 7.0, 30.0, 50.0), CvNoise::default());
    // A full, symmetric positive definite covariance and a non-zero velocity.
    let a = SMatrix::<f64, 8, 8>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 * 0.3 + if i == j { 4.0 } else { 0.0 });
    k.p = a * a.transpose();
    k.x = SVector::<f64, 8>::from([20.0, 32.0, 30.0, 50.0, 3.0, -2.0, 0.5, 0.1]);
    let (x0, p0) = (k.x, k.p);
    let dt = 0.07;
    k.predict(dt);
    let mut f = SMatrix::<f64, 8, 8>::identity();
    for i in 0..4 {
        f[(i, i + 4)] = dt;
    }
    let q = (k.noise.accel * x0[3]).powi(2); // noise scaled by the height before the step
    let mut qm = SMatrix::<f64, 8, 8>::zeros();
    for i in 0..4 {
        qm[(i, i)] = q * dt.powi(4) / 4.0;
        qm[(i, i + 4)] = q * dt.powi(3) / 2.0;
        qm[(i + 4, i)] = q * dt.powi(3) / 2.0;
        qm[(i + 4, i + 4)] = q * dt * dt;
    }
    let xp = f * x0;
    let pp = f * p0 * f.transpose() + qm;
    assert!((k.x - xp).norm() < 1e-9);
    assert!((k.p - pp).norm() < 1e-6 * pp.norm(), "{}", (k.p - pp).norm());
    // Update: dense Kalman gain with H = [I 0].
    let z = PixelBox::new(6.0, 8.0, 31.0, 49.0);
    let mut h = SMatrix::<f64, 4, 8>::zeros();
    for i in 0..4 {
        h[(i, i)] = 1.0;
    }
    let sd = k.noise.meas * k.x[3];
    let r = SMatrix::<f64, 4, 4>::from_diagonal_element(sd * sd);
    let zm = nalgebra::Vector4::new(z.x + z.w / 2.0, z.y + z.h / 2.0, z.w, z.h);
    let s = h * pp * h.transpose() + r;
    let kg = pp * h.transpose() * s.try_inverse().expect("invertible");
    let xu = k.x + kg * (zm - h * k.x);
    let pu = (SMatrix::<f64, 8, 8>::identity() - kg * h) * pp;
    k.update(&z);
    assert!((k.x - xu).norm() < 1e-9);
    assert!((k.p - pu).norm() < 1e-6 * pu.norm());
}
