//! The along-ray part of a fish's speed from its heading (not in the paper).
//!
//! A fish swims head first (the research notes' motion model: "heading follows velocity"). Turned out
//! of the plane square to its line of sight by an angle `a`, its body looks `cos a` times its length,
//! and it moves along the line of sight `tan a` times as fast as across it. So its 3D speed is its
//! speed across the line of sight (the angular speed of its box centre times its range: accurate)
//! divided by the foreshortening `cos a`, which is the box's apparent length (its angular extent times
//! the range) over the fish's own length. This replaces the change of the depth network's depth over
//! the speed span, whose noise was the largest part of the activity index's error
//! (docs/lab-notes/2026-12-activity-index.md; current figures in docs/accuracy.md, ablations). Nearly end-on
//! (below [`MIN_FORESHORTENING`]) the box no longer tells the angle, and the depth change decides
//! ([`speed_from_heading`]).
//!
//! Angles, not pixel offsets times depth: off the optical axis a pixel spans less across the line of
//! sight (by the cosine of the angle off the axis, 0.82 at 35 degrees), and a length or a speed read
//! at the centre of the image and one read at its edge must compare.
//!
//! The fish's length is the [`LENGTH_QUANTILE`] of its apparent lengths (a fish seen broadside now
//! and then shows its whole length), and at least the median apparent length of the recent fish of the
//! whole swarm ([`SWARM_FLOOR_QUANTILE`]; farmed fish are graded to one size, and foreshortening only
//! shortens): a fish tracked for a moment, or seen only turned, is not taken for a short one.
//! Histograms of fixed size: nothing allocates.

use crate::units::Metres;

/// Quantile of a fish's apparent lengths taken as its length.
pub use crate::metric::LENGTH_QUANTILE;

/// Quantile of the swarm's apparent lengths below which no fish's length is taken.
pub const SWARM_FLOOR_QUANTILE: f64 = 0.5;

/// Smallest foreshortening the box is trusted for (a body turned 72.5 degrees out of the plane square to
/// the line of sight): nearer end-on the box no longer tells the angle, and dividing by it would
/// amplify the box's noise.
pub const MIN_FORESHORTENING: f64 = 0.3;

/// Time constant of the swarm's length histogram, s: long against a fish's passage, short against
/// growth.
pub const SWARM_LENGTH_MEMORY_S: f64 = 600.0;

/// Log-spaced bins between [`HIST_MIN_M`] and [`HIST_MAX_M`] (4.4 % wide; the quantile interpolates).
const BINS: usize = 128;
/// Shortest apparent length binned, m (shorter ones count in the first bin).
const HIST_MIN_M: f64 = 0.02;
/// Longest apparent length binned, m (longer ones count in the last bin).
const HIST_MAX_M: f64 = 5.0;

/// Where a fish's speed along the line of sight comes from (`motion.along_ray`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlongRay {
    /// The change of the fish's depth over the speed span (the paper's 3D chord).
    Depth,
    /// The fish's heading: lateral speed over the box's foreshortening (module documentation).
    #[default]
    Heading,
}

impl crate::choice::Choice for AlongRay {
    const ALL: &'static [Self] = &[Self::Depth, Self::Heading];
}

/// A fixed-size histogram of lengths with log-spaced bins, for quantiles without storing samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LengthHistogram {
    counts: [f32; BINS],
    total: f32,
    /// Lowest and highest bin ever counted (decay never empties a bin): the quantile scans only these.
    lo: u8,
    hi: u8,
}

impl Default for LengthHistogram {
    fn default() -> Self {
        Self { counts: [0.0; BINS], total: 0.0, lo: u8::MAX, hi: 0 }
    }
}

impl LengthHistogram {
    fn bin_width() -> f64 {
        (HIST_MAX_M / HIST_MIN_M).ln() / BINS as f64
    }

    /// Counts one length; non-finite or non-positive lengths are ignored.
    pub fn add(&mut self, length: Metres) {
        let l = length.0;
        if !(l.is_finite() && l > 0.0) {
            return;
        }
        let i = ((l / HIST_MIN_M).ln() / Self::bin_width()).floor().clamp(0.0, (BINS - 1) as f64) as usize;
        self.counts[i] += 1.0;
        self.total += 1.0;
        self.lo = self.lo.min(i as u8);
        self.hi = self.hi.max(i as u8);
    }

    /// Multiplies every count by `factor` (in 0..=1): older lengths weigh less.
    pub fn decay(&mut self, factor: f32) {
        for c in &mut self.counts {
            *c *= factor;
        }
        self.total *= factor;
    }

    /// Number of lengths counted (after decay).
    pub fn count(&self) -> f32 {
        self.total
    }

    /// The `q` quantile (0..=1), interpolated log-linearly inside its bin; `None` when empty.
    pub fn quantile(&self, q: f64) -> Option<Metres> {
        if self.total <= 0.0 {
            return None;
        }
        let (q, total) = (q.clamp(0.0, 1.0), f64::from(self.total));
        let at =
            |i: usize, frac: f64| Metres(HIST_MIN_M * ((i as f64 + frac.clamp(0.0, 1.0)) * Self::bin_width()).exp());
        // Scan the counted bins from the nearer end: the high quantile taken per fish and frame
        // crosses few of them.
        let (lo, hi) = (usize::from(self.lo), usize::from(self.hi));
        let bins = || self.counts.iter().enumerate().take(hi + 1).skip(lo);
        let mut passed = 0.0;
        if q <= 0.5 {
            let target = q * total;
            for (i, &c) in bins() {
                let c = f64::from(c);
                if c > 0.0 && passed + c >= target {
                    return Some(at(i, (target - passed) / c));
                }
                passed += c;
            }
        } else {
            let target = (1.0 - q) * total;
            for (i, &c) in bins().rev() {
                let c = f64::from(c);
                if c > 0.0 && passed + c >= target {
                    return Some(at(i, 1.0 - (target - passed) / c));
                }
                passed += c;
            }
        }
        // Decay's rounding left the counts' sum short of the total: the far end of the non-empty bins.
        if q <= 0.5 {
            self.counts.iter().rposition(|&c| c > 0.0).map(|i| at(i, 1.0))
        } else {
            self.counts.iter().position(|&c| c > 0.0).map(|i| at(i, 0.0))
        }
    }
}

/// The swarm's floor for [`fish_length`]: the [`SWARM_FLOOR_QUANTILE`] of its apparent lengths (taken
/// once per frame, not once per fish).
pub fn swarm_floor(swarm: &LengthHistogram) -> Option<Metres> {
    swarm.quantile(SWARM_FLOOR_QUANTILE)
}

/// A fish's length from its own apparent lengths: their [`LENGTH_QUANTILE`], at least the swarm's
/// floor ([`swarm_floor`]).
pub fn fish_length(own: &LengthHistogram, swarm_floor: Option<Metres>) -> Option<Metres> {
    match (own.quantile(LENGTH_QUANTILE), swarm_floor) {
        (Some(a), Some(b)) => Some(Metres(a.0.max(b.0))),
        (a, b) => a.or(b),
    }
}

/// Foreshortening `cos a` of a fish of `length` whose box shows `apparent` metres: `apparent` is
/// `length * cos a + width * sin a` for a body `width_ratio * length` wide (seen end-on, a fish still
/// shows its width), solved for `cos a` in the small-width form, at most 1. Below
/// [`MIN_FORESHORTENING`] (even below 0) it only says "end-on". `None` for a non-positive or
/// non-finite length.
pub fn foreshortening(apparent: Metres, length: Metres, width_ratio: f64) -> Option<f64> {
    ruler_foreshortening(apparent, length, width_ratio).map(|c| c.min(1.0))
}

/// [`foreshortening`] against the ruler's length (the cohort's, while the fish set the depth scale),
/// not capped at 1: a fish longer than the cohort shows more than that length broadside. Capped,
/// the long fish would read at their speed and the short ones fast, and the mean high; uncapped,
/// each fish is off by its length over the cohort's, both ways (docs/accuracy.md).
pub fn ruler_foreshortening(apparent: Metres, length: Metres, width_ratio: f64) -> Option<f64> {
    let (a, l) = (apparent.0, length.0);
    if !(l.is_finite() && l > 0.0 && a.is_finite()) {
        return None;
    }
    let w = width_ratio.clamp(0.0, 0.9);
    Some((a - w * l) / (l * (1.0 - w)))
}

/// A fish's speed from its speed `across` the line of sight and its `foreshortening`: `across /
/// foreshortening`. End-on (foreshortening below [`MIN_FORESHORTENING`]) the box no longer tells how
/// fast the fish moves along the line of sight, so the speed is at least `depth_chord` (the speed
/// with the change of depth, the paper's), and at least `across / MIN_FORESHORTENING`.
pub fn speed_from_heading(across: f64, foreshortening: f64, depth_chord: f64) -> f64 {
    if foreshortening >= MIN_FORESHORTENING {
        across / foreshortening
    } else {
        (across / MIN_FORESHORTENING).max(depth_chord)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles_follow_the_samples() {
        let mut h = LengthHistogram::default();
        assert_eq!(h.quantile(0.5), None);
        for i in 1..=100 {
            h.add(Metres(0.01 * i as f64));
        }
        h.add(Metres(f64::NAN));
        h.add(Metres(-1.0));
        assert_eq!(h.count(), 100.0);
        for (q, want) in [(0.5, 0.5), (0.95, 0.95), (0.1, 0.1)] {
            let got = h.quantile(q).unwrap().0;
            assert!((got / want - 1.0).abs() < 0.045, "q{q}: {got} vs {want}");
        }
        // Decay scales the counts but not the quantiles.
        let before = h.quantile(0.95).unwrap().0;
        h.decay(0.5);
        assert_eq!(h.count(), 50.0);
        assert!((h.quantile(0.95).unwrap().0 - before).abs() < 1e-9);
        // Outside the range: counted at the ends.
        let mut e = LengthHistogram::default();
        e.add(Metres(100.0));
        assert!(e.quantile(1.0).unwrap().0 <= HIST_MAX_M * 1.0001);
    }

    #[test]
    fn a_fish_is_as_long_as_it_looks_at_best_and_no_shorter_than_the_swarms_median() {
        let (mut own, mut swarm) = (LengthHistogram::default(), LengthHistogram::default());
        assert_eq!(fish_length(&own, swarm_floor(&swarm)), None);
        // The swarm's apparent lengths: 0.2-0.4 m, median 0.3 m.
        for i in 0..=200 {
            swarm.add(Metres(0.2 + 0.001 * i as f64));
        }
        // A fish seen a few times nearly end-on: the swarm's median, not its own short look.
        for _ in 0..5 {
            own.add(Metres(0.15));
        }
        assert!((fish_length(&own, swarm_floor(&swarm)).unwrap().0 / 0.3 - 1.0).abs() < 0.045);
        // A long fish, seen broadside now and then: its own 95th percentile.
        for i in 0..100 {
            own.add(Metres(if i % 10 == 0 { 0.5 } else { 0.35 }));
        }
        assert!((fish_length(&own, swarm_floor(&swarm)).unwrap().0 / 0.5 - 1.0).abs() < 0.045);
        // Without a swarm yet, its own.
        assert!((fish_length(&own, None).unwrap().0 / 0.5 - 1.0).abs() < 0.045);
    }

    #[test]
    fn end_on_the_depth_change_decides() {
        assert!((speed_from_heading(0.25, 0.5, 9.0) - 0.5).abs() < 1e-12);
        // Above 1 (a fish longer than the ruler): slower than across.
        assert!((speed_from_heading(0.3, 1.4, 9.0) - 0.3 / 1.4).abs() < 1e-12);
        assert!((speed_from_heading(0.03, 0.1, 0.4) - 0.4).abs() < 1e-12);
        assert!((speed_from_heading(0.03, -0.2, 0.05) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn foreshortening_inverts_the_body_projection() {
        let l = Metres(0.5);
        for deg in [0.0f64, 30.0, 60.0] {
            let a = deg.to_radians();
            let apparent = Metres(0.5 * a.cos() + 0.1 * 0.5 * a.sin());
            let c = foreshortening(apparent, l, 0.1).unwrap();
            // The small-width form is exact at 0 degrees and within 0.05 up to 60 degrees.
            assert!((c - a.cos()).abs() < 0.05, "{deg}: {c} vs {}", a.cos());
        }
        assert!(foreshortening(Metres(0.02), l, 0.1).unwrap() < MIN_FORESHORTENING);
        assert_eq!(foreshortening(Metres(0.9), l, 0.1), Some(1.0));
        // Against the ruler's length, a fish longer than the ruler is not capped.
        let c = ruler_foreshortening(Metres(0.9), l, 0.1).unwrap();
        assert!(
            c > 1.0
                && (foreshortening(Metres(0.3), l, 0.1).unwrap() - ruler_foreshortening(Metres(0.3), l, 0.1).unwrap())
                    .abs()
                    < 1e-12
        );
        assert_eq!(foreshortening(Metres(0.3), Metres(0.0), 0.1), None);
    }
}
