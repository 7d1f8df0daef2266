//! The statistics of the familiarity monitor: what one detector run looked like ([`RunSummary`]) and
//! what a window of runs looks like ([`WindowStats`]). Pure functions of boxes, scores and times.

use crate::geometry::PixelBox;

/// A box counts as nested inside another when at least this share of its area lies inside a larger
/// box of the same run: a head, tail or flank fired on inside the fish's own box. Two fish that
/// overlap in the image rarely put 90 % of one inside the other's box.
pub const NEST_COVER: f64 = 0.9;

/// Whether `inner` lies at least [`NEST_COVER`] inside `outer`, and `outer` is the larger box.
pub fn nested_in(inner: &PixelBox, outer: &PixelBox) -> bool {
    let a = inner.area();
    if a.is_nan() || a <= 0.0 || outer.area() <= a {
        return false;
    }
    let iw = (inner.right().min(outer.right()) - inner.x.max(outer.x)).max(0.0);
    let ih = (inner.bottom().min(outer.bottom()) - inner.y.max(outer.y)).max(0.0);
    iw * ih >= NEST_COVER * a
}

/// Boxes of `boxes` nested inside another of them ([`nested_in`]); O(n^2), no allocation.
pub fn nested_count(boxes: &[PixelBox]) -> u32 {
    let mut n = 0;
    for (i, b) in boxes.iter().enumerate() {
        if boxes.iter().enumerate().any(|(j, o)| j != i && nested_in(b, o)) {
            n += 1;
        }
    }
    n
}

/// What one detector run contributed to the window (fixed size; sums, so windows add up).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunSummary {
    /// Frame time of the run, s.
    pub t: f64,
    /// Detections.
    pub dets: u32,
    /// Sum of their scores.
    pub score_sum: f64,
    /// Sum of ln(area / 1 px^2) over the detections.
    pub log_area_sum: f64,
    /// Sum of ln(area)^2.
    pub log_area_sq_sum: f64,
    /// Detections nested inside another detection of the run.
    pub nested: u32,
    /// Confirmed tracks the tracker matched to a detection of this run.
    pub confirmed: u32,
    /// |detections now - detections at the previous run| (0 at the first run after a start).
    pub count_change: u32,
    /// Whether `count_change` is meaningful (there was a previous run).
    pub has_previous: bool,
    /// Confirmed tracks that ended at this run (not matched for [`super::TRACK_END_S`]).
    pub ended: u32,
}

impl RunSummary {
    /// The detection part of a run at `t`: count, scores, sizes and nesting of `boxes` (with their
    /// `scores`); `previous`: the detection count of the previous run, if any.
    pub fn of_detections(t: f64, boxes: &[PixelBox], scores: impl Iterator<Item = f64>, previous: Option<u32>) -> Self {
        let n = boxes.len() as u32;
        let (mut s1, mut s2) = (0.0, 0.0);
        for b in boxes {
            let l = b.area().max(1.0).ln();
            s1 += l;
            s2 += l * l;
        }
        Self {
            t,
            dets: n,
            score_sum: scores.filter(|s| s.is_finite()).sum(),
            log_area_sum: s1,
            log_area_sq_sum: s2,
            nested: nested_count(boxes),
            confirmed: 0,
            count_change: previous.map_or(0, |p| p.abs_diff(n)),
            has_previous: previous.is_some(),
            ended: 0,
        }
    }
}

/// The statistics of a window of detector runs; each is `None` when the window holds too little to
/// say (no detections, fewer than [`MIN_ENDED`] ended tracks, ...).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct WindowStats {
    /// Detector runs in the window.
    pub runs: u32,
    /// Detections in the window.
    pub detections: u32,
    /// Mean detection score.
    pub score_mean: Option<f64>,
    /// Standard deviation of ln(box area): the spread of detection sizes, whatever the resolution
    /// and the fish's size (a factor `k` on every area leaves it unchanged).
    pub size_spread: Option<f64>,
    /// Share of detections nested inside another detection of the same run ([`NEST_COVER`]).
    pub nested_share: Option<f64>,
    /// Confirmed tracks matched per detection: the share of detections that became confirmed tracks.
    pub confirmed_share: Option<f64>,
    /// Confirmed tracks ended per second per confirmed track (the inverse of the tracks' mean
    /// lifetime), 1/s.
    pub track_turnover_hz: Option<f64>,
    /// Mean |change of the detection count| between successive runs over the mean count: the
    /// fish count's volatility.
    pub count_volatility: Option<f64>,
}

impl WindowStats {
    /// The statistics of `runs` (any order), which cover `span_s` seconds.
    pub fn of<'a>(runs: impl Iterator<Item = &'a RunSummary>, span_s: f64) -> Self {
        let (mut n, mut k) = (0u32, 0u32);
        let (mut score, mut s1, mut s2) = (0.0, 0.0, 0.0);
        let (mut nested, mut confirmed, mut ended) = (0u32, 0u32, 0u32);
        let (mut change, mut changes) = (0u64, 0u32);
        for r in runs {
            k += 1;
            n += r.dets;
            score += r.score_sum;
            s1 += r.log_area_sum;
            s2 += r.log_area_sq_sum;
            nested += r.nested;
            confirmed += r.confirmed;
            ended += r.ended;
            if r.has_previous {
                change += u64::from(r.count_change);
                changes += 1;
            }
        }
        let nf = f64::from(n);
        let per_det = |x: u32| (n > 0).then(|| f64::from(x) / nf);
        let mean_count = nf / f64::from(k.max(1));
        Self {
            runs: k,
            detections: n,
            score_mean: (n > 0).then(|| score / nf),
            size_spread: (n >= 2).then(|| {
                let m = s1 / nf;
                ((s2 / nf - m * m).max(0.0) * nf / (nf - 1.0)).sqrt()
            }),
            nested_share: per_det(nested),
            confirmed_share: per_det(confirmed).map(|s| s.min(1.0)),
            track_turnover_hz: (confirmed > 0 && span_s > 0.0)
                .then(|| f64::from(ended) / (f64::from(confirmed) / f64::from(k) * span_s)),
            count_volatility: (changes > 0 && mean_count > 0.0)
                .then(|| change as f64 / f64::from(changes) / mean_count),
        }
    }
}

/// The least and greatest value of each statistic over many windows (`fme eval --json`'s
/// `familiarity`: the ranges the thresholds are set from, docs/accuracy.md).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StatRanges {
    /// Windows judged.
    pub windows: u64,
    /// [least, greatest] mean detection score.
    pub score_mean: Option<[f64; 2]>,
    /// [least, greatest] spread of ln(box area).
    pub size_spread: Option<[f64; 2]>,
    /// [least, greatest] nested share.
    pub nested_share: Option<[f64; 2]>,
    /// [least, greatest] confirmed share.
    pub confirmed_share: Option<[f64; 2]>,
    /// [least, greatest] track turnover, 1/s.
    pub track_turnover_hz: Option<[f64; 2]>,
    /// [least, greatest] detection-count volatility.
    pub count_volatility: Option<[f64; 2]>,
}

impl StatRanges {
    /// Widens the ranges to hold `w`.
    pub fn add(&mut self, w: &WindowStats) {
        fn widen(r: &mut Option<[f64; 2]>, v: Option<f64>) {
            if let Some(v) = v.filter(|v| v.is_finite()) {
                *r = Some(r.map_or([v, v], |[lo, hi]| [lo.min(v), hi.max(v)]));
            }
        }
        self.windows += 1;
        widen(&mut self.score_mean, w.score_mean);
        widen(&mut self.size_spread, w.size_spread);
        widen(&mut self.nested_share, w.nested_share);
        widen(&mut self.confirmed_share, w.confirmed_share);
        widen(&mut self.track_turnover_hz, w.track_turnover_hz);
        widen(&mut self.count_volatility, w.count_volatility);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(x: f64, y: f64, w: f64, h: f64) -> PixelBox {
        PixelBox::new(x, y, w, h)
    }

    #[test]
    fn nesting_needs_most_of_the_box_inside_a_larger_one() {
        let fish = b(0.0, 0.0, 100.0, 40.0);
        let head = b(70.0, 5.0, 25.0, 30.0);
        assert!(nested_in(&head, &fish));
        assert!(!nested_in(&fish, &head), "the larger box is never nested in the smaller");
        // Half of it sticks out: two overlapping fish, not a fragment.
        assert!(!nested_in(&b(80.0, 5.0, 40.0, 30.0), &fish));
        assert!(!nested_in(&fish, &fish), "a box is not nested in an equal box");
        assert_eq!(nested_count(&[fish, head, b(200.0, 0.0, 50.0, 20.0)]), 1);
        assert_eq!(nested_count(&[]), 0);
    }

    #[test]
    fn size_spread_is_scale_free_and_zero_for_equal_boxes() {
        let boxes = [b(0.0, 0.0, 10.0, 10.0), b(0.0, 0.0, 20.0, 20.0), b(0.0, 0.0, 40.0, 10.0)];
        let scaled: Vec<PixelBox> = boxes.iter().map(|x| b(0.0, 0.0, 3.0 * x.w, 3.0 * x.h)).collect();
        let s = |bs: &[PixelBox]| {
            let r = RunSummary::of_detections(0.0, bs, bs.iter().map(|_| 0.5), None);
            WindowStats::of([r].iter(), 1.0).size_spread.expect("spread")
        };
        assert!((s(&boxes) - s(&scaled)).abs() < 1e-9);
        assert!(s(&boxes) > 0.3);
        let same = [b(0.0, 0.0, 10.0, 10.0); 4];
        assert!(s(&same).abs() < 1e-9);
    }

    #[test]
    fn window_shares_and_means() {
        let fish = b(0.0, 0.0, 100.0, 40.0);
        let head = b(70.0, 5.0, 25.0, 30.0);
        let mut r1 = RunSummary::of_detections(0.0, &[fish, head], [0.9, 0.3].into_iter(), None);
        r1.confirmed = 1;
        let mut r2 = RunSummary::of_detections(0.1, &[fish, head, head, fish], [0.8; 4].into_iter(), Some(2));
        r2.confirmed = 2;
        r2.ended = 3;
        let w = WindowStats::of([r1, r2].iter(), 2.0);
        assert_eq!((w.runs, w.detections), (2, 6));
        assert!((w.score_mean.expect("score") - (1.2 + 3.2) / 6.0).abs() < 1e-12);
        // The head in r1; in r2 both heads (the equal fish boxes are not nested in each other).
        assert!((w.nested_share.expect("nested") - 3.0 / 6.0).abs() < 1e-12);
        assert!((w.confirmed_share.expect("confirmed") - 0.5).abs() < 1e-12);
        // 3 tracks ended in 2 s with 1.5 confirmed tracks on average: 1 per track-second.
        assert!((w.track_turnover_hz.expect("turnover") - 1.0).abs() < 1e-12);
        // One change of 2 over a mean count of 3.
        assert!((w.count_volatility.expect("volatility") - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn ranges_hold_every_window() {
        let mut r = StatRanges::default();
        r.add(&WindowStats { score_mean: Some(0.5), nested_share: None, ..WindowStats::default() });
        r.add(&WindowStats { score_mean: Some(0.7), nested_share: Some(0.1), ..WindowStats::default() });
        r.add(&WindowStats { score_mean: Some(0.6), ..WindowStats::default() });
        assert_eq!(r.windows, 3);
        assert_eq!(r.score_mean, Some([0.5, 0.7]));
        assert_eq!(r.nested_share, Some([0.1, 0.1]));
        assert_eq!(r.size_spread, None);
    }

    #[test]
    fn too_little_data_says_nothing() {
        let w = WindowStats::of([].iter(), 1.0);
        assert_eq!(w, WindowStats::default());
        let mut r = RunSummary::of_detections(0.0, &[b(0.0, 0.0, 5.0, 5.0)], [0.5].into_iter(), None);
        r.ended = 2;
        let w = WindowStats::of([r].iter(), 1.0);
        assert_eq!(w.size_spread, None, "one box has no spread");
        assert_eq!(w.track_turnover_hz, None, "no confirmed track");
        assert_eq!(w.count_volatility, None, "no previous run");
        assert!(w.score_mean.is_some());
    }
}
