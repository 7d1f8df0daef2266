//! Per-track post-processing state: eq. 3 and eq. 4 detectors with their EWMA corrections.

use super::{BoxAnchor, HISTORY, PostprocessConfig, ewma};
use crate::geometry::PixelBox;
use crate::units::{Metres, Seconds};
use heapless::Deque;

#[derive(Debug, Clone, Copy)]
struct SizeSample {
    t: f64,
    w: f64,
    h: f64,
    wc: f64,
    hc: f64,
}

/// Result of the box-fluctuation step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxCorrection {
    /// The corrected box (equal to the input when nothing fired).
    pub bbox: PixelBox,
    /// Eq. 3's width detector fired and the width was replaced.
    pub width_corrected: bool,
    /// Eq. 3's height detector fired and the height was replaced.
    pub height_corrected: bool,
}

/// Fixed-size post-processing state of one track. Call [`TrackFilter::correct_box`] and then
/// [`TrackFilter::correct_depth`] (with the depth sampled at the corrected box centre) once per
/// observation, with increasing timestamps.
#[derive(Debug, Clone, Default)]
pub struct TrackFilter {
    sizes: Deque<SizeSample, HISTORY>,
    prev_raw: Option<PixelBox>,
    depths: Deque<(f64, f64), HISTORY>,
    jump_since: Option<f64>,
    /// `(t, depth)` of the exponential depth smoothing (`depth_smoothing_s`), after eq. 4.
    smoothed: Option<(f64, f64)>,
}

/// True when sample time `s` lies within `window` before `t` (with a little slack for rounding, so
/// "the previous 5 frames" at 30 fps means exactly five).
#[inline]
fn within(s: f64, t: f64, window: f64) -> bool {
    s >= t - window * (1.0 + 1e-6) - 1e-9
}

impl TrackFilter {
    /// Empty state.
    pub const fn new() -> Self {
        Self { sizes: Deque::new(), prev_raw: None, depths: Deque::new(), jump_since: None, smoothed: None }
    }

    /// Forgets all history (the next observation starts a fresh track).
    pub fn reset(&mut self) {
        self.sizes.clear();
        self.prev_raw = None;
        self.depths.clear();
        self.jump_since = None;
        self.smoothed = None;
    }

    /// The box-fluctuation detector (eq. 3) and its EWMA correction for the observation at `t`.
    pub fn correct_box(&mut self, cfg: &PostprocessConfig, t: Seconds, raw: PixelBox) -> BoxCorrection {
        let t = t.0;
        let keep = cfg.box_window_s.0.max(cfg.box_ewma_s.0);
        // Time must increase; a gap longer than the window makes the history meaningless.
        if self.sizes.back().is_some_and(|last| t <= last.t || t - last.t > keep || t.is_nan()) {
            self.sizes.clear();
            self.prev_raw = None;
        }
        while self.sizes.front().is_some_and(|s| !within(s.t, t, keep)) || self.sizes.is_full() {
            self.sizes.pop_front();
        }
        let mut out = BoxCorrection { bbox: raw, width_corrected: false, height_corrected: false };
        if let (true, Some(prev)) = (cfg.box_fluctuation, self.prev_raw) {
            // Mean absolute frame-to-frame change over the window (eq. 3's Avg(D_w), Avg(D_h)).
            let (mut sum_w, mut sum_h, mut n) = (0.0, 0.0, 0usize);
            let mut last: Option<&SizeSample> = None;
            for s in self.sizes.iter().filter(|s| within(s.t, t, cfg.box_window_s.0)) {
                if let Some(l) = last {
                    sum_w += (s.w - l.w).abs();
                    sum_h += (s.h - l.h).abs();
                    n += 1;
                }
                last = Some(s);
            }
            if n >= cfg.box_min_history.max(1) {
                let fire_w = (raw.w - prev.w).abs() > sum_w / n as f64;
                let fire_h = (raw.h - prev.h).abs() > sum_h / n as f64;
                let recent = || self.sizes.iter().filter(|s| within(s.t, t, cfg.box_ewma_s.0));
                let n_recent = recent().count();
                let mut w = raw.w;
                let mut h = raw.h;
                if fire_w && n_recent > 0 {
                    w = ewma(recent().map(|s| s.wc).collect::<heapless::Vec<f64, HISTORY>>().into_iter()).unwrap_or(w);
                    out.width_corrected = true;
                }
                if fire_h && n_recent > 0 {
                    h = ewma(recent().map(|s| s.hc).collect::<heapless::Vec<f64, HISTORY>>().into_iter()).unwrap_or(h);
                    out.height_corrected = true;
                }
                let (x, y) = match cfg.box_anchor {
                    // Rebuild around the edges that moved least since the previous raw box.
                    BoxAnchor::LeastMoved => (
                        if (raw.x - prev.x).abs() <= (raw.right() - prev.right()).abs() {
                            raw.x
                        } else {
                            raw.right() - w
                        },
                        if (raw.y - prev.y).abs() <= (raw.bottom() - prev.bottom()).abs() {
                            raw.y
                        } else {
                            raw.bottom() - h
                        },
                    ),
                    BoxAnchor::TopLeft => (raw.x, raw.y),
                    BoxAnchor::Centre => (raw.center().u - 0.5 * w, raw.center().v - 0.5 * h),
                };
                out.bbox = PixelBox::new(x, y, w, h);
            }
        }
        let _ = self.sizes.push_back(SizeSample { t, w: raw.w, h: raw.h, wc: out.bbox.w, hc: out.bbox.h });
        self.prev_raw = Some(raw);
        out
    }

    /// The depth-jump detector (eq. 4) and its EWMA correction. Returns the corrected depth and
    /// whether the detector fired. `None` in, `None` out (the state is left untouched).
    pub fn correct_depth(
        &mut self,
        cfg: &PostprocessConfig,
        t: Seconds,
        depth: Option<Metres>,
    ) -> (Option<Metres>, bool) {
        let Some(d) = depth.filter(|d| d.0.is_finite() && d.0 > 0.0) else {
            return (None, false);
        };
        let t = t.0;
        let window = cfg.depth_window_s.0;
        if self.depths.back().is_some_and(|&(last_t, _)| t <= last_t || t - last_t > window || t.is_nan()) {
            self.depths.clear();
            self.jump_since = None;
            self.smoothed = None;
        }
        while self.depths.front().is_some_and(|s| !within(s.0, t, window)) || self.depths.is_full() {
            self.depths.pop_front();
        }
        let mut out = d.0;
        let mut fired = false;
        if let (true, Some(&(_, prev))) = (cfg.depth_jump, self.depths.back()) {
            if (d.0 - prev).abs() >= cfg.depth_jump_m.0 {
                let since = *self.jump_since.get_or_insert(t);
                if t - since > cfg.depth_max_hold_s.0 + 1e-9 {
                    // Persistent: accept the new depth and restart the history from it.
                    self.depths.clear();
                    self.jump_since = None;
                } else {
                    out = ewma(self.depths.iter().map(|s| s.1)).unwrap_or(d.0);
                    fired = true;
                }
            } else {
                self.jump_since = None;
            }
        }
        let _ = self.depths.push_back((t, out));
        // Not in the paper: an estimated depth map flickers from frame to frame, and over a 1 s
        // speed span that flicker becomes speed. An EWMA with time constant tau (real dt) keeps the
        // slope of a fish's real depth change and removes most of the flicker.
        let tau = cfg.depth_smoothing_s.0;
        if tau > 0.0 {
            let s = match self.smoothed {
                Some((ts, prev)) if t > ts => prev + (1.0 - (-(t - ts) / tau).exp()) * (out - prev),
                _ => out,
            };
            self.smoothed = Some((t, s));
            out = s;
        }
        (Some(Metres(out)), fired)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 1.0 / 30.0;

    #[test]
    fn steady_size_changes_pass_and_a_tail_flick_is_corrected() {
        let cfg = PostprocessConfig::paper();
        let mut f = TrackFilter::new();
        // A fish swimming right at constant size, with a width jitter of +-0.5 px.
        let mut fired = 0;
        for i in 0..40 {
            let jitter = if i % 2 == 0 { 0.5 } else { -0.5 };
            let b = PixelBox::new(100.0 + 2.0 * i as f64, 50.0, 60.0 + jitter, 20.0);
            let c = f.correct_box(&cfg, Seconds(i as f64 * DT), b);
            fired += c.width_corrected as usize + c.height_corrected as usize;
        }
        // Alternating jitter has |dw| = 1 = its own average: never "greater than" the average.
        assert_eq!(fired, 0);
        // The tail swings out to the right by 25 px for one frame: the left edge moved least.
        let t = 40.0 * DT;
        let flick = PixelBox::new(180.0, 50.0, 85.0, 20.0);
        let c = f.correct_box(&cfg, Seconds(t), flick);
        assert!(c.width_corrected && !c.height_corrected);
        assert!((c.bbox.w - 60.0).abs() < 0.6, "{c:?}");
        assert_eq!(c.bbox.x, 180.0);
        assert!((c.bbox.center().u - (180.0 + 30.0)).abs() < 0.6);
        // Switched off: passes through.
        let mut g = TrackFilter::new();
        let off = PostprocessConfig::off();
        for i in 0..40 {
            let b = PixelBox::new(0.0, 0.0, 60.0 + (i % 7) as f64 * 10.0, 20.0);
            assert_eq!(g.correct_box(&off, Seconds(i as f64 * DT), b).bbox, b);
        }
    }

    #[test]
    fn box_detector_needs_history_and_resets_after_a_gap() {
        let cfg = PostprocessConfig::paper();
        let mut f = TrackFilter::new();
        let b = |w: f64| PixelBox::new(0.0, 0.0, w, 10.0);
        assert!(!f.correct_box(&cfg, Seconds(0.0), b(10.0)).width_corrected);
        assert!(!f.correct_box(&cfg, Seconds(DT), b(30.0)).width_corrected); // no history yet
        for i in 2..10 {
            f.correct_box(&cfg, Seconds(i as f64 * DT), b(30.0 + (i % 2) as f64));
        }
        assert!(f.correct_box(&cfg, Seconds(10.0 * DT), b(45.0)).width_corrected);
        // Two seconds later the history is stale: no detection on the first frames.
        assert!(!f.correct_box(&cfg, Seconds(3.0), b(90.0)).width_corrected);
    }

    #[test]
    fn depth_jump_is_bridged_and_a_persistent_change_accepted() {
        let cfg = PostprocessConfig { depth_smoothing_s: Seconds(0.0), ..PostprocessConfig::default() };
        let mut f = TrackFilter::new();
        let mut t = 0.0;
        let mut step = |f: &mut TrackFilter, d: f64| {
            let r = f.correct_depth(&cfg, Seconds(t), Some(Metres(d)));
            t += DT;
            r
        };
        for i in 0..30 {
            let (d, fired) = step(&mut f, 3.0 + 0.01 * i as f64);
            assert!(!fired && d.is_some());
        }
        // Another fish passes in front for 5 frames: the centre reads 1.2 m.
        for _ in 0..5 {
            let (d, fired) = step(&mut f, 1.2);
            assert!(fired);
            let d = d.unwrap().0;
            assert!((3.0..3.3).contains(&d), "{d}");
        }
        let (d, fired) = step(&mut f, 3.35);
        assert!(!fired && (d.unwrap().0 - 3.35).abs() < 1e-12);
        // A jump that lasts more than depth_max_hold_s (1 s) is accepted.
        let mut accepted_at = None;
        for i in 0..40 {
            let (d, fired) = step(&mut f, 5.0);
            if !fired {
                assert_eq!(d, Some(Metres(5.0)));
                accepted_at.get_or_insert(i);
            }
        }
        assert_eq!(accepted_at, Some(31));
        // Below delta never fires; None passes through untouched; off passes everything.
        assert!(!step(&mut f, 5.55).1);
        assert_eq!(step(&mut f, f64::NAN), (None, false));
        let mut g = TrackFilter::new();
        let off = PostprocessConfig::off();
        assert_eq!(g.correct_depth(&off, Seconds(0.0), Some(Metres(3.0))).0, Some(Metres(3.0)));
        assert_eq!(g.correct_depth(&off, Seconds(DT), Some(Metres(1.0))), (Some(Metres(1.0)), false));
    }

    #[test]
    fn depth_smoothing_removes_flicker_and_keeps_the_slope() {
        let cfg =
            PostprocessConfig { depth_smoothing_s: Seconds(2.0), depth_jump: false, ..PostprocessConfig::default() };
        let mut f = TrackFilter::new();
        // A fish moving away at 0.3 m/s with +-0.2 m frame-to-frame flicker of the estimated depth.
        let mut out = Vec::new();
        for i in 0..300 {
            let t = i as f64 * DT;
            let flicker = if i % 2 == 0 { 0.2 } else { -0.2 };
            out.push(f.correct_depth(&cfg, Seconds(t), Some(Metres(2.0 + 0.3 * t + flicker))).0.unwrap().0);
        }
        // After the transient (several tau), the smoothed depth climbs at the true 0.3 m/s...
        let slope = (out[299] - out[239]) / (60.0 * DT);
        assert!((slope - 0.3).abs() < 0.01, "slope {slope}");
        // ... and the flicker is almost gone (raw: 0.4 m between consecutive frames).
        let step = out[251..300].windows(2).map(|w| (w[1] - w[0] - 0.3 * DT).abs()).fold(0.0, f64::max);
        assert!(step < 0.01, "frame-to-frame step {step}");
        // A reset starts a fresh track: its first depth is not blended with the old track's.
        f.reset();
        assert_eq!(f.correct_depth(&cfg, Seconds(20.0), Some(Metres(5.0))).0, Some(Metres(5.0)));
        // Off (0 s): the raw value passes through.
        let mut g = TrackFilter::new();
        let off =
            PostprocessConfig { depth_jump: false, depth_smoothing_s: Seconds(0.0), ..PostprocessConfig::default() };
        assert_eq!(g.correct_depth(&off, Seconds(0.0), Some(Metres(2.0))).0, Some(Metres(2.0)));
        assert_eq!(g.correct_depth(&off, Seconds(DT), Some(Metres(2.4))).0, Some(Metres(2.4)));
    }
}
