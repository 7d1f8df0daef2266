//! The feeding rule: hysteresis on the smoothed activity with minimum on and off times.
//!
//! Contract for PLC programmers (register 17, coil 0):
//! - Off -> on when the smoothed activity is `>= on_above_mps` and the recommendation has been off for
//!   at least `min_off_s` (counted from the daemon's first sample, so a restart never feeds at once).
//! - On -> off when the smoothed activity is `<= off_below_mps` and it has been on for at least
//!   `min_on_s`.
//! - No usable value (stale, NaN, pipeline down): off immediately, whatever `min_on_s` says: the
//!   box never asks for feed it cannot justify.

use crate::config::FeedingConfig;

/// Feeding-rule state machine (pure: time comes in with each update).
#[derive(Debug, Clone)]
pub struct FeedingRule {
    cfg: FeedingConfig,
    on: bool,
    since_s: Option<f64>,
}

impl FeedingRule {
    /// A rule starting in the off state.
    pub fn new(cfg: FeedingConfig) -> Self {
        Self { cfg, on: false, since_s: None }
    }

    /// Feeds one update at time `now_s` (any monotonic clock, s) with the smoothed activity (m/s), or
    /// `None` when there is no usable value. Returns the recommendation.
    pub fn update(&mut self, now_s: f64, smoothed_mps: Option<f64>) -> bool {
        let since = *self.since_s.get_or_insert(now_s);
        let held = now_s - since;
        match smoothed_mps.filter(|v| v.is_finite()) {
            None => {
                if self.on {
                    self.on = false;
                    self.since_s = Some(now_s);
                }
            }
            Some(v) => {
                if !self.on && v >= self.cfg.on_above_mps && held >= self.cfg.min_off_s {
                    self.on = true;
                    self.since_s = Some(now_s);
                } else if self.on && v <= self.cfg.off_below_mps && held >= self.cfg.min_on_s {
                    self.on = false;
                    self.since_s = Some(now_s);
                }
            }
        }
        self.on
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule() -> FeedingRule {
        FeedingRule::new(FeedingConfig { on_above_mps: 0.3, off_below_mps: 0.1, min_on_s: 10.0, min_off_s: 5.0 })
    }

    #[test]
    fn min_off_counts_from_start() {
        let mut r = rule();
        assert!(!r.update(0.0, Some(0.5)));
        assert!(!r.update(4.9, Some(0.5)));
        assert!(r.update(5.0, Some(0.5)));
    }

    #[test]
    fn hysteresis_band_holds_state() {
        let mut r = rule();
        r.update(0.0, Some(0.0));
        assert!(r.update(6.0, Some(0.3)));
        // inside the band: stays on even after min_on
        assert!(r.update(20.0, Some(0.2)));
        assert!(!r.update(21.0, Some(0.1)));
        // inside the band: stays off
        assert!(!r.update(40.0, Some(0.29)));
    }

    #[test]
    fn min_on_time_respected() {
        let mut r = rule();
        r.update(0.0, Some(0.0));
        assert!(r.update(5.0, Some(1.0)));
        assert!(r.update(14.9, Some(0.0)));
        assert!(!r.update(15.0, Some(0.0)));
        // and min_off before switching on again
        assert!(!r.update(19.9, Some(1.0)));
        assert!(r.update(20.0, Some(1.0)));
    }

    #[test]
    fn no_value_switches_off_at_once() {
        let mut r = rule();
        r.update(0.0, Some(0.0));
        assert!(r.update(5.0, Some(1.0)));
        assert!(!r.update(6.0, None));
        assert!(!r.update(7.0, Some(f64::NAN)));
        assert!(!r.update(10.0, Some(1.0)), "min_off applies after a forced off");
        assert!(r.update(11.0, Some(1.0)));
    }
}
