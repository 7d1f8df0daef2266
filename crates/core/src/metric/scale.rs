//! Which ruler sets the depth fit's scale (`depth.scale`; docs/pipeline.md "The fish as the
//! ruler"): the reference objects (paper eq. 1-2), the tracked fish of a known length, or `auto` (the
//! references while at least [`AUTO_MIN_REFERENCES`] are visible and fit within
//! [`AUTO_MAX_RESIDUAL_M`], else the fish). Refitted on every depth frame; a failed fit keeps the
//! previous one.

use super::{
    AUTO_MAX_RESIDUAL_M, AUTO_MIN_REFERENCES, DepthFit, DepthGrid, DepthModel, DepthSample, DepthScale, FitMethod,
    FitSmoother, LengthLearner, MapKind, ROBUST_INLIER, ReferencePoints, References, RulerFit, Rulers,
    depth_over_sizes, fit_rulers, keep_fish_sizes, sample_fish,
};
use crate::geometry::{Intrinsics, PixelBox, apparent_length};
use crate::units::Metres;

/// The depth fit in use (paper eq. 1-2) and what set its scale, shown by the console `calib` command.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DepthFitState {
    /// Fitted scale s.
    pub scale: f64,
    /// Fitted shift t.
    pub shift: f64,
    /// RMS residual of the fit on the reference objects, m.
    pub residual_m: f64,
    /// Reference objects visible in the last depth frame.
    pub references_visible: u32,
    /// Whether a fit is available.
    pub fitted: bool,
    /// What set the scale of the fit in use (`depth.scale`).
    pub source: ScaleSource,
    /// Fish used as rulers in the last fish fit.
    pub fish_rulers: u32,
    /// The cohort length the fish fit uses, m (0 before any fish fit).
    pub ruler_length_m: f64,
    /// That length was measured under the references' fit (`depth.learn_fish_length`), not configured.
    pub ruler_length_learned: bool,
}

/// What set the metric scale of the fit in use (`depth.scale`; docs/pipeline.md).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ScaleSource {
    /// No fit yet.
    #[default]
    None,
    /// The reference objects (paper eq. 1-2).
    References,
    /// The tracked fish of the configured mean length (with any visible references).
    Fish,
}

impl ScaleSource {
    /// Name shown on the console and in the series.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::References => "references",
            Self::Fish => "fish",
        }
    }

    /// The source named `name` (as [`Self::name`] writes it).
    pub fn parse(name: &str) -> Option<Self> {
        [Self::None, Self::References, Self::Fish].into_iter().find(|s| s.name() == name)
    }
}

/// Counts of the metric fits (eq. 1-2) since the start, for scoring and the console.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitStats {
    /// Successful fits.
    pub fits: u64,
    /// Failed fits (the previous one was kept).
    pub failures: u64,
    /// Sum of the successful scale/shift fits' RMS residuals at the references, m.
    pub residual_sum_m: f64,
    /// Scale/shift fits with a residual (the regressors have none).
    pub residuals: u64,
    /// References rejected as outliers by the robust fit, summed over fits.
    pub rejected: u64,
}

/// The settings the scale policy reads (from `[depth]` and `[motion]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleConfig {
    /// `depth.scale`.
    pub scale: DepthScale,
    /// `depth.fit`: the fit on the references.
    pub method: FitMethod,
    /// `depth.sample`: how a fish's relative depth is read.
    pub sample: DepthSample,
    /// `depth.learn_fish_length`.
    pub learn_length: bool,
    /// `motion.body_length_m` (none: the fish cannot be the ruler).
    pub body_length: Option<Metres>,
    /// `motion.body_length_cv`: the spread of the fish's lengths.
    pub body_length_cv: f64,
}

/// One fish as the fish fit looks at it: track id, box, time last seen (s).
pub type Sighting = (u32, PixelBox, f64);

/// The depth fit and the policy that decides what sets its scale. Allocates once.
#[derive(Debug)]
pub struct ScalePolicy {
    cfg: ScaleConfig,
    fit: Option<DepthFit>,
    state: DepthFitState,
    stats: FitStats,
    /// The fish fit's running scale and shift.
    fish_fit: FitSmoother,
    /// The shift of the running fish fit as last set by a fit that fitted it (or by the
    /// references): a fit on fewer rulers fits the scale alone at this shift ([`fit_rulers`]).
    fish_shift: Option<f64>,
    /// The fish's looks for the fish fit.
    rulers: Rulers,
    /// The cohort length measured under the references' fit (`depth.learn_fish_length`).
    learned_length: LengthLearner,
    /// The fish of the current refit.
    fish: Vec<Sighting>,
}

impl ScalePolicy {
    /// A policy with no fit yet, for at most `max_fish` fish; `references_visible`: the reference
    /// objects inside the image.
    pub fn new(cfg: ScaleConfig, max_fish: usize, references_visible: usize) -> Self {
        Self {
            cfg,
            fit: None,
            state: DepthFitState { references_visible: references_visible as u32, ..DepthFitState::default() },
            stats: FitStats::default(),
            fish_fit: FitSmoother::default(),
            fish_shift: None,
            rulers: Rulers::new(max_fish),
            learned_length: LengthLearner::new(max_fish),
            fish: Vec::with_capacity(max_fish),
        }
    }

    /// The fit in use.
    pub fn fit(&self) -> Option<&DepthFit> {
        self.fit.as_ref()
    }

    /// The fit's state and what set its scale.
    pub fn state(&self) -> DepthFitState {
        self.state
    }

    /// Counts of the fits so far.
    pub fn stats(&self) -> FitStats {
        self.stats
    }

    /// Forgets the fish (tracks restarted); the fit is kept (the camera has not moved).
    pub fn restart(&mut self) {
        self.rulers.clear();
        self.learned_length.reset();
    }

    /// Refits on `map` (eq. 1-2) as `depth.scale` says, at frame time `t_s`: on `points` (the
    /// reference objects), or on `fish` as rulers (with the visible references' pairs added). Metric
    /// maps (ground-truth depth) need no fit.
    pub fn refit(
        &mut self,
        t_s: f64,
        map: &dyn DepthGrid,
        points: &ReferencePoints,
        intrinsics: &Intrinsics,
        fish: impl IntoIterator<Item = Sighting>,
    ) {
        if map.kind() == MapKind::Depth {
            return;
        }
        let (scale, ruler) = (self.cfg.scale, self.cfg.body_length);
        let refs = if points.is_empty() { References::new() } else { points.pairs(|px| map.point(px)) };
        let by_refs = match scale {
            DepthScale::References => !points.is_empty(),
            DepthScale::Auto => refs.len() >= AUTO_MIN_REFERENCES || ruler.is_none(),
            DepthScale::Fish => false,
        };
        if by_refs && !points.is_empty() {
            self.state.references_visible = refs.len() as u32;
            match self.cfg.method.fit(&refs, ROBUST_INLIER) {
                Ok(f) => {
                    let residual = f.scale_shift().map_or(f64::NAN, |ss| ss.residual_rms.0);
                    // `auto` leaves references that fit badly (fouled, moved) to the fish.
                    if scale != DepthScale::Auto || ruler.is_none() || residual <= AUTO_MAX_RESIDUAL_M {
                        self.fish_fit.reset();
                        // The references' shift, when they fitted the fish fit's model, is the
                        // fish's until enough rulers fit one.
                        self.fish_shift = f.scale_shift().filter(|ss| ss.model == DepthModel::Inverse).map(|ss| ss.t);
                        self.accept_reference_fit(f, refs.len());
                        // `auto` keeps looking at the fish, so they are rulers at once when the
                        // references go.
                        if let (DepthScale::Auto, Some(length)) = (scale, ruler) {
                            self.fish_refit(t_s, map, intrinsics, fish, length, refs, false);
                        }
                        return;
                    }
                }
                Err(e) => {
                    if scale != DepthScale::Auto || ruler.is_none() {
                        self.stats.failures += 1;
                        tracing::debug!("metric fit failed ({e}); keeping the previous fit");
                        return;
                    }
                }
            }
        }
        let Some(length) = ruler else { return };
        if scale == DepthScale::References {
            return;
        }
        self.fish_refit(t_s, map, intrinsics, fish, length, refs, true);
    }

    /// Keeps a fit on the references.
    fn accept_reference_fit(&mut self, f: DepthFit, visible: usize) {
        self.stats.fits += 1;
        let (scale, shift, residual) = match f.scale_shift() {
            Some(ss) => {
                self.stats.residual_sum_m += ss.residual_rms.0;
                self.stats.residuals += 1;
                self.stats.rejected += u64::from(ss.rejected.count_ones());
                (ss.s, ss.t, ss.residual_rms.0)
            }
            None => (f64::NAN, f64::NAN, f64::NAN),
        };
        self.fit = Some(f);
        self.state = DepthFitState {
            scale,
            shift,
            residual_m: residual,
            references_visible: visible as u32,
            fitted: true,
            source: ScaleSource::References,
            fish_rulers: 0,
            ruler_length_m: self.learned_length.length().map_or(0.0, |l| l.0),
            ruler_length_learned: self.learned_length.length().is_some(),
        };
    }

    /// The fish fit: each fish seen in enough depth frames is a reference at its depth scaled by
    /// the cohort's length over its broadside length ([`Rulers`]); `refs` (the visible references'
    /// pairs) are added. The cohort's length is `length`, or the one measured under the references'
    /// fit while they set the scale (`depth.learn_fish_length`, [`LengthLearner`]). With `fit` false
    /// (the references set the scale), the fish's looks are recorded and their length measured.
    #[allow(clippy::too_many_arguments)]
    fn fish_refit(
        &mut self,
        t_s: f64,
        map: &dyn DepthGrid,
        intrinsics: &Intrinsics,
        fish: impl IntoIterator<Item = Sighting>,
        length: Metres,
        refs: References,
        fit: bool,
    ) {
        // Only the fish fit looks at the fish: collected here, not on every depth frame.
        self.fish.clear();
        self.fish.extend(fish);
        let learn = !fit && self.cfg.learn_length;
        let learned = self.learned_length.length().filter(|_| self.cfg.learn_length);
        let length = learned.unwrap_or(length);
        let (pairs, rulers, by_size) = self.look_at_fish(t_s, map, intrinsics, length, &refs, fit, learn);
        if learn {
            self.learned_length.commit(t_s);
        }
        if !fit {
            return;
        }
        self.state.references_visible = refs.len() as u32;
        let fitted = fit_rulers(&pairs, self.cfg.body_length_cv, self.fish_shift)
            .and_then(|r| keep_fish_sizes(r.fit, &by_size).map(|fit| RulerFit { fit, ..r }));
        match fitted {
            Ok(RulerFit { fit: f, shift_fitted }) => {
                tracing::debug!(
                    t_s,
                    s = f.s,
                    t = f.t,
                    shift_fitted,
                    pairs = pairs.len(),
                    rejected = f.rejected.count_ones(),
                    median_pair_m = median_depth(&pairs),
                    gain = super::fit::depth_gain(&f, &pairs),
                    over_sizes = depth_over_sizes(&f, &by_size),
                    "fish fit"
                );
                let f = self.fish_fit.update(t_s, f);
                if shift_fitted {
                    self.fish_shift = Some(f.t);
                }
                self.stats.fits += 1;
                self.stats.residual_sum_m += f.residual_rms.0;
                self.stats.residuals += 1;
                self.stats.rejected += u64::from(f.rejected.count_ones());
                self.fit = Some(DepthFit::ScaleShift(f));
                self.state = DepthFitState {
                    scale: f.s,
                    shift: f.t,
                    residual_m: f.residual_rms.0,
                    references_visible: refs.len() as u32,
                    fitted: true,
                    source: ScaleSource::Fish,
                    fish_rulers: rulers,
                    ruler_length_m: length.0,
                    ruler_length_learned: learned.is_some(),
                };
            }
            Err(e) => {
                self.stats.failures += 1;
                tracing::debug!(t_s, pairs = pairs.len(), "fish fit failed ({e}); keeping the previous fit");
            }
        }
    }

    /// Records each fish seen at `t_s` as a ruler look (and its length, when `learn`); with `fit`,
    /// returns `refs` with the rulers' pairs added, how many rulers, and each ruler's pair from its
    /// size alone (for [`keep_fish_sizes`]).
    #[allow(clippy::too_many_arguments)]
    fn look_at_fish(
        &mut self,
        t_s: f64,
        map: &dyn DepthGrid,
        intrinsics: &Intrinsics,
        length: Metres,
        refs: &References,
        fit: bool,
        learn: bool,
    ) -> (References, u32, References) {
        let mut pairs = refs.clone();
        let mut by_size = References::new();
        let mut rulers = 0u32;
        for &(id, bbox, last_seen) in &self.fish {
            // Seen in the last frame.
            let seen = t_s - last_seen <= 0.25;
            if !seen {
                continue;
            }
            let centre = bbox.center();
            let others = self.fish.iter().filter(|x| x.0 != id).map(|x| &x.1);
            let Some(relative) =
                sample_fish(self.cfg.sample, map.kind(), &bbox, others, || map.point(centre), |p| map.grid(p))
            else {
                continue;
            };
            let angle = apparent_length(intrinsics, &bbox, Metres(1.0)).0;
            self.rulers.look(t_s, id, intrinsics, centre, angle, relative);
            if learn && let Some(l) = self.fit.as_ref().and_then(|f| self.rulers.broadside(id, f)) {
                self.learned_length.push(l);
            }
            if !fit || pairs.is_full() {
                continue;
            }
            if let Some(p) = self.rulers.pair(id, self.fit.as_ref(), length) {
                let _ = pairs.push(p);
                rulers += 1;
                if let Some(a) = self.rulers.pair(id, None, length) {
                    let _ = by_size.push(a);
                }
            }
        }
        (pairs, rulers, by_size)
    }
}

/// The median depth of `pairs`, m (NaN when empty): what the fish fit was asked to match.
fn median_depth(pairs: &References) -> f64 {
    let mut d: heapless::Vec<f64, { super::MAX_REFERENCES }> = pairs.iter().map(|p| p.depth.0).collect();
    super::fit::quantile(&mut d, 0.5).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pixel;

    /// A relative map that reads each fish's relative value inside its box (1/D = 0.2 R + 0.05).
    struct Fishes(Vec<(PixelBox, f64)>);

    impl DepthGrid for Fishes {
        fn kind(&self) -> MapKind {
            MapKind::InverseDepth
        }
        fn point(&self, px: Pixel) -> Option<f64> {
            self.0.iter().find(|(b, _)| b.contains(px)).map(|x| x.1)
        }
        fn grid(&self, px: Pixel) -> Option<f64> {
            self.point(px)
        }
    }

    /// Fish of 0.35 m broadside at `depths`, stacked near the optical axis (where a box's width is
    /// its angular length).
    fn fishes(k: &Intrinsics, depths: &[f64]) -> Vec<(u32, PixelBox, f64)> {
        depths
            .iter()
            .enumerate()
            .map(|(i, &d)| {
                let w = k.fx * 0.35 / d;
                let c = Pixel::new(k.cx, k.cy + 30.0 * (i as f64 - 2.5));
                (i as u32, PixelBox::from_center(c, w, w / 4.0), (1.0 / d - 0.05) / 0.2)
            })
            .collect()
    }

    /// Runs depth frames at 5 Hz over `from_s..to_s` with `fish` in view; returns the fit state.
    fn run(p: &mut ScalePolicy, k: &Intrinsics, fish: &[(u32, PixelBox, f64)], from_s: f64, to_s: f64) {
        let map = Fishes(fish.iter().map(|&(_, b, r)| (b, r)).collect());
        let mut t = from_s;
        while t < to_s {
            p.refit(t, &map, &ReferencePoints::default(), k, fish.iter().map(|&(id, b, _)| (id, b, t)));
            t += 0.2;
        }
    }

    #[test]
    fn the_fish_fit_takes_the_shift_from_enough_rulers_and_keeps_it_with_few() {
        let k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        let cfg = ScaleConfig {
            scale: DepthScale::Fish,
            method: FitMethod::Robust,
            sample: DepthSample::Centre,
            learn_length: false,
            body_length: Some(Metres(0.35)),
            body_length_cv: 0.1,
        };
        // Three fish only: a line through them checks too little, and there is no shift yet.
        let mut few = ScalePolicy::new(cfg, 16, 0);
        run(&mut few, &k, &fishes(&k, &[1.0, 2.0, 3.0]), 0.0, 6.0);
        assert!(!few.state().fitted);
        assert!(few.stats().fits == 0 && few.stats().failures > 0);
        // Six fish fit scale and shift; when three remain, the scale alone is fitted at that shift.
        let mut p = ScalePolicy::new(cfg, 16, 0);
        let six = fishes(&k, &[1.0, 1.5, 2.0, 2.5, 3.0, 3.5]);
        run(&mut p, &k, &six, 0.0, 6.0);
        let st = p.state();
        assert!(st.fitted && st.fish_rulers == 6, "{st:?}");
        assert!((st.shift - 0.05).abs() < 0.01, "{st:?}");
        let fits = p.stats().fits;
        run(&mut p, &k, &six[..3], 6.0, 10.0);
        assert!(p.stats().fits > fits);
        assert_eq!(p.state().shift, st.shift);
        assert_eq!(p.state().fish_rulers, 3);
    }
}
