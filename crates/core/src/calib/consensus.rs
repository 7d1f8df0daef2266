//! Whether the references agree with each other, judged against the measurement noise the user
//! states (`--click-px`, `--tape-m`) carried through the fitted camera, not against a fixed pixel
//! limit: without intrinsics a reference far from the others is predicted with an uncertainty of
//! many pixels from 1 px clicks alone, with intrinsics a fraction of one.
//!
//! Noise model: each marked pixel is off by `click` px per axis and each measured face centre by
//! `tape` m per axis (independent, Gaussian), so reference j's pixel has covariance
//! `S_j = click^2 I + tape^2 Jw_j Jw_j^T` (`Jw_j` = d pixel / d world point, 2x3). A camera fitted to
//! a set of references has parameter covariance `C = (sum_j Jt_j^T S_j^-1 Jt_j)^-1` (`Jt_j` = d pixel /
//! d camera parameters: the pose, plus `f`, `cx`, `cy` when estimated; Gauss-Newton linearisation,
//! H&Z sec. 5.2.3), and predicts a reference i left out of the fit with covariance
//! `Jt_i C Jt_i^T + S_i`. Its Mahalanobis distance squared is then chi-square with 2 degrees of
//! freedom, and the weighted residual sum of a fit of n references chi-square with `2n - p`.

use super::{CalibError, Options, Reference, Solution, pnp};
use nalgebra::{DMatrix, Matrix2, Vector2, Vector3};

/// False-alarm rate of the leave-one-out test, per reference. A calibration tests every one of
/// its (up to ten or so) references, so with 1e-4 a box of ten good references is refused about
/// once in a thousand commissionings, and the 50 random cameras of 6-10 references the tests run
/// (400 references) see a false alarm with probability about 4% even when the stated noise is the
/// true noise (the default `--click-px` of 1.5 is above a careful click, which lowers that
/// further). On the synthetic cameras of docs/calibration.md, 1e-3 refused 1-2 good sets in 50
/// while 1e-5 named no more moved references than 1e-4: the misses are moves the fitted intrinsics
/// absorb, not ones just under the threshold (4.3 sigma here).
pub const NAME_FALSE_ALARM: f64 = 1e-4;

/// One-sided standard normal quantile of the fit checks' false-alarm rate, 1e-4: a set of
/// references whose weighted residual sum exceeds its chi-square quantile at this rate is not
/// explained by the stated noise.
const FIT_Z: f64 = 3.719;

/// The upper `alpha` quantile of chi-square with 2 degrees of freedom (exact: `-2 ln alpha`).
pub fn chi2_2_quantile(alpha: f64) -> f64 {
    -2.0 * alpha.ln()
}

/// The upper quantile of chi-square with `dof` degrees of freedom at the standard normal quantile
/// `z` (Wilson & Hilferty, PNAS 1931; within a few percent from one degree of freedom up).
pub fn chi2_quantile(dof: usize, z: f64) -> f64 {
    let k = dof.max(1) as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).max(0.0).powi(3)
}

/// The chi-square limit on a fit's weighted residual sum with `dof` degrees of freedom.
pub fn fit_limit(dof: usize) -> f64 {
    chi2_quantile(dof, FIT_Z)
}

/// Reference `r`'s pixel covariance under `cam` from the stated noise; `None` behind the camera.
pub fn pixel_covariance(cam: &crate::geometry::Camera, r: &Reference, opts: &Options) -> Option<Matrix2<f64>> {
    opts.noise().pixel_covariance(cam, &r.world.0)
}

/// Marked minus projected pixel; `None` behind the camera.
fn miss(cam: &crate::geometry::Camera, r: &Reference) -> Option<Vector2<f64>> {
    let p = cam.world_to_pixel(&r.world).ok()?;
    Some(Vector2::new(r.pixel.u - p.u, r.pixel.v - p.v))
}

/// `e^T S^-1 e` (infinite when `S` is singular).
fn mahalanobis2(e: &Vector2<f64>, s: &Matrix2<f64>) -> f64 {
    s.try_inverse().map_or(f64::INFINITY, |inv| (e.transpose() * inv * e)[(0, 0)])
}

/// The weighted residual sum `sum_j e_j^T S_j^-1 e_j` of `refs` under `cam` (infinite when one is
/// behind the camera), and its degrees of freedom (`2n` minus the parameters fitted).
pub fn fit_chi2(cam: &crate::geometry::Camera, refs: &[Reference], estimate_k: bool, opts: &Options) -> (f64, usize) {
    let dof = (2 * refs.len()).saturating_sub(pnp::parameter_count(estimate_k));
    let chi2 = refs
        .iter()
        .map(|r| match (miss(cam, r), pixel_covariance(cam, r, opts)) {
            (Some(e), Some(s)) => mahalanobis2(&e, &s),
            _ => f64::INFINITY,
        })
        .sum();
    (chi2, dof)
}

/// The fewest references the leave-one-out test runs on: the others must over-determine the
/// camera (with intrinsics four others, 8 equations for 6 unknowns; without, six others, 12 for 9).
pub fn min_references(estimate_k: bool) -> usize {
    if estimate_k { 7 } else { 5 }
}

/// Leave-one-out consensus: each reference predicted by the camera refined (from the full
/// solution) on all the others, by the same maximum-likelihood fit as the full solution
/// ([`pnp::refine_ml`]; solved afresh too when the others do not fit from there). A reference is a candidate when its others fit within the stated noise
/// (weighted residual sum under [`fit_limit`]) and its Mahalanobis distance squared exceeds the
/// chi-square(2) quantile at [`NAME_FALSE_ALARM`]; of the candidates, the one whose others fit best
/// (smallest weighted residual sum) is named. Not the one most sigmas off: without intrinsics a
/// moved reference pulls the fitted camera so far that a good one left out can miss by more, while
/// only the set without the moved one is consistent. With fewer than [`min_references`], nothing
/// can be named.
pub fn consensus(refs: &[Reference], sol: &Solution, opts: &Options) -> Option<CalibError> {
    let est = sol.estimated_intrinsics;
    if refs.len() < min_references(est) {
        return None;
    }
    let limit = chi2_2_quantile(NAME_FALSE_ALARM);
    // (index, distance squared, miss px, sigma px along the miss, others' RMS px, others' chi-square)
    let mut worst: Option<(usize, f64, f64, f64, f64, f64)> = None;
    for i in 0..refs.len() {
        let others: Vec<Reference> = refs.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, r)| r.clone()).collect();
        let w: Vec<Vector3<f64>> = others.iter().map(|r| r.world.0).collect();
        let px: Vec<crate::geometry::Pixel> = others.iter().map(|r| r.pixel).collect();
        let mut cam = pnp::refine_ml(&sol.camera, &w, &px, est, &opts.noise());
        let (mut chi2, dof) = fit_chi2(&cam, &others, est, opts);
        if chi2.is_nan() || chi2 > fit_limit(dof) {
            // A moved reference can pull the full solution (focal length and principal point
            // too) into a basin the others' optimum is not reached from: solve them afresh.
            let k = (!est).then_some(sol.camera.intrinsics);
            if let Ok(fresh) = super::solve_once(&others, k.as_ref(), opts) {
                let (c, _) = fit_chi2(&fresh.camera, &others, est, opts);
                if c < chi2 {
                    cam = fresh.camera;
                    chi2 = c;
                }
            }
        }
        if chi2.is_nan() || chi2 > fit_limit(dof) {
            continue;
        }
        let Some(info) = information(&cam, &others, est, opts) else { continue };
        let Some(c) = info.try_inverse() else { continue };
        let (d2, e_px) = match (miss(&cam, &refs[i]), pixel_covariance(&cam, &refs[i], opts)) {
            (Some(e), Some(s)) => {
                let Some(jt) = pnp::parameter_jacobian(&cam, &[refs[i].world.0], est) else { continue };
                let p = &jt * c * jt.transpose();
                let pred = s + Matrix2::new(p[(0, 0)], p[(0, 1)], p[(1, 0)], p[(1, 1)]);
                (mahalanobis2(&e, &pred), e.norm())
            }
            _ => (f64::INFINITY, f64::INFINITY),
        };
        if d2 > limit && worst.is_none_or(|(.., wchi2)| chi2 < wchi2) {
            let (_, rms) = super::residuals(&cam, &others);
            worst = Some((i, d2, e_px, e_px / d2.sqrt(), rms, chi2));
        }
    }
    worst.map(|(i, d2, error_px, sigma_px, others_rms_px, _)| CalibError::Outlier {
        label: refs[i].label(),
        error_px,
        sigmas: d2.sqrt(),
        sigma_px,
        others_rms_px,
    })
}

/// `sum_j Jt_j^T S_j^-1 Jt_j` over `refs` (the inverse of the parameter covariance).
fn information(cam: &crate::geometry::Camera, refs: &[Reference], est: bool, opts: &Options) -> Option<DMatrix<f64>> {
    let n = pnp::parameter_count(est);
    let w: Vec<Vector3<f64>> = refs.iter().map(|r| r.world.0).collect();
    let jt = pnp::parameter_jacobian(cam, &w, est)?;
    let mut info = DMatrix::zeros(n, n);
    for (j, r) in refs.iter().enumerate() {
        let s_inv = pixel_covariance(cam, r, opts)?.try_inverse()?;
        let rows = jt.rows(2 * j, 2);
        info += rows.transpose() * DMatrix::from_column_slice(2, 2, s_inv.as_slice()) * rows;
    }
    Some(info)
}
