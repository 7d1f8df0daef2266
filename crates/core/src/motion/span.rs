//! A fish's speed over the speed span from its stored positions: the chord or the regression, along
//! the line of sight from its depth or its heading (`motion.speed_method`, `motion.along_ray`).

use super::heading::{
    AlongRay, LengthHistogram, fish_length, foreshortening, ruler_foreshortening, speed_from_heading,
};
use super::{MotionConfig, SpeedMethod};
use crate::geometry::angle_between;
use crate::units::Metres;
use heapless::Deque;

/// Positions kept per track for the speed span.
pub(super) const POSITIONS: usize = 32;

/// One stored observation of a track.
#[derive(Debug, Clone, Copy)]
pub(super) struct Position {
    /// Frame time, s.
    pub t: f64,
    /// Box centre lifted with the corrected depth, camera frame, m (speed norms are the same as in
    /// the world frame; the camera frame separates motion across and along the line of sight).
    pub p: [f64; 3],
    /// Distance from the camera, m.
    pub range: f64,
    /// Apparent body length ([`apparent_length`]), m; NaN when unknown.
    pub apparent: f64,
}

impl Position {
    /// Unit line of sight: what the box motion measures without depth.
    fn unit(&self) -> [f64; 3] {
        [self.p[0] / self.range, self.p[1] / self.range, self.p[2] / self.range]
    }
}

/// Within `span` of `t` (the same tolerance everywhere).
pub(super) fn within(sample: &Position, t: f64, span: f64) -> bool {
    t - sample.t <= span * (1.0 + 1e-6) + 1e-9
}

/// Least-squares velocity of `coords(sample)` over the samples within `span` of `t`; `None` for
/// fewer than 3. Returns the velocity's norm and the time it refers to (the window's mean time).
fn regression_speed(
    samples: &Deque<Position, POSITIONS>,
    t: f64,
    span: f64,
    coords: impl Fn(&Position) -> [f64; 3],
) -> Option<(f64, f64)> {
    let inside = || samples.iter().filter(|p| within(p, t, span));
    let n = inside().count();
    if n < 3 {
        return None;
    }
    let tm = inside().map(|p| p.t).sum::<f64>() / n as f64;
    let mut pm = [0.0; 3];
    for p in inside() {
        for (m, x) in pm.iter_mut().zip(coords(p)) {
            *m += x / n as f64;
        }
    }
    let (mut stt, mut stp) = (0.0, [0.0; 3]);
    for p in inside() {
        let dt = p.t - tm;
        stt += dt * dt;
        for ((s, x), m) in stp.iter_mut().zip(coords(p)).zip(pm) {
            *s += dt * (x - m);
        }
    }
    (stt > 0.0).then(|| ((stp[0] * stp[0] + stp[1] * stp[1] + stp[2] * stp[2]).sqrt() / stt, tm))
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Where a fish's length comes from when none is configured.
#[derive(Debug, Clone, Copy)]
pub(super) struct FishLengths {
    /// The fish fit's ruler length (every fish is as long as the ruler on its scale).
    pub ruler: Option<Metres>,
    /// The swarm's floor under any one fish's length.
    pub swarm_floor: Option<Metres>,
}

impl FishLengths {
    /// The ruler's length, else the fish's own from `own` (its apparent lengths).
    pub fn estimate(&self, own: &LengthHistogram) -> Option<Metres> {
        self.ruler.or_else(|| fish_length(own, self.swarm_floor))
    }
}

/// A fish's speed between `reference` and `now` (`motion.along_ray`, `motion.speed_method`), and
/// the time it refers to.
pub(super) fn speed_over_span(
    motion: &MotionConfig,
    lengths: FishLengths,
    positions: &Deque<Position, POSITIONS>,
    own: &LengthHistogram,
    now: Position,
    reference: Position,
) -> (f64, f64) {
    let (t, span) = (now.t, motion.speed_span_s.0);
    let regression = |coords: fn(&Position) -> [f64; 3]| match motion.speed_method {
        SpeedMethod::Regression => regression_speed(positions, t, span, coords),
        SpeedMethod::Chord => None,
    };
    let chord_time = 0.5 * (t + reference.t);
    match motion.along_ray {
        AlongRay::Depth => {
            regression(|p| p.p).unwrap_or_else(|| (distance(now.p, reference.p) / (t - reference.t), chord_time))
        }
        AlongRay::Heading => {
            // Speed across the line of sight (its angular speed times the mean range of the span),
            // over the foreshortening averaged over the same span: one pass for the mean range and
            // the mean apparent length where known.
            let (mut n_in, mut range_sum, mut n_seen, mut seen_sum) = (0usize, 0.0, 0usize, 0.0);
            for p in positions.iter().filter(|p| p.t >= reference.t) {
                n_in += 1;
                range_sum += p.range;
                if p.apparent.is_finite() && p.apparent > 0.0 {
                    n_seen += 1;
                    seen_sum += p.apparent;
                }
            }
            let range = range_sum / n_in as f64;
            let (across, t_ref) = regression(Position::unit)
                .map(|(w, tm)| (w * range, tm))
                .unwrap_or_else(|| (range * angle_between(now.p, reference.p) / (t - reference.t), chord_time));
            let depth_chord =
                regression(|p| p.p).map_or_else(|| distance(now.p, reference.p) / (t - reference.t), |(v, _)| v);
            let apparent = (n_seen > 0).then(|| Metres(seen_sum / n_seen as f64));
            let cos = apparent.zip(lengths.estimate(own)).and_then(|(a, l)| match lengths.ruler {
                Some(_) => ruler_foreshortening(a, l, motion.body_width_ratio),
                None => foreshortening(a, l, motion.body_width_ratio),
            });
            (cos.map_or(f64::NAN, |c| speed_from_heading(across, c, depth_chord)), t_ref)
        }
    }
}
