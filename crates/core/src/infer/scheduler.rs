//! Reduced-rate scheduling on real frame timestamps: which frames get detection and depth. The
//! tracker predicts in between (Frigate-style decoupling of detection rate from camera rate).
//! Time always comes from the frames, never from an assumed frame period.

use crate::units::Seconds;

/// Slack for timestamp jitter: a frame up to this early still counts as on time. 2 ms absorbs
/// rounding of millisecond timestamps without skipping a slot.
const JITTER: f64 = 0.002;

/// Fires at most `rate` times per second of frame time, on the first frame at or after each slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateScheduler {
    period: f64,
    next: Option<f64>,
    last_t: Option<f64>,
}

impl RateScheduler {
    /// A scheduler for `rate_hz` runs per second; 0 runs on every frame.
    pub fn new(rate_hz: f64) -> Self {
        let period = if rate_hz > 0.0 && rate_hz.is_finite() { 1.0 / rate_hz } else { 0.0 };
        Self { period, next: None, last_t: None }
    }

    /// Whether the frame at `t` should be processed. The first frame always is. Slots advance by
    /// one period from the previous slot (no drift); after a gap longer than a period, or when time
    /// goes backwards (camera restart), the schedule restarts at `t`.
    pub fn due(&mut self, t: Seconds) -> bool {
        let t = t.0;
        if !t.is_finite() {
            return false;
        }
        let restarted = self.last_t.is_some_and(|last| t < last);
        self.last_t = Some(t);
        if self.period == 0.0 {
            return true;
        }
        match self.next {
            Some(next) if !restarted && t + JITTER < next => false,
            Some(next) if !restarted && t < next + self.period => {
                self.next = Some(next + self.period);
                true
            }
            _ => {
                self.next = Some(t + self.period);
                true
            }
        }
    }

    /// Forgets the schedule; the next frame runs.
    pub fn reset(&mut self) {
        self.next = None;
        self.last_t = None;
    }
}

/// What to run on one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FramePlan {
    /// Run the detector.
    pub detect: bool,
    /// Run the depth network.
    pub depth: bool,
}

/// Detector and depth schedules together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InferSchedule {
    detect: RateScheduler,
    depth: RateScheduler,
}

impl InferSchedule {
    /// Detector and depth rates in runs per second of frame time (`detector.rate_hz`,
    /// `depth.rate_hz`); 0 runs on every frame.
    pub fn new(detect_hz: f64, depth_hz: f64) -> Self {
        Self { detect: RateScheduler::new(detect_hz), depth: RateScheduler::new(depth_hz) }
    }

    /// The plan for the frame at `t`.
    pub fn plan(&mut self, t: Seconds) -> FramePlan {
        FramePlan { detect: self.detect.due(t), depth: self.depth.due(t) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_third_frame_at_30fps_10hz() {
        let mut s = RateScheduler::new(10.0);
        let fired: Vec<usize> = (0..30).filter(|i| s.due(Seconds(*i as f64 / 30.0))).collect();
        assert_eq!(fired, (0..30).step_by(3).collect::<Vec<_>>());
    }

    #[test]
    fn zero_rate_runs_every_frame() {
        let mut s = RateScheduler::new(0.0);
        assert!((0..5).all(|i| s.due(Seconds(i as f64 * 0.04))));
    }
}
