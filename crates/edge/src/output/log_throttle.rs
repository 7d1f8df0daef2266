//! A warning that can repeat as fast as the outside world pushes it (a PLC reconnecting in a tight
//! loop evicts a connection per attempt) is logged at most once per period, with the number held
//! back since the last message. The journal on the box's flash is the technician's record; it must
//! not be flooded by one misbehaving client. The exact counts stay in the register bank.

use std::time::Duration;
use tokio::time::Instant;

/// At most one message per `period`; counts the events it held back.
#[derive(Debug, Clone)]
pub struct LogThrottle {
    period: Duration,
    last: Option<Instant>,
    held_back: u64,
}

impl LogThrottle {
    /// A throttle that lets the first event through and then at most one per `period`.
    pub fn new(period: Duration) -> Self {
        Self { period, last: None, held_back: 0 }
    }

    /// `Some(n)` when the event at `now` should be logged, `n` being the events held back since the
    /// last one logged; `None` when it is held back (and counted).
    pub fn allow(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(last) if now.saturating_duration_since(last) < self.period => {
                self.held_back += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.held_back))
            }
        }
    }
}

/// Makes the process-wide panic message (the default hook: message and backtrace, kilobytes each)
/// appear at most once per `period`, with the number not printed since. A peer that could trigger
/// a panic in a connection task on every frame must not flood the journal; the tasks themselves
/// count every panic.
pub fn throttle_panic_messages(period: Duration) {
    let default = std::panic::take_hook();
    let state = std::sync::Mutex::new((None::<std::time::Instant>, 0u64));
    std::panic::set_hook(Box::new(move |info| {
        let now = std::time::Instant::now();
        let held_back = {
            let mut s = state.lock().unwrap_or_else(|p| p.into_inner());
            match s.0 {
                Some(last) if now.saturating_duration_since(last) < period => {
                    s.1 += 1;
                    None
                }
                _ => {
                    s.0 = Some(now);
                    Some(std::mem::take(&mut s.1))
                }
            }
        };
        if let Some(n) = held_back {
            default(info);
            if n > 0 {
                eprintln!("({n} more panics since the last message were not printed)");
            }
        }
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_event_passes_then_one_per_period_with_the_count_held_back() {
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        let mut t = LogThrottle::new(Duration::from_secs(10));
        assert_eq!(t.allow(t0), Some(0));
        assert_eq!(t.allow(t0 + s), None);
        assert_eq!(t.allow(t0 + 5 * s), None);
        assert_eq!(t.allow(t0 + 9 * s), None);
        assert_eq!(t.allow(t0 + 10 * s), Some(3), "three held back since the first");
        assert_eq!(t.allow(t0 + 11 * s), None);
        assert_eq!(t.allow(t0 + 60 * s), Some(1));
        assert_eq!(t.allow(t0 + 100 * s), Some(0), "nothing held back after a quiet period");
    }

    #[test]
    fn a_clock_that_steps_back_holds_back_rather_than_panics() {
        let t0 = Instant::now() + Duration::from_secs(100);
        let mut t = LogThrottle::new(Duration::from_secs(10));
        assert_eq!(t.allow(t0), Some(0));
        assert_eq!(t.allow(t0 - Duration::from_secs(50)), None);
    }
}
