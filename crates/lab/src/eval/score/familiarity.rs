//! "Detections look unlike fish" (`[familiarity]`, status bit 10): the statistics' ranges over the
//! run and the share of output updates with the flag raised, on the daemon's update clock.

use super::{FrameTruth, Scorer};
use crate::eval::{EvalError, EvalReport};
use fme_core::familiarity::StatRanges;
use fme_core::pipeline::FrameOutcome;

/// Follows the familiarity monitor as the outputs would see it.
#[derive(Debug)]
pub struct FamiliarityScorer {
    ranges: StatRanges,
    /// `1 / output.rate_hz`, s.
    period_s: f64,
    next_update: f64,
    updates: u64,
    flagged: u64,
}

impl FamiliarityScorer {
    /// Output updates every `period_s` of frame time (`1 / output.rate_hz`).
    pub fn new(period_s: f64) -> Self {
        Self { ranges: StatRanges::default(), period_s, next_update: f64::NEG_INFINITY, updates: 0, flagged: 0 }
    }
}

impl Scorer for FamiliarityScorer {
    fn frame(&mut self, _truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        if o.plan.detect
            && let Some(w) = o.health.familiarity.stats
        {
            self.ranges.add(&w);
        }
        let Some(sample) = o.sample else { return Ok(()) };
        let t = sample.timestamp.0;
        if t >= self.next_update {
            self.updates += 1;
            self.flagged += u64::from(sample.flags.unlike_fish);
            let from = if self.next_update.is_finite() { self.next_update } else { t };
            self.next_update = from + self.period_s;
            if self.next_update <= t {
                self.next_update = t + self.period_s;
            }
        }
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.unlike_fish_share = self.flagged as f64 / self.updates.max(1) as f64;
        report.familiarity = self.ranges;
        Ok(())
    }
}
