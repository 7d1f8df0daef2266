//! `[feeding]`: the feeding-recommended rule's thresholds and times, and their check.

use crate::config::KeyError;
use serde::{Deserialize, Serialize};

/// `[feeding]`: hysteresis on the smoothed activity with minimum on/off times.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct FeedingConfig {
    /// Recommend feeding when the smoothed activity rises to this or above, m/s.
    pub on_above_mps: f64,
    /// Stop recommending when the smoothed activity falls to this or below, m/s.
    pub off_below_mps: f64,
    /// Shortest time the recommendation stays on, s.
    pub min_on_s: f64,
    /// Shortest time the recommendation stays off, s.
    pub min_off_s: f64,
}

impl Default for FeedingConfig {
    fn default() -> Self {
        Self { on_above_mps: 0.25, off_below_mps: 0.15, min_on_s: 300.0, min_off_s: 600.0 }
    }
}

impl FeedingConfig {
    /// The hysteresis must not be inverted (the ranges check each threshold alone).
    pub fn validate(&self) -> Result<(), KeyError> {
        if self.off_below_mps > self.on_above_mps {
            return Err(KeyError::new("feeding.off_below_mps", "must be <= feeding.on_above_mps (hysteresis)"));
        }
        Ok(())
    }
}
