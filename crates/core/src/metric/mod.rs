//! Metric depth from relative inverse depth using reference objects (paper eq. 1-2).
//!
//! A monocular depth network returns a relative inverse depth map `R` with unknown scale and shift.
//! Reference objects with known world positions are projected into the image, `R` is sampled there
//! with a small median window ([`sample_median`]), and a scale/shift model is fitted against the
//! references' known depths ([`fit`]):
//! - [`DepthModel::Linear`]: the paper's eq. 2, `D = s*R + t`;
//! - [`DepthModel::Inverse`]: the physically consistent `1/D = s*R + t` (MiDaS alignment);
//! - [`fit_robust`]: either model fitted by exhaustive-pair RANSAC then least squares on the inliers,
//!   which survives one or two fouled or hidden references; [`fit_scale_at`] the same for the
//!   inverse model's scale alone at a known shift (the fish fit on few rulers).
//!
//! The paper's other regressors (2nd-order polynomial, decision tree, k-nearest neighbours, Table 4)
//! live in [`regressors`]; [`FitMethod`] (`depth.fit`) chooses among all of them.
//!
//! Nothing here allocates: references are held in a fixed-capacity list of [`MAX_REFERENCES`].

mod fish;
mod fit;
mod grid;
mod method;
mod references;
pub mod regressors;
mod sample;
mod scale;

pub use fish::{
    AUTO_MAX_RESIDUAL_M, AUTO_MIN_REFERENCES, FISH_FIT_SMOOTHING_S, FitSmoother, LEARNED_LENGTH_SMOOTHING_S,
    LENGTH_QUANTILE, LOOKS, LengthLearner, MAX_OFF_SIZES, MIN_LOOKS, MIN_RULERS, MIN_SHIFT_INLIERS, RULER_TIMEOUT_S,
    RulerFit, Rulers, depth_over_sizes, fit_rulers, keep_fish_sizes, ruler_depth,
};
pub use fit::{
    DepthModel, FitError, ROBUST_INLIER, ReferencePair, References, ScaleShift, fit, fit_robust, fit_scale_at,
};
pub use grid::DepthGrid;
pub use method::{DepthFit, DepthScale, FitMethod};
pub use references::{ReferenceFootprints, ReferencePoints};
pub use sample::{
    CORE_FRAC, DepthSample, MAX_OVERLAPS, MAX_RADIUS, MIN_VISIBLE_POINTS, MIN_VISIBLE_POINTS_BEHIND, MapKind, Overlaps,
    RelativeMap, behind_a_nearer_fish, sample_box_quantile, sample_box_quantile_visible, sample_fish, sample_median,
};
pub use scale::{DepthFitState, FitStats, ScaleConfig, ScalePolicy, ScaleSource, Sighting};

/// Most reference objects a scene may have (the paper uses ten).
pub const MAX_REFERENCES: usize = 32;
