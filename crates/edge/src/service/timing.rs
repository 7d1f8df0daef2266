//! The daemon's timers, built once from the configuration with checked conversions: a value no
//! timer can hold is an error naming its key (exit 2), never a panic. Validation
//! ([`crate::config::ranges`]) already keeps every key in a range these conversions accept; this is
//! the second line, for configurations built in code.

use crate::config::Config;
use fme_core::units::Seconds;
use std::time::{Duration, Instant};

/// The durations `fme run` builds from `[output]`, `[service]` and `[record]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timing {
    /// Between two activity updates (`1 / output.rate_hz`).
    pub output_period: Duration,
    /// `output.stale_after_s`.
    pub stale_after: Duration,
    /// `service.stall_after_s`.
    pub stall_after: Duration,
    /// `service.live_view_s`; `None` = off.
    pub live_view: Option<Duration>,
    /// `record.freeze_min_gap_s`.
    pub freeze_gap: Duration,
    /// `service.disk_stall_s`.
    pub disk_stall: Duration,
}

/// A key whose value gives no usable duration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("key `{key}`: {value} gives no usable duration (must be finite, > 0 where it divides, at most 100 years)")]
pub struct TimingError {
    /// Dotted key.
    pub key: &'static str,
    /// The configured value.
    pub value: f64,
}

fn secs(key: &'static str, value: f64) -> Result<Duration, TimingError> {
    let d = Seconds(value).to_duration().map_err(|_| TimingError { key, value })?;
    // Timers add 1.5 x the duration to `Instant::now()`.
    match Instant::now().checked_add(d.saturating_mul(2)) {
        Some(_) => Ok(d),
        None => Err(TimingError { key, value }),
    }
}

impl Timing {
    /// The timers of `cfg`.
    pub fn from_config(cfg: &Config) -> Result<Self, TimingError> {
        let rate = cfg.output.rate_hz;
        if !(rate.is_finite() && rate > 0.0) {
            return Err(TimingError { key: "output.rate_hz", value: rate });
        }
        let output_period =
            secs("output.rate_hz", 1.0 / rate).map_err(|_| TimingError { key: "output.rate_hz", value: rate })?;
        if output_period.is_zero() {
            return Err(TimingError { key: "output.rate_hz", value: rate });
        }
        let live = cfg.service.live_view_s;
        let live_view = if live == 0.0 {
            None
        } else {
            let d = secs("service.live_view_s", live)?;
            // `tokio::time::interval` panics on a zero period.
            if d.is_zero() {
                return Err(TimingError { key: "service.live_view_s", value: live });
            }
            Some(d)
        };
        Ok(Self {
            output_period,
            stale_after: secs("output.stale_after_s", cfg.output.stale_after_s)?,
            stall_after: secs("service.stall_after_s", cfg.service.stall_after_s)?,
            live_view,
            freeze_gap: secs("record.freeze_min_gap_s", cfg.record.freeze_min_gap_s)?,
            disk_stall: secs("service.disk_stall_s", cfg.service.disk_stall_s)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_extremes() {
        let t = Timing::from_config(&Config::default()).expect("defaults");
        assert_eq!(
            (t.output_period, t.stale_after, t.live_view),
            (Duration::from_secs(1), Duration::from_secs(5), None)
        );
        let mut c = Config::default();
        c.output.stale_after_s = 1e20;
        assert_eq!(Timing::from_config(&c).map_err(|e| e.key), Err("output.stale_after_s"));
        let mut c = Config::default();
        c.output.rate_hz = 1e-20;
        assert_eq!(Timing::from_config(&c).map_err(|e| e.key), Err("output.rate_hz"));
        let mut c = Config::default();
        c.service.live_view_s = f64::INFINITY;
        assert_eq!(Timing::from_config(&c).map_err(|e| e.key), Err("service.live_view_s"));
        let mut c = Config::default();
        c.service.live_view_s = 1e-300;
        assert_eq!(Timing::from_config(&c).map_err(|e| e.key), Err("service.live_view_s"));
        let mut c = Config::default();
        c.record.freeze_min_gap_s = f64::NAN;
        assert_eq!(Timing::from_config(&c).map_err(|e| e.key), Err("record.freeze_min_gap_s"));
    }
}
