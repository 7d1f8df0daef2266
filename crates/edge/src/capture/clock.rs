//! Frame time for network cameras: the stream's own clock (RTP timestamps, or a part's timestamp
//! header) mapped to seconds from the first frame, so a fish's speed is distance over camera time,
//! not over arrival time (network jitter). A reconnect starts a new stream clock: its first frame
//! continues after the last one by the arrival-time gap, so the downtime stays a gap in frame time.

use std::time::Instant;

/// Maps a stream's seconds (any origin, restarting on reconnect) to monotonic frame time.
#[derive(Debug, Default, Clone)]
pub struct StreamClock {
    /// Frame time of the current stream's first frame, and that frame's stream time.
    origin: Option<(f64, f64)>,
    /// The last frame time handed out and when that frame arrived.
    last: Option<(f64, Instant)>,
}

impl StreamClock {
    /// A new stream (a reconnect): its clock has an origin of its own.
    pub fn restart(&mut self) {
        self.origin = None;
    }

    /// The frame time of a frame at `stream_s` on the stream's clock that arrived at `arrived`;
    /// `None` for a frame not after the previous one (a reordered or repeated timestamp: dropped).
    pub fn time(&mut self, stream_s: f64, arrived: Instant) -> Option<f64> {
        let (t0, s0) = *self.origin.get_or_insert_with(|| {
            let t0 = match self.last {
                Some((t, at)) => t + arrived.saturating_duration_since(at).as_secs_f64().max(1e-3),
                None => 0.0,
            };
            (t0, stream_s)
        });
        let t = t0 + (stream_s - s0);
        if !t.is_finite() || self.last.is_some_and(|(last, _)| t <= last) {
            return None;
        }
        self.last = Some((t, arrived));
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn stream_time_not_arrival_time_and_a_gap_stays_a_gap() {
        let mut c = StreamClock::default();
        let t0 = Instant::now();
        let near = |got: Option<f64>, want: f64| got.is_some_and(|t| (t - want).abs() < 1e-9);
        // Frames at 30 fps on the stream clock arriving with jitter: stream time wins.
        assert_eq!(c.time(100.0, t0), Some(0.0));
        assert!(near(c.time(100.0 + 1.0 / 30.0, t0 + Duration::from_millis(80)), 1.0 / 30.0));
        // A lost second of frames is a one-second gap.
        assert!(near(c.time(101.0 + 1.0 / 30.0, t0 + Duration::from_millis(1100)), 1.0 + 1.0 / 30.0));
        // A repeated or reordered timestamp is dropped.
        assert_eq!(c.time(101.0, t0 + Duration::from_millis(1110)), None);
        // Reconnect 10 s later with a stream clock from zero: time goes on after the downtime.
        c.restart();
        let t = c.time(0.0, t0 + Duration::from_millis(11_100)).expect("after reconnect");
        assert!((t - (1.0 + 1.0 / 30.0 + 10.0)).abs() < 1e-9, "{t}");
        assert!(near(c.time(0.5, t0 + Duration::from_millis(11_600)), t + 0.5));
    }
}
