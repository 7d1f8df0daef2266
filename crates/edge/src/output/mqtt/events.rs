//! The `event` topic's events, found between successive published updates (pure).

use crate::output::Update;
use crate::status::FaultCode;
use fme_core::pipeline::ScaleSource;

/// An event of the `event` topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// Feeding recommended became on.
    FeedingOn,
    /// Feeding recommended became off.
    FeedingOff,
    /// A fault ([`FaultCode::is_fault`]) appeared.
    FaultRaised(FaultCode),
    /// A fault went away.
    FaultCleared(FaultCode),
    /// "Detections look unlike fish" (status bit 10) was raised (`true`) or cleared (`false`).
    UnlikeFish(bool),
    /// The source of the metric scale changed (`depth.scale`: fish <-> references).
    ScaleSource {
        /// Before.
        from: ScaleSource,
        /// Now.
        to: ScaleSource,
    },
}

impl EventKind {
    /// The `event` field of the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::FeedingOn => "feeding_on",
            Self::FeedingOff => "feeding_off",
            Self::FaultRaised(_) => "fault_raised",
            Self::FaultCleared(_) => "fault_cleared",
            Self::UnlikeFish(true) => "unlike_fish_raised",
            Self::UnlikeFish(false) => "unlike_fish_cleared",
            Self::ScaleSource { .. } => "scale_source",
        }
    }
}

/// Finds the events between successive updates (pure). The first update only sets the baseline,
/// except that a fault present then is raised; the final "stopped" update makes no events (the
/// `status` topic says "offline").
#[derive(Debug, Clone, Default)]
pub struct EventTracker {
    last: Option<(bool, FaultCode, ScaleSource)>,
    unlike_fish: bool,
}

impl EventTracker {
    /// The events of update `u` against the previous update.
    pub fn update(&mut self, u: &Update) -> heapless::Vec<EventKind, 6> {
        let mut out = heapless::Vec::new();
        if u.fault == FaultCode::Stopped {
            return out;
        }
        // Only faults raise and clear ([`FaultCode::is_fault`], as the history counts them).
        let code = if u.fault.is_fault() { u.fault } else { FaultCode::None };
        let scale = u.scale;
        let (feeding, fault) = match self.last {
            Some((f, c, s)) => {
                if scale != s && scale != ScaleSource::None && s != ScaleSource::None {
                    let _ = out.push(EventKind::ScaleSource { from: s, to: scale });
                }
                (f, c)
            }
            None => (false, FaultCode::None),
        };
        if code != fault {
            if fault != FaultCode::None {
                let _ = out.push(EventKind::FaultCleared(fault));
            }
            if code != FaultCode::None {
                let _ = out.push(EventKind::FaultRaised(code));
            }
        }
        let unlike = u.unlike_fish();
        if unlike != self.unlike_fish {
            let _ = out.push(EventKind::UnlikeFish(unlike));
            self.unlike_fish = unlike;
        }
        if u.feeding != feeding {
            let _ = out.push(if u.feeding { EventKind::FeedingOn } else { EventKind::FeedingOff });
        }
        // A scale source of "none" (no fit yet) is not a change worth an event: keep the last real one.
        let kept = match (self.last, scale) {
            (Some((_, _, s)), ScaleSource::None) => s,
            _ => scale,
        };
        self.last = Some((u.feeding, code, kept));
        out
    }
}
