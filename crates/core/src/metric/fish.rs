//! The fish as the ruler (not in the paper; docs/pipeline.md, "The fish as the ruler").
//!
//! A fish of length `L` seen broadside spans the angle `L / range`, so a tracked fish is a reference
//! object at its own depth once its broadside length is known. Its angular length alone does not
//! tell it: the fish moves nearer and farther over its track. [`Rulers`] keeps, per fish and depth
//! frame, its box's angular length and the relative inverse depth sampled at it; with the fit in use
//! each look becomes a metric length (angle times range), and their [`LENGTH_QUANTILE`] is the fish's
//! broadside length `l` under that fit. The fish's pair is then (its relative value now, its fitted
//! depth now times `L / l`): a fit off by a factor is corrected in one step. Before any fit, the
//! angular lengths alone give a first one ([`ruler_depth`]). The same eq. 2 family is fitted over the
//! pairs by [`fit_robust`], or the scale alone by [`fit_scale_at`] when too few pairs agree to fit
//! the shift ([`MIN_SHIFT_INLIERS`]), with a tolerance from the cohort's spread, so fish whose
//! length or box is off are rejected. The cohort's mean length `L` sets the scale: a length 10 % off scales every depth, and
//! so every speed in m/s, by 10 %; speeds in body lengths per second do not depend on it.

use super::fit::{DepthModel, FitError, ReferencePair, ScaleShift, fit_robust, fit_scale_at, quantile, usable};
use super::method::DepthFit;
use crate::geometry::{Intrinsics, Pixel};
use crate::units::Metres;

/// Depth frames a fish must have been seen in before its broadside length is trusted.
pub const MIN_LOOKS: usize = 10;

/// Looks kept per fish (the most recent; at 5 depth frames/s, 12.8 s).
pub const LOOKS: usize = 64;

/// Quantile of a fish's lengths taken as its broadside length: a fish seen broadside now and then
/// shows its length in its longest looks (the fish fit here, the speed's heading in `motion`).
pub const LENGTH_QUANTILE: f64 = 0.95;

/// A fish not seen in a depth frame for this long is forgotten, s.
pub const RULER_TIMEOUT_S: f64 = 1.0;

/// `depth.scale = "auto"` keeps the references while at least this many are visible ...
pub const AUTO_MIN_REFERENCES: usize = 3;

/// ... and their fit's RMS residual is at most this, m.
pub const AUTO_MAX_RESIDUAL_M: f64 = 0.15;

/// Fish rulers (plus references) a fit needs.
pub const MIN_RULERS: usize = 3;

/// The most a fish fit may put the fish nearer or farther than their sizes alone say: the median
/// over the rulers of the fit's depth over [`ruler_depth`] must lie within `1/x..x`
/// ([`keep_fish_sizes`]). On renders and real clips other than the evaluation sequence the fits
/// stay within 0.9-1.25; with a few rulers whose relative values nearly coincide, a line through
/// them (even one with [`MIN_SHIFT_INLIERS`] inliers) can be so steep that the fish end up a few
/// centimetres from the lens, and the 0.1 m inlier tolerance then keeps it; a scale fitted at an
/// old shift can be as far off.
pub const MAX_OFF_SIZES: f64 = 2.0;

/// Time constant of the averaging of the cohort's length measured under the references' fit
/// ([`LengthLearner`]), s.
pub const LEARNED_LENGTH_SMOOTHING_S: f64 = 10.0;

/// Time constant of the smoothing of the fish fit's scale and shift, s (the fish in view change from
/// frame to frame; the water and the camera do not).
pub const FISH_FIT_SMOOTHING_S: f64 = 2.0;

/// Camera z of a fish of `length` whose box centre is at `centre` and whose broadside angular length
/// is `broadside_rad`: range `length / angle`, along the ray through the centre. `None` for a
/// non-positive or non-finite angle or length.
pub fn ruler_depth(intrinsics: &Intrinsics, centre: Pixel, broadside_rad: f64, length: Metres) -> Option<Metres> {
    if !(broadside_rad.is_finite() && broadside_rad > 0.0 && length.0.is_finite() && length.0 > 0.0) {
        return None;
    }
    let ray = intrinsics.ray(centre);
    let z = length.0 / broadside_rad / ray.norm();
    (z.is_finite() && z > 0.0).then_some(Metres(z))
}

/// Inlier rulers a fish fit needs before it fits the depth network's shift as well as its scale.
/// A line through two rulers checks nothing and one through three is checked once; with few
/// rulers whose relative values nearly coincide such a line takes almost any slope, and every
/// fish's depth, and so its speed along the line of sight, follows it. With fewer inliers the
/// scale alone is fitted, at the shift of the last fit that had enough, and before there is one
/// the fit is refused ([`fit_rulers`]): the depth network's shift is its own (on renders it
/// carries four fifths of the depth), so no fixed value can stand in for it.
pub const MIN_SHIFT_INLIERS: usize = 4;

/// A fish fit, and whether it fitted the shift or kept the one it was given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RulerFit {
    /// The fit (inverse model).
    pub fit: ScaleShift,
    /// The shift was fitted ([`MIN_SHIFT_INLIERS`] inliers or more), not given.
    pub shift_fitted: bool,
}

/// The fit over fish rulers (and any references among `pairs`): the inverse model by [`fit_robust`],
/// a pair an inlier within 0.1 m or twice the cohort's length spread `length_cv` (at least 5 %);
/// when that fit keeps fewer than [`MIN_SHIFT_INLIERS`] pairs, the scale alone at `shift`
/// ([`fit_scale_at`]), or [`FitError::TooFewInliers`] without one.
pub fn fit_rulers(pairs: &[ReferencePair], length_cv: f64, shift: Option<f64>) -> Result<RulerFit, FitError> {
    let n = pairs.iter().filter(|p| usable(p)).count();
    if n < MIN_RULERS {
        return Err(FitError::TooFewReferences { usable: n, needed: MIN_RULERS });
    }
    let (abs, rel) = (Metres(0.1), (2.0 * length_cv).max(0.05));
    match fit_robust(DepthModel::Inverse, pairs, abs, rel) {
        Ok(fit) if fit.used >= MIN_SHIFT_INLIERS => Ok(RulerFit { fit, shift_fitted: true }),
        line => match shift {
            Some(t) => fit_scale_at(t, pairs, abs, rel).map(|fit| RulerFit { fit, shift_fitted: false }),
            None => {
                Err(line.map_or_else(|e| e, |f| FitError::TooFewInliers { inliers: f.used, needed: MIN_SHIFT_INLIERS }))
            }
        },
    }
}

/// The median over `by_size` (each ruler's pair from its angular length alone, [`Rulers::pair`]
/// without a fit) of the fit's depth there over that pair's depth; NaN when none has a depth.
pub fn depth_over_sizes(f: &ScaleShift, by_size: &[ReferencePair]) -> f64 {
    let mut q: heapless::Vec<f64, { super::MAX_REFERENCES }> = by_size
        .iter()
        .take(super::MAX_REFERENCES)
        .filter_map(|p| f.depth(p.relative).map(|d| d.0 / p.depth.0))
        .collect();
    quantile(&mut q, 0.5).unwrap_or(f64::NAN)
}

/// `f` when it keeps the fish within [`MAX_OFF_SIZES`] of the depths their sizes give (or there is
/// nothing to compare with), else [`FitError::OffTheFishSizes`]. The fish fit corrects the
/// angle-only scale with the depth network's ranking; it may not throw it away.
pub fn keep_fish_sizes(f: ScaleShift, by_size: &[ReferencePair]) -> Result<ScaleShift, FitError> {
    let q = depth_over_sizes(&f, by_size);
    if q.is_finite() && !(1.0 / MAX_OFF_SIZES..=MAX_OFF_SIZES).contains(&q) {
        return Err(FitError::OffTheFishSizes(q));
    }
    Ok(f)
}

/// One look at a fish in a depth frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Look {
    /// The box's angular length, radians.
    angle: f64,
    /// Relative inverse depth sampled at the fish.
    relative: f64,
    /// Range over camera z along the ray through the box centre (at least 1).
    ray_norm: f64,
}

#[derive(Debug, Clone)]
struct RulerFish {
    id: u32,
    last_t: f64,
    looks: heapless::Deque<Look, LOOKS>,
}

/// The fish's looks over their tracks, for the fish fit (module documentation). Allocated once.
#[derive(Debug, Clone)]
pub struct Rulers {
    fish: Vec<RulerFish>,
    capacity: usize,
    scratch: Vec<f64>,
}

impl Rulers {
    /// A table for at most `capacity` fish.
    pub fn new(capacity: usize) -> Self {
        Self { fish: Vec::with_capacity(capacity), capacity, scratch: Vec::with_capacity(LOOKS) }
    }

    /// Forgets every fish.
    pub fn clear(&mut self) {
        self.fish.clear();
    }

    /// Records fish `id` in the depth frame at `t_s`: its box's angular length `angle` (radians) at
    /// `centre`, and the relative inverse depth `relative` sampled at it. Fish not seen for
    /// [`RULER_TIMEOUT_S`] are dropped first; a full table ignores new fish.
    pub fn look(&mut self, t_s: f64, id: u32, intrinsics: &Intrinsics, centre: Pixel, angle: f64, relative: f64) {
        if !(angle.is_finite() && angle > 0.0 && relative.is_finite()) {
            return;
        }
        let i = match self.fish.iter().position(|f| f.id == id) {
            Some(i) => i,
            None => {
                self.fish.retain(|f| t_s - f.last_t <= RULER_TIMEOUT_S);
                if self.fish.len() >= self.capacity {
                    return;
                }
                self.fish.push(RulerFish { id, last_t: t_s, looks: heapless::Deque::new() });
                self.fish.len() - 1
            }
        };
        let f = &mut self.fish[i];
        f.last_t = t_s;
        if f.looks.is_full() {
            f.looks.pop_front();
        }
        let _ = f.looks.push_back(Look { angle, relative, ray_norm: intrinsics.ray(centre).norm() });
    }

    /// The broadside length of fish `id` under `fit`, m: the [`LENGTH_QUANTILE`] of its looks' angular
    /// lengths times their fitted ranges; `None` before [`MIN_LOOKS`] looks.
    pub fn broadside(&mut self, id: u32, fit: &DepthFit) -> Option<Metres> {
        let f = self.fish.iter().find(|f| f.id == id)?;
        if f.looks.len() < MIN_LOOKS {
            return None;
        }
        self.scratch.clear();
        self.scratch.extend(f.looks.iter().filter_map(|l| fit.depth(l.relative).map(|z| l.angle * z.0 * l.ray_norm)));
        quantile(&mut self.scratch, LENGTH_QUANTILE).filter(|l| l.is_finite() && *l > 0.0).map(Metres)
    }

    /// The pair of fish `id` for a fit, from its latest look, when it has at least [`MIN_LOOKS`]: with
    /// `fit` (the fit in use), its fitted depth now times `length` over its broadside length under
    /// that fit ([`Self::broadside`]); without, [`ruler_depth`] of the [`LENGTH_QUANTILE`] of its
    /// angular lengths.
    pub fn pair(&mut self, id: u32, fit: Option<&DepthFit>, length: Metres) -> Option<ReferencePair> {
        let f = self.fish.iter().find(|f| f.id == id)?;
        if f.looks.len() < MIN_LOOKS {
            return None;
        }
        let now = *f.looks.back()?;
        match fit {
            Some(fit) => {
                let z_now = fit.depth(now.relative)?.0;
                let l = self.broadside(id, fit)?.0;
                let depth = z_now * length.0 / l;
                (depth.is_finite() && depth > 0.0)
                    .then_some(ReferencePair { relative: now.relative, depth: Metres(depth) })
            }
            None => {
                self.scratch.clear();
                self.scratch.extend(f.looks.iter().map(|l| l.angle));
                let a = quantile(&mut self.scratch, LENGTH_QUANTILE)?;
                let z = length.0 / a / now.ray_norm;
                (z.is_finite() && z > 0.0).then_some(ReferencePair { relative: now.relative, depth: Metres(z) })
            }
        }
    }
}

/// The cohort's ruler length learned while the references set the scale (`depth.learn_fish_length`):
/// the median of the fish's broadside lengths under the references' fit, averaged over time. When
/// the references go, the fish fit uses it instead of `motion.body_length_m`, so the scale carries
/// on where the references left it: a configured length that is off, or a length quantile that
/// reads short, costs nothing while the references lasted.
#[derive(Debug, Clone, Default)]
pub struct LengthLearner {
    last: Option<(f64, f64)>,
    lengths: Vec<f64>,
}

impl LengthLearner {
    /// A learner for up to `capacity` fish a frame (allocated once).
    pub fn new(capacity: usize) -> Self {
        Self { last: None, lengths: Vec::with_capacity(capacity) }
    }

    /// Adds the broadside length of one fish seen under the references' fit in this depth frame (a
    /// full frame ignores more).
    pub fn push(&mut self, length: Metres) {
        if length.0.is_finite() && length.0 > 0.0 && self.lengths.len() < self.lengths.capacity() {
            self.lengths.push(length.0);
        }
    }

    /// Ends the depth frame at `t_s`: blends the median of its lengths into the running length; a
    /// frame with fewer than [`MIN_RULERS`] fish is skipped.
    pub fn commit(&mut self, t_s: f64) {
        let m = if self.lengths.len() >= MIN_RULERS { quantile(&mut self.lengths, 0.5) } else { None };
        self.lengths.clear();
        let Some(m) = m else { return };
        self.last = Some(match self.last {
            // Time going backwards starts over.
            Some((t0, prev)) if t_s >= t0 => {
                let a = 1.0 - (-(t_s - t0) / LEARNED_LENGTH_SMOOTHING_S).exp();
                (t_s, prev + a * (m - prev))
            }
            _ => (t_s, m),
        });
    }

    /// The learned length, m; `None` before any.
    pub fn length(&self) -> Option<Metres> {
        self.last.map(|(_, l)| Metres(l))
    }

    /// Forgets it.
    pub fn reset(&mut self) {
        self.last = None;
        self.lengths.clear();
    }
}

/// Exponential smoothing of successive fish fits' scale and shift ([`FISH_FIT_SMOOTHING_S`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitSmoother {
    last: Option<(f64, ScaleShift)>,
}

impl FitSmoother {
    /// Blends `fit` at time `t_s` into the running fit and returns it; the residual and counts are
    /// the new fit's. A fit of another model, or time going backwards, starts over.
    pub fn update(&mut self, t_s: f64, fit: ScaleShift) -> ScaleShift {
        let out = match self.last {
            Some((t0, prev)) if prev.model == fit.model && t_s > t0 => {
                let a = 1.0 - (-(t_s - t0) / FISH_FIT_SMOOTHING_S).exp();
                ScaleShift { s: prev.s + a * (fit.s - prev.s), t: prev.t + a * (fit.t - prev.t), ..fit }
            }
            _ => fit,
        };
        self.last = Some((t_s, out));
        out
    }

    /// Forgets the running fit.
    pub fn reset(&mut self) {
        self.last = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broadside_fish_is_at_its_length_over_its_angle() {
        let k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        let centre = Pixel::new(k.cx, k.cy);
        let z = ruler_depth(&k, centre, 0.35 / 3.0, Metres(0.35)).unwrap().0;
        assert!((z - 3.0).abs() < 1e-9);
        // Off the axis the range is along the ray: z is shorter.
        let off = ruler_depth(&k, Pixel::new(k.cx + k.fx, k.cy), 0.35 / 3.0, Metres(0.35)).unwrap().0;
        assert!((off - 3.0 / 2f64.sqrt()).abs() < 1e-9);
        assert_eq!(ruler_depth(&k, centre, 0.0, Metres(0.35)), None);
        assert_eq!(ruler_depth(&k, centre, 0.1, Metres(f64::NAN)), None);
    }

    #[test]
    fn rulers_recover_the_scale_and_reject_odd_fish() {
        // 1/D = 0.2 R + 0.05; 20 fish at 1.5-6 m, lengths +-10 %, two wildly off.
        let mut pairs = heapless::Vec::<ReferencePair, 32>::new();
        for i in 0..20 {
            let d = 1.5 + 4.5 * i as f64 / 19.0;
            let r = (1.0 / d - 0.05) / 0.2;
            let err = if i == 3 {
                1.8
            } else if i == 11 {
                0.5
            } else {
                1.0 + 0.1 * ((i as f64) * 2.3).sin()
            };
            let _ = pairs.push(ReferencePair { relative: r, depth: Metres(d * err) });
        }
        let RulerFit { fit: f, shift_fitted } = fit_rulers(&pairs, 0.1, None).unwrap();
        assert!(shift_fitted);
        assert!((f.t - 0.05).abs() < 0.02, "{f:?}");
        assert_eq!(f.rejected.count_ones(), 2, "{f:?}");
        for d in [2.0, 4.0] {
            let r = (1.0 / d - 0.05) / 0.2;
            assert!((f.depth(r).unwrap().0 / d - 1.0).abs() < 0.05, "{d}: {f:?}");
        }
        assert!(matches!(fit_rulers(&pairs[..2], 0.1, None), Err(FitError::TooFewReferences { .. })));
    }

    #[test]
    fn few_rulers_fit_the_scale_alone_at_the_given_shift() {
        // 1/D = 0.2 R + 0.05, three rulers with nearly the same relative value and lengths a few
        // per cent off: a line through two of them is steep, the scale alone at the shift is not.
        let truth = |d: f64| (1.0 / d - 0.05) / 0.2;
        let pairs: heapless::Vec<ReferencePair, 32> = [(2.0, 1.04), (2.05, 0.97), (2.1, 1.0)]
            .iter()
            .map(|&(d, err)| ReferencePair { relative: truth(d), depth: Metres(d * err) })
            .collect();
        let line = fit_robust(DepthModel::Inverse, &pairs, Metres(0.1), 0.05).unwrap();
        assert!(line.used < MIN_SHIFT_INLIERS);
        // The line through them sends a fish at 1 m far off (or behind the camera).
        assert!(line.depth(truth(1.0)).is_none_or(|d| (d.0 - 1.0).abs() > 0.3), "{line:?}");
        // Without a shift from an earlier fit: refused, not a guess.
        assert!(matches!(fit_rulers(&pairs, 0.1, None), Err(FitError::TooFewInliers { .. })));
        let RulerFit { fit, shift_fitted } = fit_rulers(&pairs, 0.1, Some(0.05)).unwrap();
        assert!(!shift_fitted);
        assert_eq!(fit.t, 0.05);
        assert!((fit.s / 0.2 - 1.0).abs() < 0.05, "{fit:?}");
        // Where the fish go nearer or farther the scale-only fit stays on the truth.
        for d in [1.0, 4.0] {
            assert!((fit.depth(truth(d)).unwrap().0 / d - 1.0).abs() < 0.06, "{d}: {fit:?}");
        }
        // The same pairs plus enough rulers elsewhere fit the shift.
        let mut more = pairs.clone();
        for d in [1.0, 1.5, 3.0, 4.0] {
            let _ = more.push(ReferencePair { relative: truth(d), depth: Metres(d) });
        }
        let RulerFit { fit, shift_fitted } = fit_rulers(&more, 0.1, None).unwrap();
        assert!(shift_fitted);
        assert!((fit.t - 0.05).abs() < 0.01, "{fit:?}");
    }

    #[test]
    fn a_fit_that_moves_the_fish_far_off_their_sizes_is_refused() {
        // Four rulers at 0.9-1.2 m by their sizes; relative values 1/D.
        let by_size: heapless::Vec<ReferencePair, 32> =
            [0.9, 1.0, 1.1, 1.2].iter().map(|&d| ReferencePair { relative: 1.0 / d, depth: Metres(d) }).collect();
        let fit = |s: f64, t: f64| ScaleShift {
            model: super::super::fit::DepthModel::Inverse,
            s,
            t,
            residual_rms: Metres(0.0),
            used: 4,
            rejected: 0,
        };
        // The depth network's ranking corrects the sizes by 20 %: kept.
        assert!(keep_fish_sizes(fit(1.0 / 1.2, 0.0), &by_size).is_ok());
        assert!((depth_over_sizes(&fit(1.0 / 1.2, 0.0), &by_size) - 1.2).abs() < 1e-9);
        // A steep two-pair fit (1/D = 60 R - 52: large scale, shift cancelling most of it) puts the
        // fish at a few centimetres: refused, and so is one that sends them 3x as far.
        let steep = fit(60.0, -52.0);
        assert!(depth_over_sizes(&steep, &by_size) < 0.2);
        assert!(matches!(keep_fish_sizes(steep, &by_size), Err(FitError::OffTheFishSizes(q)) if q < 0.2));
        assert!(matches!(keep_fish_sizes(fit(1.0 / 3.0, 0.0), &by_size), Err(FitError::OffTheFishSizes(_))));
        // Nothing to compare with: kept.
        assert!(keep_fish_sizes(steep, &[]).is_ok());
    }

    #[test]
    fn the_learner_takes_the_median_and_averages_over_time() {
        let mut l = LengthLearner::new(8);
        assert_eq!(l.length(), None);
        // Too few fish: nothing learned.
        let frame = |l: &mut LengthLearner, t: f64, v: &[f64]| {
            v.iter().for_each(|x| l.push(Metres(*x)));
            l.commit(t);
        };
        frame(&mut l, 0.0, &[0.3, 0.3]);
        assert_eq!(l.length(), None);
        // The median, not the mean: one wild fish does not move it.
        frame(&mut l, 0.0, &[0.30, 0.32, 0.34, 3.0]);
        let first = l.length().unwrap().0;
        assert!((first - 0.32).abs() < 1e-12 || (first - 0.34).abs() < 1e-12, "{first}");
        frame(&mut l, LEARNED_LENGTH_SMOOTHING_S, &[0.5, 0.5, 0.5]);
        let want = first + (1.0 - (-1f64).exp()) * (0.5 - first);
        assert!((l.length().unwrap().0 - want).abs() < 1e-12);
        l.reset();
        assert_eq!(l.length(), None);
    }

    #[test]
    fn the_smoother_follows_with_its_time_constant() {
        let f =
            |s| ScaleShift { model: DepthModel::Inverse, s, t: 0.0, residual_rms: Metres(0.0), used: 3, rejected: 0 };
        let mut sm = FitSmoother::default();
        assert_eq!(sm.update(0.0, f(1.0)).s, 1.0);
        let s = sm.update(FISH_FIT_SMOOTHING_S, f(2.0)).s;
        assert!((s - (2.0 - (-1f64).exp())).abs() < 1e-12);
        sm.reset();
        assert_eq!(sm.update(0.0, f(5.0)).s, 5.0);
    }
}
