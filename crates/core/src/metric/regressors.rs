//! The paper's other scale/shift regressors (Table 4): 2nd-order polynomial, decision tree and
//! k-nearest neighbours, each mapping relative inverse depth `R` to depth `D` from the reference
//! pairs. For the evaluation table only: the paper shows they extrapolate badly (polynomial) or
//! produce layered depth maps (tree, kNN). Fixed-capacity, allocation-free.

use super::{FitError, MAX_REFERENCES, ReferencePair};
use crate::units::Metres;

/// Which regressor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RegressorKind {
    /// `D = a R^2 + b R + c`, least squares (needs 3 references with distinct R).
    Poly2,
    /// Regression tree on `R`, depth-limited to [`TREE_DEPTH`], at least one reference per leaf.
    Tree,
    /// Mean depth of the [`KNN_K`] references nearest in `R`.
    Knn,
}

/// Maximum depth of the regression tree (at most 8 leaves).
pub const TREE_DEPTH: u32 = 3;
/// Neighbours used by the kNN regressor.
pub const KNN_K: usize = 3;

/// A fitted regressor.
#[derive(Debug, Clone)]
pub struct Regressor {
    kind: RegressorKind,
    poly: [f64; 3],
    /// Sorted by R: references (kNN) or leaves as (upper R bound, mean depth) (tree).
    points: heapless::Vec<(f64, f64), MAX_REFERENCES>,
}

impl Regressor {
    /// Fits `kind` on the usable references (finite R, positive depth).
    pub fn fit(kind: RegressorKind, refs: &[ReferencePair]) -> Result<Self, FitError> {
        let mut pts: heapless::Vec<(f64, f64), MAX_REFERENCES> = refs
            .iter()
            .filter(|p| p.relative.is_finite() && p.depth.0.is_finite() && p.depth.0 > 0.0)
            .take(MAX_REFERENCES)
            .map(|p| (p.relative, p.depth.0))
            .collect();
        pts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let needed = if kind == RegressorKind::Poly2 { 3 } else { 2 };
        if pts.len() < needed {
            return Err(FitError::TooFewReferences { usable: pts.len(), needed });
        }
        let (lo, hi) = (pts[0].0, pts[pts.len() - 1].0);
        if hi - lo <= 1e-12 * lo.abs().max(1.0) {
            return Err(FitError::DegenerateRelative(lo));
        }
        let mut out = Self { kind, poly: [0.0; 3], points: heapless::Vec::new() };
        match kind {
            RegressorKind::Poly2 => out.poly = poly2(&pts)?,
            RegressorKind::Knn => out.points = pts,
            RegressorKind::Tree => {
                split(&pts, TREE_DEPTH, &mut out.points);
                // Move each boundary half-way to the next reference, so a value between two
                // references goes to the nearer leaf.
                for leaf in out.points.iter_mut() {
                    if let Some(next) = pts.iter().find(|p| p.0 > leaf.0) {
                        leaf.0 = 0.5 * (leaf.0 + next.0);
                    }
                }
            }
        }
        Ok(out)
    }

    /// Predicted depth at `relative`; `None` where the prediction is not a positive finite depth.
    pub fn depth(&self, relative: f64) -> Option<Metres> {
        if !relative.is_finite() {
            return None;
        }
        let d = match self.kind {
            RegressorKind::Poly2 => (self.poly[0] * relative + self.poly[1]) * relative + self.poly[2],
            RegressorKind::Tree => {
                let leaf = self.points.iter().find(|(ub, _)| relative <= *ub).or(self.points.last());
                leaf.map_or(f64::NAN, |l| l.1)
            }
            RegressorKind::Knn => {
                let mut near = [(f64::INFINITY, 0.0); KNN_K];
                for &(r, d) in &self.points {
                    let dist = (r - relative).abs();
                    if dist < near[KNN_K - 1].0 {
                        near[KNN_K - 1] = (dist, d);
                        near.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
                    }
                }
                let used: heapless::Vec<f64, KNN_K> = near.iter().filter(|n| n.0.is_finite()).map(|n| n.1).collect();
                used.iter().sum::<f64>() / used.len() as f64
            }
        };
        (d.is_finite() && d > 0.0).then_some(Metres(d))
    }
}

fn poly2(pts: &[(f64, f64)]) -> Result<[f64; 3], FitError> {
    // Normal equations on centred R for conditioning.
    let n = pts.len() as f64;
    let m = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for &(r, d) in pts {
        let x = r - m;
        let v = nalgebra::Vector3::new(x * x, x, 1.0);
        a += v * v.transpose();
        b += v * d;
    }
    let sol = a.lu().solve(&b).ok_or(FitError::DegenerateRelative(m))?;
    let (p, q, c) = (sol[0], sol[1], sol[2]);
    // Expand p (r-m)^2 + q (r-m) + c.
    let coeffs = [p, q - 2.0 * p * m, p * m * m - q * m + c];
    if coeffs.iter().all(|c| c.is_finite()) { Ok(coeffs) } else { Err(FitError::DegenerateRelative(m)) }
}

/// Recursive variance-reduction split of sorted points; pushes leaves (upper bound, mean) in order.
fn split(pts: &[(f64, f64)], depth: u32, leaves: &mut heapless::Vec<(f64, f64), MAX_REFERENCES>) {
    let mean = |s: &[(f64, f64)]| s.iter().map(|p| p.1).sum::<f64>() / s.len() as f64;
    let sse = |s: &[(f64, f64)]| {
        let m = mean(s);
        s.iter().map(|p| (p.1 - m).powi(2)).sum::<f64>()
    };
    let mut best: Option<(usize, f64)> = None;
    if depth > 0 && pts.len() >= 2 {
        let total = sse(pts);
        for k in 1..pts.len() {
            if pts[k].0 <= pts[k - 1].0 {
                continue;
            }
            let e = sse(&pts[..k]) + sse(&pts[k..]);
            if e < total - 1e-12 && best.is_none_or(|b| e < b.1) {
                best = Some((k, e));
            }
        }
    }
    match best {
        Some((k, _)) => {
            split(&pts[..k], depth - 1, leaves);
            split(&pts[k..], depth - 1, leaves);
        }
        None => {
            let ub = pts[pts.len() - 1].0;
            let _ = leaves.push((ub, mean(pts)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs(f: impl Fn(f64) -> f64) -> heapless::Vec<ReferencePair, MAX_REFERENCES> {
        (0..10).map(|i| 0.1 + 0.1 * i as f64).map(|r| ReferencePair { relative: r, depth: Metres(f(r)) }).collect()
    }

    #[test]
    fn poly2_recovers_a_quadratic() {
        let refs = pairs(|r| 2.0 * r * r - 5.0 * r + 6.0);
        let p = Regressor::fit(RegressorKind::Poly2, &refs).unwrap();
        assert!((p.depth(0.55).unwrap().0 - (2.0 * 0.3025 - 2.75 + 6.0)).abs() < 1e-9);
        assert!(Regressor::fit(RegressorKind::Poly2, &refs[..2]).is_err());
    }

    #[test]
    fn tree_and_knn_are_piecewise_constant_and_interpolate_roughly() {
        let refs = pairs(|r| 6.0 - 5.0 * r);
        let t = Regressor::fit(RegressorKind::Tree, &refs).unwrap();
        assert!(t.points.len() <= 8 && t.points.len() >= 4, "{:?}", t.points);
        let a = t.depth(0.1).unwrap().0;
        assert!((a - 5.5).abs() < 0.6, "{a}");
        assert_eq!(t.depth(0.1), t.depth(0.1001)); // layered output
        assert!(t.depth(0.95).unwrap().0 <= 1.5 + 1e-9);
        let k = Regressor::fit(RegressorKind::Knn, &refs).unwrap();
        // Nearest three of 0.5 are 0.4, 0.5, 0.6: mean depth 3.5.
        assert!((k.depth(0.5).unwrap().0 - 3.5).abs() < 1e-9);
        assert!(k.depth(f64::NAN).is_none());
        let same: heapless::Vec<ReferencePair, MAX_REFERENCES> =
            (0..3).map(|_| ReferencePair { relative: 0.3, depth: Metres(2.0) }).collect();
        assert!(matches!(Regressor::fit(RegressorKind::Knn, &same), Err(FitError::DegenerateRelative(_))));
    }
}
