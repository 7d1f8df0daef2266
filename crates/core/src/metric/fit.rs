//! Scale and shift fits of relative inverse depth to metric depth (paper eq. 1-2).

use super::MAX_REFERENCES;
use crate::units::Metres;

/// One reference object: the relative inverse depth sampled at its projected pixel, and its known
/// metric depth (camera z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePair {
    /// Relative inverse depth `R` sampled at the reference's pixel.
    pub relative: f64,
    /// Known depth `D` (camera z) of the reference point.
    pub depth: Metres,
}

/// The references of one frame, fixed capacity ([`MAX_REFERENCES`]).
pub type References = heapless::Vec<ReferencePair, MAX_REFERENCES>;

/// Which quantity is linear in the relative inverse depth `R`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthModel {
    /// The paper's eq. 2: `D = s*R + t`, least squares in metres (eq. 1). Since `R` grows as things
    /// get nearer, a valid fit has `s < 0`.
    Linear,
    /// `1/D = s*R + t` (MiDaS's disparity-space alignment), the physically consistent model for an
    /// affine-invariant inverse depth. Least squares on `1/D` weighted by `D^4`, which approximates
    /// squared depth error since `dD = D^2 d(1/D)`. A valid fit has `s > 0`.
    Inverse,
}

/// Why a fit cannot be used. The caller keeps its previous fit or flags the frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer than two usable references (finite values, positive depth).
    #[error("need at least {needed} usable reference objects, have {usable}")]
    TooFewReferences {
        /// References with finite values and positive depth.
        usable: usize,
        /// Minimum for this model.
        needed: usize,
    },
    /// A robust fit kept too few references that agree with it: a fish fit of scale and shift
    /// with no earlier shift to fit the scale alone at (fish.rs, `MIN_SHIFT_INLIERS`), or a
    /// scale-only fit on which no two references agree.
    #[error("the fit kept {inliers} agreeing references, it needs {needed}")]
    TooFewInliers {
        /// References within the fit's tolerance.
        inliers: usize,
        /// References needed.
        needed: usize,
    },
    /// The shift given to a scale-only fit is not a number.
    #[error("the shift to fit the scale at is not a finite number ({0})")]
    NonFiniteShift(f64),
    /// All references have (nearly) the same relative value, so the scale is undetermined.
    #[error("reference objects all have the same relative inverse depth ({0}); scale is undetermined")]
    DegenerateRelative(f64),
    /// The fitted scale has the wrong sign (depth would grow with inverse depth) or is zero.
    #[error("fitted scale s = {0} has the wrong sign for this model (depth must fall as inverse depth rises)")]
    WrongScaleSign(f64),
    /// The fit predicts a non-positive or non-finite depth at a reference it used.
    #[error("fit predicts a non-positive depth at a reference (relative inverse depth {0})")]
    NegativeDepth(f64),
    /// A fish fit puts the fish this many times as far as their sizes alone say (fish.rs,
    /// `MAX_OFF_SIZES`).
    #[error("fish fit puts the fish at {0:.2} times the depth their sizes give")]
    OffTheFishSizes(f64),
}

/// A fitted scale/shift model with its residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleShift {
    /// The model the coefficients belong to.
    pub model: DepthModel,
    /// Scale `s*`.
    pub s: f64,
    /// Shift `t*`.
    pub t: f64,
    /// Root mean square depth error over the references used, metres.
    pub residual_rms: Metres,
    /// Number of references used (inliers for the robust fit).
    pub used: usize,
    /// Bit `i` set: reference `i` was rejected as an outlier by [`fit_robust`].
    pub rejected: u32,
}

impl ScaleShift {
    /// Metric depth for a relative inverse depth value; `None` when the model gives a non-positive
    /// or non-finite depth there (never NaN).
    #[inline]
    pub fn depth(&self, relative: f64) -> Option<Metres> {
        let d = match self.model {
            DepthModel::Linear => self.s * relative + self.t,
            DepthModel::Inverse => {
                let inv = self.s * relative + self.t;
                if inv > 0.0 { 1.0 / inv } else { f64::NAN }
            }
        };
        (d.is_finite() && d > 0.0).then_some(Metres(d))
    }
}

/// How strongly an inverse fit's depth follows the relative value at the median of the pairs it
/// kept: `s r / (s r + t)`, the relative change of depth per relative change of `r` (1: no shift;
/// 40: the shift cancels 97 % of `s r`, and a 1 % error in `r` moves the depth by 40 %). NaN for the
/// linear model or without kept pairs.
pub fn depth_gain(f: &ScaleShift, pairs: &[ReferencePair]) -> f64 {
    if f.model != DepthModel::Inverse {
        return f64::NAN;
    }
    // `rejected` has a bit per pair of the fit's first MAX_REFERENCES (32), as `fit_robust` reads them.
    let mut r: heapless::Vec<f64, MAX_REFERENCES> = pairs
        .iter()
        .take(MAX_REFERENCES)
        .enumerate()
        .filter(|&(i, p)| usable(p) && f.rejected & (1 << i) == 0)
        .map(|(_, p)| p.relative)
        .collect();
    quantile(&mut r, 0.5).map_or(f64::NAN, |m| f.s * m / (f.s * m + f.t))
}

/// The `q` quantile of `values` (reordered; nearest rank); `None` when empty.
pub(crate) fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let k = ((values.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, v, _) = values.select_nth_unstable_by(k, f64::total_cmp);
    Some(*v)
}

/// A pair a fit can use: finite relative value, finite positive depth.
pub(crate) fn usable(p: &ReferencePair) -> bool {
    p.relative.is_finite() && p.depth.0.is_finite() && p.depth.0 > 0.0
}

/// Target and weight of one reference for the model's least squares.
#[inline]
fn target(model: DepthModel, p: &ReferencePair) -> (f64, f64) {
    match model {
        DepthModel::Linear => (p.depth.0, 1.0),
        DepthModel::Inverse => (1.0 / p.depth.0, p.depth.0.powi(4)),
    }
}

/// Weighted least squares over the references selected by `mask` (bit i = use reference i).
fn least_squares(model: DepthModel, refs: &[ReferencePair], mask: u32) -> Result<ScaleShift, FitError> {
    let sel = || refs.iter().enumerate().filter(move |(i, p)| mask & (1 << i) != 0 && usable(p)).map(|(_, p)| p);
    let n = sel().count();
    if n < 2 {
        return Err(FitError::TooFewReferences { usable: n, needed: 2 });
    }
    // Centre R for numerical stability.
    let (mut sw, mut swr) = (0.0, 0.0);
    for p in sel() {
        let (_, w) = target(model, p);
        sw += w;
        swr += w * p.relative;
    }
    let rm = swr / sw;
    let (mut srr, mut sry, mut sy) = (0.0, 0.0, 0.0);
    let mut spread: f64 = 0.0;
    for p in sel() {
        let (y, w) = target(model, p);
        let dr = p.relative - rm;
        srr += w * dr * dr;
        sry += w * dr * y;
        sy += w * y;
        spread = spread.max(dr.abs());
    }
    if spread <= 1e-12 * rm.abs().max(1.0) || srr <= 0.0 {
        return Err(FitError::DegenerateRelative(rm));
    }
    let s = sry / srr;
    let t = sy / sw - s * rm;
    finish(model, s, t, refs, mask)
}

/// Validates coefficients and computes the depth residual over the masked references.
fn finish(model: DepthModel, s: f64, t: f64, refs: &[ReferencePair], mask: u32) -> Result<ScaleShift, FitError> {
    let sign_ok = match model {
        DepthModel::Linear => s < 0.0,
        DepthModel::Inverse => s > 0.0,
    };
    if !s.is_finite() || !t.is_finite() || !sign_ok {
        return Err(FitError::WrongScaleSign(s));
    }
    let mut fit = ScaleShift { model, s, t, residual_rms: Metres(0.0), used: 0, rejected: 0 };
    let mut sse = 0.0;
    for (i, p) in refs.iter().enumerate() {
        if mask & (1 << i) == 0 || !usable(p) {
            continue;
        }
        let d = fit.depth(p.relative).ok_or(FitError::NegativeDepth(p.relative))?;
        sse += (d.0 - p.depth.0).powi(2);
        fit.used += 1;
    }
    fit.residual_rms = Metres((sse / fit.used.max(1) as f64).sqrt());
    Ok(fit)
}

fn all_mask(n: usize) -> u32 {
    if n >= 32 { u32::MAX } else { (1u32 << n) - 1 }
}

/// Default inlier tolerance of [`fit_robust`]: `max(0.1 m, 5% of the depth)`.
pub const ROBUST_INLIER: (Metres, f64) = (Metres(0.1), 0.05);

/// Least-squares fit of `model` over all usable references (paper eq. 1).
pub fn fit(model: DepthModel, refs: &[ReferencePair]) -> Result<ScaleShift, FitError> {
    least_squares(model, &refs[..refs.len().min(MAX_REFERENCES)], all_mask(refs.len()))
}

/// Robust fit: every pair of references defines an exact model (RANSAC's minimal sample, tried
/// exhaustively since there are few references, so the result is deterministic); the pair with the
/// most references within `max(inlier_abs, inlier_rel * D)` of their known depth wins (ties: lower
/// total error), then least squares on its inliers, repeated once on the refit's inliers.
/// Rejected references are reported in [`ScaleShift::rejected`]. With fewer than three usable
/// references this is the plain fit.
pub fn fit_robust(
    model: DepthModel,
    refs: &[ReferencePair],
    inlier_abs: Metres,
    inlier_rel: f64,
) -> Result<ScaleShift, FitError> {
    let refs = &refs[..refs.len().min(MAX_REFERENCES)];
    if refs.iter().filter(|p| usable(p)).count() < 3 {
        return fit(model, refs);
    }
    let pairs = (0..refs.len()).flat_map(|i| (i + 1..refs.len()).map(move |j| (1u32 << i) | (1 << j)));
    let samples = pairs.filter_map(|m| least_squares(model, refs, m).ok());
    consensus(refs, (inlier_abs, inlier_rel), samples, |mask| least_squares(model, refs, mask))
        .unwrap_or_else(|| fit(model, refs))
}

/// Robust fit of the inverse model's scale alone at a given shift `t` (`1/D = s*R + t`): every
/// reference gives its own scale `(1/D - t) / R`, then as [`fit_robust`] (the one with the most
/// inliers wins, weighted least squares on its inliers, repeated once). One parameter, so a single
/// reference checks it where a line through two references checks nothing.
pub fn fit_scale_at(
    t: f64,
    refs: &[ReferencePair],
    inlier_abs: Metres,
    inlier_rel: f64,
) -> Result<ScaleShift, FitError> {
    let refs = &refs[..refs.len().min(MAX_REFERENCES)];
    let n_usable = refs.iter().filter(|p| usable(p)).count();
    if n_usable < 2 {
        return Err(FitError::TooFewReferences { usable: n_usable, needed: 2 });
    }
    if !t.is_finite() {
        return Err(FitError::NonFiniteShift(t));
    }
    let scale_on = |mask: u32| -> Result<ScaleShift, FitError> {
        // Least squares on 1/D weighted by D^4, as `least_squares`, with the shift held.
        let (mut srr, mut sry) = (0.0, 0.0);
        for (i, p) in refs.iter().enumerate() {
            if mask & (1 << i) != 0 && usable(p) {
                let (y, w) = target(DepthModel::Inverse, p);
                srr += w * p.relative * p.relative;
                sry += w * p.relative * (y - t);
            }
        }
        if srr <= 0.0 {
            return Err(FitError::DegenerateRelative(0.0));
        }
        finish(DepthModel::Inverse, sry / srr, t, refs, mask)
    };
    let samples = (0..refs.len()).filter_map(|i| scale_on(1 << i).ok());
    // No two references agree on a scale: nothing to fit (unlike `fit_robust`, no plain fallback,
    // since one parameter leaves no structure for the rest to follow).
    consensus(refs, (inlier_abs, inlier_rel), samples, scale_on)
        .unwrap_or(Err(FitError::TooFewInliers { inliers: 1, needed: 2 }))
}

/// RANSAC's consensus step shared by the robust fits: of the `samples` (fits on minimal samples),
/// the one with the most references within `max(abs, rel * D)` (ties: lower total error), then
/// `refit` on its inliers, repeated once on the refit's inliers; rejected references in
/// [`ScaleShift::rejected`]. `None` when no sample has two inliers.
fn consensus(
    refs: &[ReferencePair],
    (inlier_abs, inlier_rel): (Metres, f64),
    samples: impl Iterator<Item = ScaleShift>,
    refit: impl Fn(u32) -> Result<ScaleShift, FitError>,
) -> Option<Result<ScaleShift, FitError>> {
    let tol = |p: &ReferencePair| inlier_abs.0.max(inlier_rel * p.depth.0);
    let inliers_of = |f: &ScaleShift| -> (u32, usize, f64) {
        let (mut mask, mut count, mut err) = (0u32, 0usize, 0.0);
        for (i, p) in refs.iter().enumerate() {
            if let Some(d) = f.depth(p.relative).filter(|_| usable(p)) {
                let e = (d.0 - p.depth.0).abs();
                if e <= tol(p) {
                    mask |= 1 << i;
                    count += 1;
                    err += e;
                }
            }
        }
        (mask, count, err)
    };
    let mut best: Option<(u32, usize, f64)> = None;
    for f in samples {
        let cand = inliers_of(&f);
        if best.is_none_or(|(_, c, e)| cand.1 > c || (cand.1 == c && cand.2 < e)) {
            best = Some(cand);
        }
    }
    let (mut mask, _, _) = best.filter(|b| b.1 >= 2)?;
    let mut f = match refit(mask) {
        Ok(f) => f,
        Err(e) => return Some(Err(e)),
    };
    let (mask2, count2, _) = inliers_of(&f);
    if count2 >= 2
        && mask2 != mask
        && let Ok(f2) = refit(mask2)
    {
        f = f2;
        mask = mask2;
    }
    let usable_mask = refs.iter().enumerate().filter(|(_, p)| usable(p)).fold(0u32, |m, (i, _)| m | (1 << i));
    f.rejected = usable_mask & !mask;
    Some(Ok(f))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refs_from(depths: &[f64], rel: impl Fn(f64) -> f64) -> References {
        depths.iter().map(|&d| ReferencePair { relative: rel(d), depth: Metres(d) }).collect()
    }

    #[test]
    fn the_scale_alone_is_fitted_at_the_given_shift_and_an_odd_reference_rejected() {
        // 1/D = 0.3 R + 0.1 at 1-5 m; reference 2 is 40 % off.
        let mut refs = refs_from(&[1.0, 2.0, 3.0, 4.0, 5.0], |d| (1.0 / d - 0.1) / 0.3);
        refs[2].depth = Metres(3.0 * 1.4);
        let f = fit_scale_at(0.1, &refs, Metres(0.1), 0.05).unwrap();
        assert_eq!((f.t, f.rejected, f.used), (0.1, 1 << 2, 4));
        assert!((f.s - 0.3).abs() < 1e-9, "{f:?}");
        // One usable reference is not a fit; a shift that leaves no positive scale is refused.
        assert!(matches!(fit_scale_at(0.1, &refs[..1], Metres(0.1), 0.05), Err(FitError::TooFewReferences { .. })));
        assert!(fit_scale_at(5.0, &refs, Metres(0.1), 0.05).is_err());
        assert!(matches!(fit_scale_at(f64::NAN, &refs, Metres(0.1), 0.05), Err(FitError::NonFiniteShift(_))));
        // No two references agree on a scale: refused, not a least-squares compromise.
        let scattered: References = [(1.0, 1.0), (2.0, 3.5), (3.0, 9.0)]
            .iter()
            .map(|&(r, d)| ReferencePair { relative: r, depth: Metres(d) })
            .collect();
        assert!(matches!(fit_scale_at(0.0, &scattered, Metres(0.1), 0.05), Err(FitError::TooFewInliers { .. })));
    }

    #[test]
    fn depth_gain_is_how_much_of_the_depth_the_relative_value_carries() {
        let f = |s: f64, t: f64, rejected: u32| ScaleShift {
            model: DepthModel::Inverse,
            s,
            t,
            residual_rms: Metres(0.0),
            used: 3,
            rejected,
        };
        let pairs: Vec<ReferencePair> =
            [1.0, 1.1, 1.2, 9.0].iter().map(|&r| ReferencePair { relative: r, depth: Metres(1.0) }).collect();
        // No shift: depth follows 1/r exactly, gain 1.
        assert!((depth_gain(&f(1.0, 0.0, 0), &pairs[..3]) - 1.0).abs() < 1e-12);
        // 1/D = 40 R - 35 at the kept median R = 1.1: 44 / 9.
        assert!((depth_gain(&f(40.0, -35.0, 0b1000), &pairs) - 44.0 / 9.0).abs() < 1e-12);
        assert!(depth_gain(&f(1.0, 0.0, 0), &[]).is_nan());
    }

    #[test]
    fn linear_fit_recovers_known_scale_and_shift() {
        // Data exactly linear: D = -2 R + 7.
        let refs: References = [0.5, 1.0, 1.5, 2.5]
            .iter()
            .map(|&r| ReferencePair { relative: r, depth: Metres(-2.0 * r + 7.0) })
            .collect();
        let f = fit(DepthModel::Linear, &refs).unwrap();
        assert!((f.s + 2.0).abs() < 1e-12 && (f.t - 7.0).abs() < 1e-12, "{f:?}");
        assert!(f.residual_rms.0 < 1e-12);
        assert_eq!(f.used, 4);
        assert!((f.depth(2.0).unwrap().0 - 3.0).abs() < 1e-12);
    }

    #[test]
    fn inverse_fit_recovers_known_scale_and_shift() {
        // R = (1/D - 0.05) / 0.4, i.e. 1/D = 0.4 R + 0.05.
        let refs = refs_from(&[0.8, 1.5, 2.7, 4.0, 5.5], |d| (1.0 / d - 0.05) / 0.4);
        let f = fit(DepthModel::Inverse, &refs).unwrap();
        assert!((f.s - 0.4).abs() < 1e-9 && (f.t - 0.05).abs() < 1e-9, "{f:?}");
        assert!(f.residual_rms.0 < 1e-9);
        let r = (1.0 / 3.3 - 0.05) / 0.4;
        assert!((f.depth(r).unwrap().0 - 3.3).abs() < 1e-9);
    }

    #[test]
    fn degenerate_inputs_are_errors_not_nan() {
        let one = refs_from(&[2.0], |d| 1.0 / d);
        assert_eq!(fit(DepthModel::Linear, &one), Err(FitError::TooFewReferences { usable: 1, needed: 2 }));
        let nan = [
            ReferencePair { relative: f64::NAN, depth: Metres(2.0) },
            ReferencePair { relative: 0.3, depth: Metres(3.0) },
            ReferencePair { relative: 0.2, depth: Metres(-1.0) },
        ];
        assert!(matches!(fit(DepthModel::Inverse, &nan), Err(FitError::TooFewReferences { usable: 1, .. })));
        let same = refs_from(&[2.0, 3.0, 4.0], |_| 0.7);
        assert!(matches!(fit(DepthModel::Linear, &same), Err(FitError::DegenerateRelative(_))));
        // Depth rising with inverse depth: wrong sign for both models.
        let wrong = refs_from(&[1.0, 2.0, 3.0], |d| d);
        assert!(matches!(fit(DepthModel::Linear, &wrong), Err(FitError::WrongScaleSign(_))));
        assert!(matches!(fit(DepthModel::Inverse, &wrong), Err(FitError::WrongScaleSign(_))));
        // A valid fit still refuses to produce a non-positive depth far outside the references.
        let f = fit(DepthModel::Linear, &refs_from(&[1.0, 2.0], |d| 3.0 - d)).unwrap();
        assert_eq!(f.depth(10.0), None);
        assert_eq!(f.depth(f64::NAN), None);
    }

    #[test]
    fn robust_fit_survives_two_fouled_references() {
        let truth = |d: f64| (1.0 / d - 0.05) / 0.4;
        let mut refs = refs_from(&[0.8, 1.2, 1.9, 2.6, 3.4, 4.1, 4.8, 5.5, 6.0, 2.2], truth);
        refs[3].relative = truth(0.6); // fouled: algae makes it look near
        refs[7].relative = truth(1.5);
        let plain = fit(DepthModel::Inverse, &refs).unwrap();
        let robust = fit_robust(DepthModel::Inverse, &refs, Metres(0.05), 0.03).unwrap();
        assert_eq!(robust.rejected, (1 << 3) | (1 << 7), "{robust:?}");
        assert_eq!(robust.used, 8);
        assert!((robust.s - 0.4).abs() < 1e-9 && (robust.t - 0.05).abs() < 1e-9);
        assert!(robust.residual_rms.0 < 1e-9);
        assert!(plain.residual_rms.0 > 0.1, "the plain fit is pulled by the outliers: {plain:?}");
        // Linear model, one hidden (NaN) and one fouled reference.
        let mut lin: References = (0..8)
            .map(|i| {
                let r = 0.2 + 0.1 * i as f64;
                ReferencePair { relative: r, depth: Metres(6.0 - 5.0 * r) }
            })
            .collect();
        lin[1].relative = f64::NAN;
        lin[5].depth = Metres(0.4);
        let f = fit_robust(DepthModel::Linear, &lin, Metres(0.05), 0.03).unwrap();
        assert!((f.s + 5.0).abs() < 1e-9 && (f.t - 6.0).abs() < 1e-9, "{f:?}");
        assert_eq!(f.rejected, 1 << 5);
    }
}
