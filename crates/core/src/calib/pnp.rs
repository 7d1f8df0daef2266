//! Perspective-n-point: the camera pose (and, optionally, the focal length and principal point) from
//! known world points and the pixels where they appear.
//!
//! Two linear starts and one refinement:
//! - [`dlt`]: the normalised Direct Linear Transform (Hartley & Zisserman, *Multiple View Geometry*,
//!   2nd ed., sec. 7.1, algorithm 7.1) for six or more non-coplanar points. With known intrinsics
//!   it runs on undistorted normalised coordinates and the left 3x3 block is projected onto the
//!   nearest rotation; without, the 3x4 matrix is split into `K [R | t]` by an RQ decomposition
//!   (H&Z sec. 6.2.4).
//! - [`planar`]: a homography from the points' best-fit plane to normalised coordinates, decomposed
//!   into a pose (Zhang, "A flexible new technique for camera calibration", PAMI 2000, sec. 3.1);
//!   exact for coplanar points, an approximate start for four or five points that are not.
//! - [`sampled_starts`]: rotation sampling with the translation solved linearly, the fallback start
//!   when the others do not reach the data (few points off a plane).
//! - [`refine`]: Levenberg-Marquardt (Marquardt 1963; H&Z appendix A6.2) on the reprojection error
//!   in pixels through [`Intrinsics::project`] (distortion included). The rotation is updated by a
//!   local axis-angle increment `R <- exp([w]x) R`, so there is no singularity at any attitude.
//! - [`refine_ml`]: the same on the whitened residuals `L_j^-1 r_j` (`S_j = L_j L_j^T` the pixel
//!   covariance of reference j under the stated click and tape noise, see [`Noise`]), re-weighted
//!   from the current camera between passes: the maximum-likelihood camera under that noise. Tape
//!   error on a near reference is several pixels and on a far one a fraction of one, so equal
//!   pixel weights let the near ones pull the pose.

use crate::geometry::{Camera, Intrinsics, Pixel, Pose};
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Matrix3x4, Rotation3, Vector3};

/// Hartley's isotropic normalisation of 2D points: centroid to the origin, mean distance sqrt(2).
/// Returns the transform `T` (3x3) and the transformed points.
fn normalise_2d(p: &[(f64, f64)]) -> (Matrix3<f64>, Vec<(f64, f64)>) {
    let n = p.len() as f64;
    let (mx, my) = p.iter().fold((0.0, 0.0), |(a, b), &(x, y)| (a + x / n, b + y / n));
    let mean_d = p.iter().map(|&(x, y)| ((x - mx).powi(2) + (y - my).powi(2)).sqrt()).sum::<f64>() / n;
    let s = if mean_d > 1e-12 { std::f64::consts::SQRT_2 / mean_d } else { 1.0 };
    let t = Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0);
    (t, p.iter().map(|&(x, y)| (s * (x - mx), s * (y - my))).collect())
}

/// The 3D counterpart of [`normalise_2d`]: mean distance sqrt(3). Returns `(scale, centroid)`.
fn normalise_3d(p: &[Vector3<f64>]) -> (f64, Vector3<f64>) {
    let n = p.len() as f64;
    let c = p.iter().fold(Vector3::zeros(), |a, q| a + q / n);
    let mean_d = p.iter().map(|q| (q - c).norm()).sum::<f64>() / n;
    let s = if mean_d > 1e-12 { 3f64.sqrt() / mean_d } else { 1.0 };
    (s, c)
}

/// The right singular vector of the smallest singular value (the least-squares null vector).
fn null_vector(a: DMatrix<f64>) -> Option<DVector<f64>> {
    let cols = a.ncols();
    // Pad to at least as many rows as columns so V^T is complete.
    let a = if a.nrows() < cols { a.resize_vertically(cols, 0.0) } else { a };
    let svd = a.svd(false, true);
    let vt = svd.v_t?;
    let (k, _) = svd.singular_values.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    Some(vt.row(k).transpose())
}

/// The rotation nearest to `m` in the Frobenius norm (`U V^T` of its SVD, determinant +1).
pub fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        r = u * d * vt;
    }
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Normalised DLT: the 3x4 matrix `P` with `img ~ P [X; 1]` for six or more points, in the units of
/// `img` (pixels, or normalised coordinates when the intrinsics are known).
pub fn dlt(world: &[Vector3<f64>], img: &[(f64, f64)]) -> Option<Matrix3x4<f64>> {
    if world.len() < 6 || world.len() != img.len() {
        return None;
    }
    let (t2, q) = normalise_2d(img);
    let (s3, c3) = normalise_3d(world);
    let mut a = DMatrix::zeros(2 * world.len(), 12);
    for (i, (w, &(u, v))) in world.iter().zip(&q).enumerate() {
        let x = (w - c3) * s3;
        let xh = [x.x, x.y, x.z, 1.0];
        for j in 0..4 {
            a[(2 * i, 4 + j)] = -xh[j];
            a[(2 * i, 8 + j)] = v * xh[j];
            a[(2 * i + 1, j)] = xh[j];
            a[(2 * i + 1, 8 + j)] = -u * xh[j];
        }
    }
    let h = null_vector(a)?;
    let pn = Matrix3x4::from_fn(|r, c| h[4 * r + c]);
    // Undo the normalisations: P = T2^-1 Pn T3.
    let mut t3 = nalgebra::Matrix4::identity() * s3;
    t3[(3, 3)] = 1.0;
    for k in 0..3 {
        t3[(k, 3)] = -s3 * c3[k];
    }
    let p = t2.try_inverse()? * pn * t3;
    p.iter().all(|v| v.is_finite()).then_some(p)
}

/// A pose from a DLT matrix in normalised coordinates (`P ~ [R | t]`).
pub fn pose_from_normalised_dlt(p: &Matrix3x4<f64>) -> Option<Pose> {
    let mut p = *p;
    let m = p.fixed_view::<3, 3>(0, 0).into_owned();
    if m.determinant() < 0.0 {
        p = -p;
    }
    let m = p.fixed_view::<3, 3>(0, 0).into_owned();
    let r = nearest_rotation(&m)?;
    let scale = m.svd(false, false).singular_values.mean();
    if scale.is_nan() || scale <= 1e-12 {
        return None;
    }
    let t = p.column(3).into_owned() / scale;
    Pose::new(r, t).ok()
}

/// `K [R | t]` from a DLT matrix in pixels by RQ decomposition; `K` is reduced to `fx = fy` (their
/// mean), `cx`, `cy`, no skew and no distortion.
pub fn camera_from_pixel_dlt(p: &Matrix3x4<f64>) -> Option<Camera> {
    let mut p = *p;
    if p.fixed_view::<3, 3>(0, 0).determinant() < 0.0 {
        p = -p;
    }
    let m = p.fixed_view::<3, 3>(0, 0).into_owned();
    // RQ via QR of the row-reversed transpose: with J the anti-identity, (J M)^T = Q' R' gives
    // M = (J R'^T J) (J Q'^T), an upper-triangular times an orthonormal matrix.
    let j = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let qr = (j * m).transpose().qr();
    let (q, r) = (qr.q(), qr.r());
    let mut k = j * r.transpose() * j;
    let mut rot = j * q.transpose();
    let d = Matrix3::from_diagonal(&Vector3::new(k[(0, 0)].signum(), k[(1, 1)].signum(), k[(2, 2)].signum()));
    k *= d;
    rot = d * rot;
    if rot.determinant() < 0.0 {
        return None;
    }
    let lambda = k[(2, 2)];
    if lambda.is_nan() || lambda.abs() <= 1e-12 {
        return None;
    }
    let kn = k / lambda;
    let t = kn.try_inverse()? * p.column(3).into_owned() / lambda;
    let f = 0.5 * (kn[(0, 0)] + kn[(1, 1)]);
    let intrinsics = Intrinsics { fx: f, fy: f, cx: kn[(0, 2)], cy: kn[(1, 2)], distortion: [0.0; 5] };
    intrinsics.validate().ok()?;
    let rot = nearest_rotation(&rot)?;
    Some(Camera { intrinsics, pose: Pose::new(rot, t).ok()? })
}

/// The best-fit plane of the points: centroid, orthonormal basis (columns: two in-plane axes, then
/// the normal) and the three singular values of the centred points (largest first). The last over
/// the first measures non-coplanarity; the second over the first, non-collinearity.
pub fn plane_fit(world: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>, [f64; 3]) {
    let n = world.len().max(1) as f64;
    let c = world.iter().fold(Vector3::zeros(), |a, q| a + q / n);
    let mut cov = Matrix3::zeros();
    for q in world {
        let d = q - c;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let e1 = eig.eigenvectors.column(idx[0]).into_owned();
    let e2 = eig.eigenvectors.column(idx[1]).into_owned();
    let basis = Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]);
    let sv = idx.map(|i| eig.eigenvalues[i].max(0.0).sqrt());
    (c, basis, sv)
}

/// A pose from points (treated as lying on their best-fit plane) and their undistorted normalised
/// image coordinates, through the plane-to-image homography (Zhang 2000, sec. 3.1). Needs four.
pub fn planar(world: &[Vector3<f64>], img: &[(f64, f64)]) -> Option<Pose> {
    if world.len() < 4 || world.len() != img.len() {
        return None;
    }
    let (c, basis, _) = plane_fit(world);
    let plane: Vec<(f64, f64)> = world
        .iter()
        .map(|q| {
            let d = basis.transpose() * (q - c);
            (d.x, d.y)
        })
        .collect();
    let (ta, a) = normalise_2d(&plane);
    let (tb, b) = normalise_2d(img);
    let mut m = DMatrix::zeros(2 * world.len(), 9);
    for (i, (&(x, y), &(u, v))) in a.iter().zip(&b).enumerate() {
        let xh = [x, y, 1.0];
        for j in 0..3 {
            m[(2 * i, 3 + j)] = -xh[j];
            m[(2 * i, 6 + j)] = v * xh[j];
            m[(2 * i + 1, j)] = xh[j];
            m[(2 * i + 1, 6 + j)] = -u * xh[j];
        }
    }
    let h = null_vector(m)?;
    let hn = Matrix3::from_fn(|r, col| h[3 * r + col]);
    let hm = tb.try_inverse()? * hn * ta;
    let (h1, h2, h3) = (hm.column(0).into_owned(), hm.column(1).into_owned(), hm.column(2).into_owned());
    let mut lambda = 2.0 / (h1.norm() + h2.norm());
    if !lambda.is_finite() {
        return None;
    }
    // The plane's origin (the centroid) must be in front of the camera.
    if h3.z < 0.0 {
        lambda = -lambda;
    }
    let r1 = h1 * lambda;
    let r2 = h2 * lambda;
    let rp = nearest_rotation(&Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]))?;
    let tp = h3 * lambda;
    // p_cam = Rp B^T (p - c) + tp  =>  R = Rp B^T, t = tp - R c.
    let r = rp * basis.transpose();
    Pose::new(r, tp - r * c).ok()
}

/// Starting poses by rotation sampling, for when the linear starts do not apply (four or five
/// references that are not coplanar): for each of `count` seeded uniformly random rotations (unit
/// quaternions from four normal deviates, Shoemake 1992) the translation follows linearly from
/// `x_i (r3 X_i + t_z) = r1 X_i + t_x`, `y_i (r3 X_i + t_z) = r2 X_i + t_y` (least squares); the `keep`
/// rotations with every point in front and the smallest error in normalised coordinates are
/// returned, best first, for [`refine`] to finish.
pub fn sampled_starts(world: &[Vector3<f64>], img: &[(f64, f64)], count: usize, keep: usize) -> Vec<Pose> {
    let mut rng = crate::rng::Rng::new(0x0ca1_1b7a);
    let mut best: Vec<(f64, Pose)> = Vec::with_capacity(keep + 1);
    for _ in 0..count {
        let q = nalgebra::Quaternion::new(rng.normal(), rng.normal(), rng.normal(), rng.normal());
        let Some(uq) = nalgebra::UnitQuaternion::try_new(q, 1e-9) else { continue };
        let r = uq.to_rotation_matrix().into_inner();
        let mut ata = Matrix3::<f64>::zeros();
        let mut atb = Vector3::<f64>::zeros();
        for (w, &(x, y)) in world.iter().zip(img) {
            let rw = r * w;
            // Rows [1, 0, -x] . t = x rw.z - rw.x and [0, 1, -y] . t = y rw.z - rw.y.
            for (row, b) in
                [(Vector3::new(1.0, 0.0, -x), x * rw.z - rw.x), (Vector3::new(0.0, 1.0, -y), y * rw.z - rw.y)]
            {
                ata += row * row.transpose();
                atb += row * b;
            }
        }
        let Some(t) = ata.try_inverse().map(|inv| inv * atb) else { continue };
        let mut cost = 0.0;
        let mut front = true;
        for (w, &(x, y)) in world.iter().zip(img) {
            let c = r * w + t;
            if c.z <= 1e-6 {
                front = false;
                break;
            }
            cost += (c.x / c.z - x).powi(2) + (c.y / c.z - y).powi(2);
        }
        if !front || !cost.is_finite() {
            continue;
        }
        if best.len() < keep || cost < best[best.len() - 1].0 {
            best.push((cost, Pose { rotation: r, translation: t }));
            best.sort_by(|a, b| a.0.total_cmp(&b.0));
            best.truncate(keep);
        }
    }
    best.into_iter().map(|(_, p)| p).collect()
}

/// Pixel residuals `projected - measured` (u then v per point), each pre-multiplied by its
/// whitening matrix when `weights` are given; a point behind the camera costs a large constant so
/// the optimiser moves away from it.
fn residuals(
    cam: &Camera,
    world: &[Vector3<f64>],
    px: &[Pixel],
    weights: Option<&[Matrix2<f64>]>,
    out: &mut DVector<f64>,
) {
    for (i, (w, m)) in world.iter().zip(px).enumerate() {
        let (du, dv) = match cam.intrinsics.project(&cam.pose.to_camera(&crate::geometry::WorldPoint(*w))) {
            Ok(p) => (p.u - m.u, p.v - m.v),
            Err(_) => (1e4, 1e4),
        };
        let r = match weights.and_then(|ws| ws.get(i)) {
            Some(wm) => wm * nalgebra::Vector2::new(du, dv),
            None => nalgebra::Vector2::new(du, dv),
        };
        out[2 * i] = r.x;
        out[2 * i + 1] = r.y;
    }
}

/// The stated measurement noise: each marked pixel off by `click_px` per axis and each measured
/// face centre by `tape_m` per axis (independent, Gaussian).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Pixels per axis (standard deviation).
    pub click_px: f64,
    /// Metres per axis (standard deviation).
    pub tape_m: f64,
}

impl Noise {
    /// Pixel covariance of a reference at `world` under `cam`: `click^2 I + tape^2 Jw Jw^T`;
    /// `None` when it is at or behind the camera.
    pub fn pixel_covariance(&self, cam: &Camera, world: &Vector3<f64>) -> Option<Matrix2<f64>> {
        let jw = world_jacobian(cam, world)?;
        Some(Matrix2::identity() * self.click_px.powi(2) + jw * jw.transpose() * self.tape_m.powi(2))
    }

    /// Whitening matrices `L_j^-1` (`S_j = L_j L_j^T`) of the points under `cam`, so that
    /// `|L_j^-1 r_j|^2 = r_j^T S_j^-1 r_j`. A point behind the camera gets the click noise alone.
    pub fn whitening(&self, cam: &Camera, world: &[Vector3<f64>]) -> Vec<Matrix2<f64>> {
        let click = Matrix2::identity() / self.click_px.max(1e-12);
        world
            .iter()
            .map(|w| {
                self.pixel_covariance(cam, w)
                    .and_then(|s| s.cholesky())
                    .and_then(|c| c.l().try_inverse())
                    .filter(|m| m.iter().all(|v| v.is_finite()))
                    .unwrap_or(click)
            })
            .collect()
    }

    /// The weighted residual sum `sum_j r_j^T S_j^-1 r_j` of the points under `cam` (infinite
    /// when one is behind it).
    pub fn chi2(&self, cam: &Camera, world: &[Vector3<f64>], px: &[Pixel]) -> f64 {
        world
            .iter()
            .zip(px)
            .map(|(w, m)| {
                let (Ok(p), Some(s)) =
                    (cam.world_to_pixel(&crate::geometry::WorldPoint(*w)), self.pixel_covariance(cam, w))
                else {
                    return f64::INFINITY;
                };
                let e = nalgebra::Vector2::new(m.u - p.u, m.v - p.v);
                s.try_inverse().map_or(f64::INFINITY, |inv| (e.transpose() * inv * e)[(0, 0)])
            })
            .sum()
    }
}

/// Passes of [`refine_ml`]: each re-evaluates the weights at the camera of the one before (the
/// pixel covariances change little once the pose is within centimetres, so three settle them).
const ML_PASSES: usize = 3;

/// Maximum-likelihood refinement under `noise`: [`refine`] on the whitened residuals, the
/// whitening re-evaluated from the current camera before each of [`ML_PASSES`] passes.
pub fn refine_ml(start: &Camera, world: &[Vector3<f64>], px: &[Pixel], estimate_k: bool, noise: &Noise) -> Camera {
    let mut cam = *start;
    for _ in 0..ML_PASSES {
        let w = noise.whitening(&cam, world);
        cam = refine_weighted(&cam, world, px, estimate_k, Some(&w));
    }
    cam
}

/// The camera after applying parameter increment `d` (`[w(3), dt(3), df, dcx, dcy]`) to `cam`.
fn apply(cam: &Camera, d: &[f64]) -> Camera {
    let w = Vector3::new(d[0], d[1], d[2]);
    let r = Rotation3::from_scaled_axis(w).into_inner() * cam.pose.rotation;
    let t = cam.pose.translation + Vector3::new(d[3], d[4], d[5]);
    let mut k = cam.intrinsics;
    if d.len() == 9 {
        k.fx += d[6];
        k.fy += d[6];
        k.cx += d[7];
        k.cy += d[8];
    }
    Camera { intrinsics: k, pose: Pose { rotation: r, translation: t } }
}

/// The number of camera parameters [`refine`] adjusts: the pose (6), plus `fx = fy`, `cx`, `cy`.
pub fn parameter_count(estimate_k: bool) -> usize {
    if estimate_k { 9 } else { 6 }
}

/// d pixel / d camera parameters (rows u then v per point; columns as [`refine`]'s increments:
/// rotation, translation, then `f`, `cx`, `cy` with `estimate_k`) by central differences. `None`
/// when a point is at or behind the camera.
pub fn parameter_jacobian(cam: &Camera, world: &[Vector3<f64>], estimate_k: bool) -> Option<DMatrix<f64>> {
    let np = parameter_count(estimate_k);
    let mut j = DMatrix::zeros(2 * world.len(), np);
    for k in 0..np {
        let h = if k < 6 { 1e-6 } else { 1e-4 };
        let mut d = [0.0; 9];
        d[k] = h;
        let plus = apply(cam, &d[..np]);
        d[k] = -h;
        let minus = apply(cam, &d[..np]);
        for (i, w) in world.iter().enumerate() {
            let p = plus.world_to_pixel(&crate::geometry::WorldPoint(*w)).ok()?;
            let m = minus.world_to_pixel(&crate::geometry::WorldPoint(*w)).ok()?;
            j[(2 * i, k)] = (p.u - m.u) / (2.0 * h);
            j[(2 * i + 1, k)] = (p.v - m.v) / (2.0 * h);
        }
    }
    Some(j)
}

/// d pixel / d world point (2x3) by central differences (1 mm steps); `None` when the point is at
/// or behind the camera.
pub fn world_jacobian(cam: &Camera, world: &Vector3<f64>) -> Option<nalgebra::Matrix2x3<f64>> {
    let h = 1e-3;
    let mut j = nalgebra::Matrix2x3::zeros();
    for k in 0..3 {
        let mut d = Vector3::zeros();
        d[k] = h;
        let p = cam.world_to_pixel(&crate::geometry::WorldPoint(world + d)).ok()?;
        let m = cam.world_to_pixel(&crate::geometry::WorldPoint(world - d)).ok()?;
        j[(0, k)] = (p.u - m.u) / (2.0 * h);
        j[(1, k)] = (p.v - m.v) / (2.0 * h);
    }
    Some(j)
}

/// Levenberg-Marquardt on the reprojection error in pixels. `estimate_k`: also refine `fx = fy`,
/// `cx`, `cy` (needs six or more non-coplanar points to be determined). Returns the refined camera
/// (the rotation re-orthonormalised).
pub fn refine(start: &Camera, world: &[Vector3<f64>], px: &[Pixel], estimate_k: bool) -> Camera {
    refine_weighted(start, world, px, estimate_k, None)
}

/// [`refine`] minimising `sum_j |W_j r_j|^2` with one 2x2 weight `W_j` per point (`None`: the
/// identity).
pub fn refine_weighted(
    start: &Camera,
    world: &[Vector3<f64>],
    px: &[Pixel],
    estimate_k: bool,
    weights: Option<&[Matrix2<f64>]>,
) -> Camera {
    let np = parameter_count(estimate_k);
    let nr = 2 * world.len();
    let mut cam = *start;
    let mut r = DVector::zeros(nr);
    residuals(&cam, world, px, weights, &mut r);
    let mut cost = r.norm_squared();
    let mut mu = 1e-3;
    let mut j = DMatrix::zeros(nr, np);
    let mut rp = DVector::zeros(nr);
    let mut rm = DVector::zeros(nr);
    for _ in 0..200 {
        // Central-difference Jacobian: steps of 1e-6 rad / 1e-6 m / 1e-4 px.
        for k in 0..np {
            let h = if k < 6 { 1e-6 } else { 1e-4 };
            let mut d = [0.0; 9];
            d[k] = h;
            residuals(&apply(&cam, &d[..np]), world, px, weights, &mut rp);
            d[k] = -h;
            residuals(&apply(&cam, &d[..np]), world, px, weights, &mut rm);
            j.set_column(k, &((&rp - &rm) / (2.0 * h)));
        }
        let jtj = j.transpose() * &j;
        let g = j.transpose() * &r;
        let mut improved = false;
        for _ in 0..30 {
            let mut a = jtj.clone();
            for k in 0..np {
                a[(k, k)] += mu * jtj[(k, k)].max(1e-9);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&g))) else {
                mu *= 10.0;
                continue;
            };
            let trial = apply(&cam, step.as_slice());
            residuals(&trial, world, px, weights, &mut rp);
            let c = rp.norm_squared();
            if c.is_finite() && c < cost {
                let small = step.norm() < 1e-12 || (cost - c) < 1e-14 * cost.max(1e-30);
                cam = trial;
                std::mem::swap(&mut r, &mut rp);
                cost = c;
                mu = (mu / 3.0).max(1e-12);
                improved = !small;
                break;
            }
            mu *= 4.0;
            if mu > 1e12 {
                break;
            }
        }
        if !improved {
            break;
        }
    }
    if let Some(rot) = nearest_rotation(&cam.pose.rotation) {
        cam.pose.rotation = rot;
    }
    cam
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::WorldPoint;

    fn truth() -> Camera {
        let k = Intrinsics::from_hfov(640, 384, 100.0).unwrap();
        let pose =
            Pose::look_at(WorldPoint::new(3.0, -0.4, 1.6), WorldPoint::new(3.0, 3.0, 0.8), Vector3::z()).unwrap();
        Camera { intrinsics: k, pose }
    }

    fn points(planar_only: bool) -> Vec<Vector3<f64>> {
        let mut v = vec![
            Vector3::new(1.2, 3.9, 1.2),
            Vector3::new(4.7, 3.9, 1.1),
            Vector3::new(4.8, 3.2, 0.05),
            Vector3::new(2.6, 1.5, 0.05),
            Vector3::new(3.35, 3.25, 0.05),
            Vector3::new(0.4, 2.8, 1.1),
            Vector3::new(1.5, 1.95, 0.05),
        ];
        if planar_only {
            for p in &mut v {
                p.z = 0.05;
            }
        }
        v
    }

    fn pixels(cam: &Camera, w: &[Vector3<f64>]) -> Vec<Pixel> {
        w.iter().map(|p| cam.world_to_pixel(&WorldPoint(*p)).unwrap()).collect()
    }

    #[test]
    fn dlt_and_planar_starts_recover_an_exact_pose() {
        let cam = truth();
        let w = points(false);
        let px = pixels(&cam, &w);
        let norm: Vec<_> =
            px.iter().map(|p| ((p.u - 320.0) / cam.intrinsics.fx, (p.v - 192.0) / cam.intrinsics.fy)).collect();
        let pose = pose_from_normalised_dlt(&dlt(&w, &norm).unwrap()).unwrap();
        assert!((pose.camera_center().0 - cam.pose.camera_center().0).norm() < 1e-6);
        let pix: Vec<_> = px.iter().map(|p| (p.u, p.v)).collect();
        let full = camera_from_pixel_dlt(&dlt(&w, &pix).unwrap()).unwrap();
        assert!((full.intrinsics.fx - cam.intrinsics.fx).abs() < 1e-4, "{:?}", full.intrinsics);
        assert!((full.pose.camera_center().0 - cam.pose.camera_center().0).norm() < 1e-6);
        let wp = points(true);
        let pxp = pixels(&cam, &wp);
        let normp: Vec<_> =
            pxp.iter().map(|p| ((p.u - 320.0) / cam.intrinsics.fx, (p.v - 192.0) / cam.intrinsics.fy)).collect();
        let pose = planar(&wp, &normp).unwrap();
        assert!((pose.camera_center().0 - cam.pose.camera_center().0).norm() < 1e-6, "{pose:?}");
    }

    #[test]
    fn refine_converges_from_a_perturbed_start() {
        let cam = truth();
        let w = points(false);
        let px = pixels(&cam, &w);
        let mut start = cam;
        start.pose.rotation =
            Rotation3::from_scaled_axis(Vector3::new(0.05, -0.04, 0.03)).into_inner() * start.pose.rotation;
        start.pose.translation += Vector3::new(0.2, -0.1, 0.3);
        start.intrinsics.fx *= 1.1;
        start.intrinsics.fy *= 1.1;
        let out = refine(&start, &w, &px, true);
        assert!((out.pose.camera_center().0 - cam.pose.camera_center().0).norm() < 1e-5, "{out:?}");
        assert!((out.intrinsics.fx - cam.intrinsics.fx).abs() < 1e-3);
    }
}
