//! The published update: the values one output update carries, made once per update by the
//! publisher and read by every output (register map, serial line, history, MQTT, metrics, console),
//! so none of them decodes another's encoding.

use crate::status::FaultCode;
use fme_core::pipeline::ScaleSource;
use std::ops::{BitOr, BitOrAssign};

/// The status bits of register 10, typed. Unknown bits of a raw word are kept (a newer version's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct StatusBits(u16);

impl StatusBits {
    /// Bit 0: the daemon is running (cleared in the final "stopped" write).
    pub const RUNNING: Self = Self(1 << 0);
    /// Bit 1: the camera delivers frames.
    pub const CAMERA_OK: Self = Self(1 << 1);
    /// Bit 2: the detector works.
    pub const DETECTOR_OK: Self = Self(1 << 2);
    /// Bit 3: metric depth is calibrated.
    pub const DEPTH_CALIBRATED: Self = Self(1 << 3);
    /// Bit 4: the activity value is stale.
    pub const STALE: Self = Self(1 << 4);
    /// Bit 5: the PLC link is up (server: a request within the last 10 s; client: last write succeeded).
    pub const PLC_LINK_OK: Self = Self(1 << 5);
    /// Bit 6: too few fish tracked for a reliable mean.
    pub const TOO_FEW_FISH: Self = Self(1 << 6);
    /// Bit 7: disk fault: recording paused or the history held in memory after a write error (disk
    /// full, read-only), or a write to the state directory stalled for `service.disk_stall_s`
    /// (docs/recording.md). The activity values are unaffected.
    pub const RECORD_FAULT: Self = Self(1 << 7);
    /// Bit 8: the metric scale in use comes from the fish, not the reference objects (`depth.scale`).
    pub const SCALE_FROM_FISH: Self = Self(1 << 8);
    /// Bit 9: telemetry fault: MQTT is on and the broker refused the login or the TLS handshake
    /// failed (retried with backoff; docs/mqtt.md). The Modbus outputs are unaffected.
    pub const TELEMETRY_FAULT: Self = Self(1 << 9);
    /// Bit 10: the detections look unlike fish: their scores, sizes, nesting, tracks and count
    /// have left the range measured on the training data for `familiarity.raise_after_s`
    /// (`[familiarity]`, docs/pipeline.md). The value is not to be trusted; the feeding rule does
    /// not act on it (feeding recommended is off).
    pub const UNLIKE_FISH: Self = Self(1 << 10);

    /// Every bit by name, in bit order: the one spelling the MQTT `activity` JSON, the metrics
    /// (`fme_status_bit{name}`) and the console use.
    pub const NAMES: [(&'static str, Self); 11] = [
        ("running", Self::RUNNING),
        ("camera_ok", Self::CAMERA_OK),
        ("detector_ok", Self::DETECTOR_OK),
        ("depth_calibrated", Self::DEPTH_CALIBRATED),
        ("stale", Self::STALE),
        ("plc_link_ok", Self::PLC_LINK_OK),
        ("too_few_fish", Self::TOO_FEW_FISH),
        ("record_fault", Self::RECORD_FAULT),
        ("scale_from_fish", Self::SCALE_FROM_FISH),
        ("telemetry_fault", Self::TELEMETRY_FAULT),
        ("unlike_fish", Self::UNLIKE_FISH),
    ];

    /// No bit set.
    pub const fn empty() -> Self {
        Self(0)
    }

    /// The bits of a raw register 10 word.
    pub const fn from_word(word: u16) -> Self {
        Self(word)
    }

    /// The raw register 10 word.
    pub const fn bits(self) -> u16 {
        self.0
    }

    /// Every bit of `other` is set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// Sets (`on`) or clears the bits of `other`.
    pub fn set(&mut self, other: Self, on: bool) {
        if on { self.0 |= other.0 } else { self.0 &= !other.0 }
    }

    /// Each named bit with whether it is set, in bit order.
    pub fn named(self) -> impl Iterator<Item = (&'static str, bool)> {
        Self::NAMES.into_iter().map(move |(n, b)| (n, self.contains(b)))
    }

    /// The names of the bits set, space separated (`-` when none is).
    pub fn words(self) -> String {
        let v: Vec<&str> = self.named().filter(|&(_, on)| on).map(|(n, _)| n).collect();
        if v.is_empty() { "-".into() } else { v.join(" ") }
    }
}

impl BitOr for StatusBits {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl BitOrAssign for StatusBits {
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

/// One published update (a pure value: encoding it is the outputs' job).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Update {
    /// Wall-clock time of the update, ms since the Unix epoch (UTC).
    pub unix_ms: i64,
    /// Activity mean (paper eq. 5), m/s (NaN when unavailable or stale).
    pub mean_mps: f64,
    /// Activity mean, body lengths/s (NaN when unavailable).
    pub mean_bls: f64,
    /// Smoothed activity, m/s (NaN when unavailable).
    pub smoothed_mps: f64,
    /// 95% interval half-width, m/s (NaN when unavailable).
    pub ci95_half_mps: f64,
    /// Fish in the mean.
    pub fish: u32,
    /// Status bits.
    pub status: StatusBits,
    /// Fault code: the most severe current problem.
    pub fault: FaultCode,
    /// Heartbeat counter (increments every update, wraps).
    pub heartbeat: u16,
    /// Uptime, s.
    pub uptime_s: u32,
    /// Camera frame rate, frames/s.
    pub camera_fps: f64,
    /// Dropped frames (total).
    pub dropped: u64,
    /// Feeding recommended.
    pub feeding: bool,
    /// Detector runs/s.
    pub detector_hz: f64,
    /// Depth runs/s.
    pub depth_hz: f64,
    /// Age of the activity value, s (infinite when there is none).
    pub value_age_s: f64,
    /// Last feeding acknowledge from the PLC (HR 100).
    pub feeding_ack: u16,
    /// What set the metric scale in use (`depth.scale`).
    pub scale: ScaleSource,
}

impl Update {
    /// The detections look unlike fish (status bit 10).
    pub const fn unlike_fish(&self) -> bool {
        self.status.contains(StatusBits::UNLIKE_FISH)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_name_the_bits_in_bit_order_and_keep_unknown_bits() {
        assert_eq!(StatusBits::empty().words(), "-");
        assert_eq!((StatusBits::TOO_FEW_FISH | StatusBits::RUNNING).words(), "running too_few_fish");
        let mut b = StatusBits::from_word(0x8001);
        assert!(b.contains(StatusBits::RUNNING));
        b.set(StatusBits::RUNNING, false);
        assert_eq!(b.bits(), 0x8000);
        for (i, (_, bit)) in StatusBits::NAMES.iter().enumerate() {
            assert_eq!(bit.bits(), 1 << i, "bit order");
        }
    }
}
