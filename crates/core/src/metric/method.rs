//! The metric fit a deployment chooses (`depth.fit`): the paper's eq. 2 and its variants, and the
//! paper's Table 4 regressors, behind one type the pipeline keeps until the next depth frame.

use super::fit::{DepthModel, FitError, ReferencePair, ScaleShift, fit, fit_robust};
use super::regressors::{Regressor, RegressorKind};
use crate::units::Metres;

/// How relative inverse depth becomes metres (`depth.fit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FitMethod {
    /// The paper's eq. 2, `D = s*R + t`.
    Linear,
    /// `1/D = s*R + t`.
    Inverse,
    /// The inverse model by `fit_robust` (survives one or two fouled or hidden references).
    Robust,
    /// 2nd-order polynomial in `R` (paper Table 4).
    Poly2,
    /// Regression tree on `R` (paper Table 4).
    Tree,
    /// k-nearest neighbours in `R` (paper Table 4).
    Knn,
}

impl crate::choice::Choice for FitMethod {
    const ALL: &'static [Self] = &[Self::Linear, Self::Inverse, Self::Robust, Self::Tree, Self::Knn];
}

/// What sets the metric scale of the depth map (`depth.scale`; docs/pipeline.md, "The fish as the
/// ruler").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthScale {
    /// The reference objects only (paper eq. 1-2).
    References,
    /// The tracked fish of known mean length (`motion.body_length_m`), plus any visible references.
    Fish,
    /// The references while enough are visible and fit well, else the fish.
    #[default]
    Auto,
}

/// A fitted mapping from relative inverse depth to metres.
#[derive(Debug, Clone)]
pub enum DepthFit {
    /// Eq. 2 or its inverse form.
    ScaleShift(ScaleShift),
    /// One of Table 4's regressors (boxed: it is large, and only the evaluation tables use it).
    Regressor(Box<Regressor>),
}

impl DepthFit {
    /// Metric depth for a relative inverse depth value; `None` where the fit gives no positive depth.
    pub fn depth(&self, relative: f64) -> Option<Metres> {
        match self {
            Self::ScaleShift(f) => f.depth(relative),
            Self::Regressor(r) => r.depth(relative),
        }
    }

    /// The scale and shift, for the fits that have them.
    pub fn scale_shift(&self) -> Option<&ScaleShift> {
        match self {
            Self::ScaleShift(f) => Some(f),
            Self::Regressor(_) => None,
        }
    }
}

impl FitMethod {
    /// Fits `refs`; `inlier` is the robust fit's tolerance (see [`fit_robust`]).
    pub fn fit(self, refs: &[ReferencePair], inlier: (Metres, f64)) -> Result<DepthFit, FitError> {
        let reg = |kind| Regressor::fit(kind, refs).map(|r| DepthFit::Regressor(Box::new(r)));
        match self {
            Self::Linear => fit(DepthModel::Linear, refs).map(DepthFit::ScaleShift),
            Self::Inverse => fit(DepthModel::Inverse, refs).map(DepthFit::ScaleShift),
            Self::Robust => fit_robust(DepthModel::Inverse, refs, inlier.0, inlier.1).map(DepthFit::ScaleShift),
            Self::Poly2 => reg(RegressorKind::Poly2),
            Self::Tree => reg(RegressorKind::Tree),
            Self::Knn => reg(RegressorKind::Knn),
        }
    }
}
