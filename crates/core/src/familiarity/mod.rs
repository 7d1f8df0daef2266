//! The familiarity monitor: "detections look unlike fish". Not in the paper.
//!
//! A detector that meets a scene unlike its training data (other fish, another camera, another
//! tank) does not fail loudly: it keeps giving boxes, and the activity index keeps coming, wrong.
//! This monitor watches what the pipeline already sees on every detector run and compares a sliding
//! window of it (`familiarity.window_s`) with the ranges measured on the detector's familiar data
//! (the renders and the bundled recording) and on a development set of unfamiliar real footage
//! (docs/accuracy.md, "Detections unlike fish"):
//!
//! | statistic | fragments of fish read | range |
//! |---|---|---|
//! | mean detection score | low | `min_score_mean` |
//! | spread of ln(box area) | wide (heads, tails and whole fish mixed) | `max_size_spread` |
//! | share of boxes nested inside another box | high | `max_nested_share` |
//! | share of detections that became confirmed tracks | low | `min_confirmed_share` |
//! | confirmed tracks ended per track-second (1 / mean lifetime) | high | `max_track_turnover_hz` |
//! | detection-count volatility between runs | high | `max_count_volatility` |
//!
//! A window is out of range when at least `min_out` statistics are (one alone can leave its range
//! for a reason of the scene: a dense school nests boxes, a dark hour lowers scores). The flag is
//! raised after the windows have been out of range for `raise_after_s` without a break, and cleared
//! after `clear_after_s` back in range (hysteresis, so it does not flicker). Time is frame time.
//! Every run's summary is logged at trace level (`--log fme_core::familiarity=trace`): the ranges of
//! another detector, or another window, can be measured from it offline.
//!
//! Fixed size: a ring of [`RUNS`] run summaries and a table of [`track::MAX_TRACKS`] track spans;
//! [`FamiliarityMonitor::observe`] never allocates.

mod stats;

pub use stats::{NEST_COVER, RunSummary, StatRanges, WindowStats, nested_count, nested_in};

use crate::geometry::PixelBox;
use crate::track;

/// Detector runs held in the window at most (30 s at 30 runs/s); older runs fall out first.
pub const RUNS: usize = 1024;
/// A confirmed track not matched for this long has ended, s (the tracker's default `max_age_s`).
pub const TRACK_END_S: f64 = 1.0;

/// `[familiarity]`: when the detections stop looking like fish (docs/pipeline.md, "Detections
/// unlike fish"). The ranges are those measured on the training data, with margins
/// (docs/accuracy.md).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FamiliarityConfig {
    /// Watch the detections; off: status bit 10 is never set.
    pub enabled: bool,
    /// The sliding window of detector runs the statistics are taken over, s.
    pub window_s: f64,
    /// Out of range this long without a break raises the flag, s.
    pub raise_after_s: f64,
    /// Back in range this long without a break clears it, s.
    pub clear_after_s: f64,
    /// Detections a window needs before it is judged.
    pub min_detections: u32,
    /// Statistics out of range that make a window out of range.
    pub min_out: u32,
    /// Lowest mean detection score in range.
    pub min_score_mean: f64,
    /// Largest standard deviation of ln(box area) in range.
    pub max_size_spread: f64,
    /// Largest share of detections nested inside another detection in range.
    pub max_nested_share: f64,
    /// Lowest share of detections that became confirmed tracks in range.
    pub min_confirmed_share: f64,
    /// Largest track turnover in range: confirmed tracks ended per second per confirmed track (the
    /// inverse of their mean lifetime), 1/s.
    pub max_track_turnover_hz: f64,
    /// Largest mean change of the detection count between runs, over the mean count, in range.
    pub max_count_volatility: f64,
}

impl Default for FamiliarityConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            // 1 s windows raised after 0.5 s: the flag can rise 1.5 s after a start, so a short
            // clip or a camera that just moved is flagged for most of its updates.
            window_s: 1.0,
            raise_after_s: 0.5,
            clear_after_s: 3.0,
            min_detections: 10,
            min_out: 2,
            // docs/accuracy.md, "Detections unlike fish". The score and the confirmed share separate
            // the familiar data (renders, the bundled recording) from the development set (real
            // DeepFish clips): each limit is halfway between the worst familiar 1 s window and the
            // development set's window nearest to familiar. The others do not separate them and keep
            // three times the largest distance from the ideal seen on the familiar data (nothing
            // nested, no turnover, a steady count), rounded outwards; the size spread, which has no
            // ideal, 1.5 times its largest.
            min_score_mean: 0.57,
            max_size_spread: 1.4,
            max_nested_share: 0.12,
            min_confirmed_share: 0.31,
            max_track_turnover_hz: 0.7,
            max_count_volatility: 0.25,
        }
    }
}

impl FamiliarityConfig {
    /// Checks ranges; the message starts with the key.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |k: &str, v: f64, max: f64| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(format!("familiarity.{k} must be a positive number of seconds <= {max}, got {v}"))
            }
        };
        pos("window_s", self.window_s, 30.0)?;
        pos("raise_after_s", self.raise_after_s, 3600.0)?;
        pos("clear_after_s", self.clear_after_s, 3600.0)?;
        if !(1..=6).contains(&self.min_out) {
            return Err(format!("familiarity.min_out must be 1..=6 (there are six statistics), got {}", self.min_out));
        }
        for (k, v) in [
            ("min_score_mean", self.min_score_mean),
            ("max_nested_share", self.max_nested_share),
            ("min_confirmed_share", self.min_confirmed_share),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(format!("familiarity.{k} must be 0..1, got {v}"));
            }
        }
        for (k, v) in [
            ("max_size_spread", self.max_size_spread),
            ("max_track_turnover_hz", self.max_track_turnover_hz),
            ("max_count_volatility", self.max_count_volatility),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("familiarity.{k} must be a positive number, got {v}"));
            }
        }
        Ok(())
    }
}

/// Which statistics of a window are out of range (one bit per statistic, in the order of
/// [`OutOfRange::NAMES`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OutOfRange(pub u8);

impl OutOfRange {
    /// The statistics' short names (console, logs).
    pub const NAMES: [&'static str; 6] = ["score", "size", "nested", "confirmed", "turnover", "volatility"];

    /// How many are out of range.
    pub fn count(self) -> u32 {
        self.0.count_ones()
    }

    /// The names of those out of range.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Self::NAMES.into_iter().enumerate().filter(move |(i, _)| self.0 & (1 << i) != 0).map(|(_, n)| n)
    }

    /// Judges `w` against the ranges of `cfg` (a statistic the window cannot say is in range).
    pub fn judge(w: &WindowStats, cfg: &FamiliarityConfig) -> Self {
        let tests = [
            w.score_mean.is_some_and(|v| v < cfg.min_score_mean),
            w.size_spread.is_some_and(|v| v > cfg.max_size_spread),
            w.nested_share.is_some_and(|v| v > cfg.max_nested_share),
            w.confirmed_share.is_some_and(|v| v < cfg.min_confirmed_share),
            w.track_turnover_hz.is_some_and(|v| v > cfg.max_track_turnover_hz),
            w.count_volatility.is_some_and(|v| v > cfg.max_count_volatility),
        ];
        Self(tests.iter().enumerate().fold(0, |acc, (i, &t)| acc | (u8::from(t) << i)))
    }
}

/// What the monitor says now (the console's `status`, `fme eval`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FamiliarityState {
    /// The flag: the detections look unlike fish (status bit 10).
    pub unlike_fish: bool,
    /// The last judged window's statistics (`None` before the first judged window).
    pub stats: Option<WindowStats>,
    /// Which of them are out of range.
    pub out: OutOfRange,
}

impl FamiliarityState {
    /// One line for the console's `status` (after `detections `): the verdict, then the last
    /// window's statistics and those out of range.
    pub fn describe(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::from(if self.unlike_fish { "LOOK UNLIKE FISH" } else { "look like fish" });
        let Some(w) = self.stats else {
            s.push_str(" (not judged yet)");
            return s;
        };
        let f =
            |v: Option<f64>, scale: f64, unit: &str| v.map_or("-".to_string(), |v| format!("{:.2}{unit}", v * scale));
        let _ = write!(
            s,
            " (score {}, size-spread {}, nested {}, confirmed {}, turnover {}, volatility {}",
            f(w.score_mean, 1.0, ""),
            f(w.size_spread, 1.0, ""),
            f(w.nested_share, 100.0, " %"),
            f(w.confirmed_share, 100.0, " %"),
            f(w.track_turnover_hz, 1.0, "/s"),
            f(w.count_volatility, 1.0, "")
        );
        if self.out.count() > 0 {
            s.push_str("; out of range:");
            for n in self.out.names() {
                s.push(' ');
                s.push_str(n);
            }
        }
        s.push(')');
        s
    }
}

#[derive(Debug, Clone, Copy)]
struct Span {
    id: u32,
    last: f64,
}

/// The monitor: fed once per detector run (pure; time comes in with each run).
#[derive(Debug, Clone)]
pub struct FamiliarityMonitor {
    cfg: FamiliarityConfig,
    runs: Box<[RunSummary; RUNS]>,
    head: usize,
    len: usize,
    spans: heapless::Vec<Span, { track::MAX_TRACKS }>,
    boxes: heapless::Vec<PixelBox, { track::MAX_DETS }>,
    first_t: Option<f64>,
    /// Since when the windows have been out of range (raised: in range) without a break.
    since: Option<f64>,
    state: FamiliarityState,
}

impl FamiliarityMonitor {
    /// A monitor with the given settings (validate user input first).
    pub fn new(cfg: FamiliarityConfig) -> Self {
        Self {
            cfg,
            runs: Box::new([RunSummary::default(); RUNS]),
            head: 0,
            len: 0,
            spans: heapless::Vec::new(),
            boxes: heapless::Vec::new(),
            first_t: None,
            since: None,
            state: FamiliarityState::default(),
        }
    }

    /// Forgets everything (time went backwards: the camera restarted).
    pub fn reset(&mut self) {
        self.head = 0;
        self.len = 0;
        self.spans.clear();
        self.first_t = None;
        self.since = None;
        self.state = FamiliarityState::default();
    }

    /// The current state.
    pub fn state(&self) -> FamiliarityState {
        self.state
    }

    /// Whether the flag is raised.
    pub fn unlike_fish(&self) -> bool {
        self.state.unlike_fish
    }

    fn previous(&self) -> Option<&RunSummary> {
        (self.len > 0).then(|| &self.runs[(self.head + RUNS - 1) % RUNS])
    }

    /// One detector run at frame time `t`: its detections (box, score) and the ids of the confirmed
    /// tracks the tracker matched to them. Returns the flag.
    pub fn observe(
        &mut self,
        t: f64,
        detections: impl Iterator<Item = (PixelBox, f64)> + Clone,
        matched: impl Iterator<Item = u32>,
    ) -> bool {
        if !self.cfg.enabled || !t.is_finite() {
            return self.state.unlike_fish;
        }
        self.boxes.clear();
        for (b, _) in detections.clone() {
            if self.boxes.push(b).is_err() {
                break;
            }
        }
        let previous = self.previous().map(|r| r.dets);
        let mut run = RunSummary::of_detections(t, &self.boxes, detections.map(|(_, s)| s), previous);
        // Track spans: a matched id is alive now; one not matched for TRACK_END_S has ended.
        for id in matched {
            run.confirmed += 1;
            match self.spans.iter_mut().find(|s| s.id == id) {
                Some(s) => s.last = t,
                None => {
                    if self.spans.is_full() {
                        self.end_oldest(&mut run);
                    }
                    let _ = self.spans.push(Span { id, last: t });
                }
            }
        }
        let mut i = 0;
        while i < self.spans.len() {
            let s = self.spans[i];
            if t - s.last > TRACK_END_S {
                Self::end(&mut run);
                self.spans.swap_remove(i);
            } else {
                i += 1;
            }
        }
        // One line per run (`--log fme_core::familiarity=trace`): what a window's statistics are made
        // of, to measure the ranges of another detector or try another window offline.
        tracing::trace!(
            t,
            dets = run.dets,
            score_sum = run.score_sum,
            log_area_sum = run.log_area_sum,
            log_area_sq_sum = run.log_area_sq_sum,
            nested = run.nested,
            confirmed = run.confirmed,
            count_change = run.count_change,
            has_previous = run.has_previous,
            ended = run.ended,
            "familiarity run"
        );
        self.runs[self.head] = run;
        self.head = (self.head + 1) % RUNS;
        self.len = (self.len + 1).min(RUNS);
        let first = *self.first_t.get_or_insert(t);
        // The window must be full before it is judged (a start has no tracks confirmed yet).
        if t - first < self.cfg.window_s {
            return self.state.unlike_fish;
        }
        let from = t - self.cfg.window_s;
        let w = WindowStats::of(self.window().filter(|r| r.t > from), self.cfg.window_s);
        if w.detections < self.cfg.min_detections {
            // Too little to judge (an empty cage, the lights off): the flag holds.
            self.since = None;
            return self.state.unlike_fish;
        }
        let out = OutOfRange::judge(&w, &self.cfg);
        self.state.stats = Some(w);
        self.state.out = out;
        let out_now = out.count() >= self.cfg.min_out;
        if out_now == self.state.unlike_fish {
            self.since = None;
        } else {
            let since = *self.since.get_or_insert(t);
            let hold = if out_now { self.cfg.raise_after_s } else { self.cfg.clear_after_s };
            if t - since >= hold {
                self.state.unlike_fish = out_now;
                self.since = None;
            }
        }
        self.state.unlike_fish
    }

    /// The runs held, newest first.
    fn window(&self) -> impl Iterator<Item = &RunSummary> {
        (0..self.len).map(move |k| &self.runs[(self.head + RUNS - 1 - k) % RUNS])
    }

    fn end(run: &mut RunSummary) {
        run.ended += 1;
    }

    fn end_oldest(&mut self, run: &mut RunSummary) {
        if let Some((i, _)) = self.spans.iter().enumerate().min_by(|a, b| a.1.last.total_cmp(&b.1.last)) {
            self.spans.swap_remove(i);
            Self::end(run);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> FamiliarityConfig {
        FamiliarityConfig::default()
    }

    /// `n` fish-like boxes side by side, all matched to confirmed tracks 1..=n that started at 0.
    fn fish_run(m: &mut FamiliarityMonitor, t: f64, n: u32) -> bool {
        let dets: Vec<(PixelBox, f64)> =
            (0..n).map(|i| (PixelBox::new(f64::from(i) * 60.0, 100.0, 50.0, 20.0), 0.85)).collect();
        m.observe(t, dets.iter().copied(), 1..=n)
    }

    /// Fragments: a few fish boxes with heads and tails inside them, low scores, new track ids that
    /// live 0.3 s each, and a count that jumps between runs.
    fn fragment_run(m: &mut FamiliarityMonitor, t: f64, k: u32) -> bool {
        let mut dets = Vec::new();
        for i in 0..(6 + 4 * (k % 2)) {
            let x = f64::from(i) * 200.0;
            dets.push((PixelBox::new(x, 100.0, 180.0, 60.0), 0.4));
            dets.push((PixelBox::new(x + 5.0, 110.0, 40.0, 40.0), 0.35));
            dets.push((PixelBox::new(x + 130.0, 105.0, 45.0, 50.0), 0.33));
        }
        let base = 1000 + (k / 3) * 20;
        m.observe(t, dets.iter().copied(), (0..8).map(|j| base + j))
    }

    #[test]
    fn fish_never_raise_the_flag() {
        let mut m = FamiliarityMonitor::new(cfg());
        for k in 0..300 {
            assert!(!fish_run(&mut m, 0.1 * f64::from(k), 20), "run {k}");
        }
        let s = m.state();
        assert_eq!(s.out, OutOfRange(0), "{s:?}");
        assert!(s.stats.is_some());
    }

    #[test]
    fn fragments_raise_after_the_hold_and_clear_after_theirs() {
        let c = cfg();
        let mut m = FamiliarityMonitor::new(c);
        let mut raised_at = None;
        for k in 0..100 {
            let t = 0.1 * f64::from(k);
            if fragment_run(&mut m, t, k) && raised_at.is_none() {
                raised_at = Some(t);
            }
        }
        let raised_at = raised_at.expect("raised");
        // Judged once the window is full, raised `raise_after_s` later.
        assert!(raised_at >= c.window_s + c.raise_after_s - 1e-9, "{raised_at}");
        assert!(raised_at <= c.window_s + c.raise_after_s + 0.5, "{raised_at}");
        let out: Vec<&str> = m.state().out.names().collect();
        assert!(out.len() >= 4, "{out:?}");
        // Back to fish: the flag holds while the window still holds fragments, then clear_after_s.
        let mut cleared_at = None;
        for k in 100..300 {
            let t = 0.1 * f64::from(k);
            if !fish_run(&mut m, t, 20) && cleared_at.is_none() {
                cleared_at = Some(t);
            }
        }
        let cleared_at = cleared_at.expect("cleared");
        assert!(cleared_at >= 10.0 + c.clear_after_s - 1e-9, "{cleared_at}");
        assert!(cleared_at <= 10.0 + c.window_s + c.clear_after_s + 1.0, "{cleared_at}");
    }

    #[test]
    fn a_short_excursion_does_not_flicker_the_flag() {
        let mut m = FamiliarityMonitor::new(cfg());
        for k in 0..50 {
            fish_run(&mut m, 0.1 * f64::from(k), 20);
        }
        // A fifth of a second of fragments is not enough to leave the range for raise_after_s.
        for k in 50..52 {
            assert!(!fragment_run(&mut m, 0.1 * f64::from(k), k));
        }
        for k in 55..200 {
            assert!(!fish_run(&mut m, 0.1 * f64::from(k), 20), "run {k}");
        }
    }

    #[test]
    fn off_or_too_few_detections_never_raise() {
        let mut m = FamiliarityMonitor::new(FamiliarityConfig { enabled: false, ..cfg() });
        for k in 0..100 {
            assert!(!fragment_run(&mut m, 0.1 * f64::from(k), k));
        }
        let mut m = FamiliarityMonitor::new(FamiliarityConfig { min_detections: 100_000, ..cfg() });
        for k in 0..100 {
            assert!(!fragment_run(&mut m, 0.1 * f64::from(k), k));
        }
        assert_eq!(m.state().stats, None);
    }

    #[test]
    fn reset_forgets_the_window_and_the_flag() {
        let mut m = FamiliarityMonitor::new(cfg());
        for k in 0..100 {
            fragment_run(&mut m, 0.1 * f64::from(k), k);
        }
        assert!(m.unlike_fish());
        m.reset();
        assert_eq!(m.state(), FamiliarityState::default());
        assert!(!fish_run(&mut m, 0.0, 20));
    }

    #[test]
    fn tracks_end_once_unmatched_for_track_end_s() {
        let mut m = FamiliarityMonitor::new(FamiliarityConfig { min_detections: 1, ..cfg() });
        let d = [(PixelBox::new(0.0, 0.0, 10.0, 10.0), 0.9)];
        // Track 1 is matched until 0.5 s, track 2 until 3 s, track 3 throughout.
        let mut ended_at = Vec::new();
        for k in 0..=50u32 {
            let t = 0.1 * f64::from(k);
            let ids: Vec<u32> = [(1, 0.5), (2, 3.0), (3, 9.0)]
                .into_iter()
                .filter(|&(_, end)| t <= end + 1e-9)
                .map(|(id, _)| id)
                .collect();
            m.observe(t, d.iter().copied(), ids.into_iter());
            let r = m.window().next().copied().expect("run");
            ended_at.extend(std::iter::repeat_n(t, r.ended as usize));
        }
        assert_eq!(ended_at.len(), 2, "{ended_at:?}");
        assert!((ended_at[0] - (0.5 + TRACK_END_S + 0.1)).abs() < 1e-6, "{ended_at:?}");
        assert!((ended_at[1] - (3.0 + TRACK_END_S + 0.1)).abs() < 1e-6, "{ended_at:?}");
    }

    #[test]
    fn the_console_line_names_the_verdict_and_what_is_out() {
        assert_eq!(FamiliarityState::default().describe(), "look like fish (not judged yet)");
        let mut m = FamiliarityMonitor::new(cfg());
        for k in 0..100 {
            fragment_run(&mut m, 0.1 * f64::from(k), k);
        }
        let line = m.state().describe();
        assert!(line.starts_with("LOOK UNLIKE FISH (score 0.3"), "{line}");
        assert!(line.contains("out of range: score") && line.contains("nested"), "{line}");
    }

    #[test]
    fn config_checks_name_the_key() {
        assert!(cfg().validate().is_ok());
        for (c, key) in [
            (FamiliarityConfig { window_s: 0.0, ..cfg() }, "familiarity.window_s"),
            (FamiliarityConfig { window_s: 31.0, ..cfg() }, "familiarity.window_s"),
            (FamiliarityConfig { min_out: 0, ..cfg() }, "familiarity.min_out"),
            (FamiliarityConfig { max_nested_share: 1.5, ..cfg() }, "familiarity.max_nested_share"),
            (FamiliarityConfig { max_size_spread: f64::NAN, ..cfg() }, "familiarity.max_size_spread"),
        ] {
            let e = c.validate().expect_err(key);
            assert!(e.starts_with(key), "{e}");
        }
    }
}
