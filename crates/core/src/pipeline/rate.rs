//! Achieved run rate of a stage over the last few seconds of frame time (fixed size).

/// Run times of the last 16 runs, frame time.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct RateMeter {
    times: [f64; 16],
    n: usize,
    next: usize,
}

impl RateMeter {
    /// Records a run at frame time `t`, s.
    pub(super) fn record(&mut self, t: f64) {
        self.times[self.next] = t;
        self.next = (self.next + 1) % self.times.len();
        self.n = (self.n + 1).min(self.times.len());
    }

    /// Runs per second over the recorded runs (0 with fewer than two).
    pub(super) fn hz(&self) -> f64 {
        if self.n < 2 {
            return 0.0;
        }
        let newest = self.times[(self.next + self.times.len() - 1) % self.times.len()];
        let oldest = self.times[(self.next + self.times.len() - self.n) % self.times.len()];
        if newest > oldest { (self.n - 1) as f64 / (newest - oldest) } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_of_runs_every_tenth_of_a_second() {
        let mut m = RateMeter::default();
        assert_eq!(m.hz(), 0.0);
        for i in 0..40 {
            m.record(f64::from(i) * 0.1);
        }
        assert!((m.hz() - 10.0).abs() < 1e-9, "{}", m.hz());
    }
}
