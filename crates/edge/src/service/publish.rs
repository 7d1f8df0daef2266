//! Turns the health snapshot into the published update (status bits, fault code, heartbeat, feeding
//! rule), made once per update and handed to every output: register block, history, MQTT, serial line.

use crate::config::{Config, ModbusMode, WordOrder};
use crate::output::bank::RegisterBank;
use crate::output::feeding::FeedingRule;
use crate::output::registers::{self, FaultCode};
use crate::output::{StatusBits, Update};
use crate::status::{Health, Shared};
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A server-role PLC link counts as up when it polled within this window.
pub const SERVER_LINK_WINDOW: Duration = Duration::from_secs(10);

/// Makes and publishes the updates. Owned by whoever publishes (pipeline thread or keepalive),
/// behind a mutex in [`super::Daemon`].
#[derive(Debug)]
pub struct Publisher {
    bank: Arc<RegisterBank>,
    heartbeat: u16,
    feeding: FeedingRule,
    order: WordOrder,
    mode: ModbusMode,
    stale_after: Duration,
    stall_after: Duration,
    disk_stall: Duration,
    /// Last publish (keepalive publishes when this gets old).
    pub last_publish: Option<Instant>,
    line: String,
    /// Latched once the "stopped" block is published: a frame still in flight must not overwrite it.
    stopped: bool,
    /// Every published update also goes to the history writer (never waits; `docs/history.md`).
    history: Option<crate::history::HistorySender>,
    /// Every published update also goes to the MQTT publisher (never waits; docs/mqtt.md).
    mqtt: Option<crate::output::mqtt::MqttSender>,
}

impl Publisher {
    /// A publisher for `cfg` (with its checked `timing`) writing to `bank`.
    pub fn new(cfg: &Config, timing: &super::timing::Timing, bank: Arc<RegisterBank>) -> Self {
        Self {
            bank,
            heartbeat: 0,
            feeding: FeedingRule::new(cfg.feeding.clone()),
            order: cfg.output.modbus.word_order,
            mode: cfg.output.modbus.mode,
            stale_after: timing.stale_after,
            stall_after: timing.stall_after,
            disk_stall: timing.disk_stall,
            last_publish: None,
            line: String::with_capacity(128),
            stopped: false,
            history: None,
            mqtt: None,
        }
    }

    /// Sends every later update to the history writer (`None`: stop sending, which lets the writer
    /// finish once it has written what it holds).
    pub fn set_history(&mut self, tx: Option<crate::history::HistorySender>) {
        self.history = tx;
    }

    /// Sends every later update to the MQTT publisher (`None`: stop sending; the publisher then
    /// says "offline" and disconnects once it has sent what it holds).
    pub fn set_mqtt(&mut self, tx: Option<crate::output::mqtt::MqttSender>) {
        self.mqtt = tx;
    }

    /// Makes the update at `now` (pure apart from advancing the heartbeat and feeding rule, and the
    /// wall clock it is stamped with).
    pub fn update(&mut self, h: &Health, plc_link_ok: bool, feeding_ack: u16, now: Instant, stopped: bool) -> Update {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        let age = h.last_sample_at.map(|t| now.saturating_duration_since(t));
        let stale = age.is_none_or(|a| a > self.stale_after);
        let sample = h.last_sample.filter(|_| !stale);
        // No frame finished yet counts from the start: the first frames are not a stall.
        let stalled =
            h.camera_ok && now.saturating_duration_since(h.last_processed_at.unwrap_or(h.started)) > self.stall_after;
        let uptime = now.saturating_duration_since(h.started);
        // Start-up is no fault: until the camera's first frame or first error, for at most
        // `service.stall_after_s`, the camera is "not yet", not "lost" (bit 1 stays clear).
        let starting = h.frames_captured == 0 && h.capture_errors == 0 && uptime <= self.stall_after;
        // A value whose detections look unlike fish is no usable value for the feeding rule.
        let unlike_fish = h.last_sample.is_some_and(|s| s.flags.unlike_fish);
        let smoothed = sample.filter(|s| !s.flags.unlike_fish).map(|s| s.smoothed.get());
        let feeding = if stopped { false } else { self.feeding.update(uptime.as_secs_f64(), smoothed) };
        let mut bits = StatusBits::empty();
        bits.set(StatusBits::RUNNING, !stopped);
        bits.set(StatusBits::CAMERA_OK, h.camera_ok);
        bits.set(StatusBits::DETECTOR_OK, h.stage.detector_ok);
        bits.set(StatusBits::DEPTH_CALIBRATED, h.fit_state.fitted || h.last_sample.is_some_and(|s| !s.flags.unfitted));
        bits.set(StatusBits::STALE, stale);
        bits.set(StatusBits::PLC_LINK_OK, plc_link_ok);
        bits.set(StatusBits::TOO_FEW_FISH, h.last_sample.is_none_or(|s| s.flags.too_few_fish));
        // Bit 7: the state directory's disk fails writes (recorder or history) or a write stalls.
        let disk = h.record.disk_fault || h.disk.history_fault || h.disk.stalled_for(now) >= self.disk_stall;
        bits.set(StatusBits::RECORD_FAULT, disk);
        bits.set(StatusBits::SCALE_FROM_FISH, h.fit_state.source == fme_core::pipeline::ScaleSource::Fish);
        bits.set(StatusBits::TELEMETRY_FAULT, h.mqtt.link == crate::status::MqttLink::AuthFailed);
        bits.set(StatusBits::UNLIKE_FISH, unlike_fish);
        let client = matches!(self.mode, ModbusMode::TcpClient | ModbusMode::RtuClient);
        let fault = if stopped {
            FaultCode::Stopped
        } else if !h.camera_ok && !starting {
            FaultCode::Camera
        } else if stalled {
            FaultCode::PipelineStalled
        } else if h.frames_processed > 0 && !h.stage.detector_ok {
            FaultCode::Detector
        } else if h.frames_processed > 0 && !h.stage.depth_ok {
            FaultCode::Depth
        } else if unlike_fish {
            FaultCode::UnlikeFish
        } else if client && !plc_link_ok {
            FaultCode::PlcLink
        } else {
            FaultCode::None
        };
        let nan = f64::NAN;
        Update {
            unix_ms: crate::history::now_unix_ms(),
            mean_mps: sample.map_or(nan, |s| s.mean.get()),
            mean_bls: sample.map_or(nan, |s| s.mean_body_lengths),
            smoothed_mps: sample.map_or(nan, |s| s.smoothed.get()),
            ci95_half_mps: sample.map_or(nan, |s| s.ci95_half.get()),
            fish: sample.map_or(0, |s| s.fish),
            status: bits,
            fault,
            heartbeat: self.heartbeat,
            uptime_s: uptime.as_secs().min(u64::from(u32::MAX)) as u32,
            camera_fps: h.camera_fps,
            dropped: h.frames_dropped,
            feeding,
            detector_hz: h.stage.detector_hz,
            depth_hz: h.stage.depth_hz,
            value_age_s: age.map_or(f64::INFINITY, |a| a.as_secs_f64()),
            feeding_ack,
            scale: h.fit_state.source,
        }
    }

    /// Computes and publishes one update; returns the serial line to send (borrowed buffer). After a
    /// `stopped` publish, later calls change nothing.
    pub fn publish(&mut self, shared: &Shared, now: Instant, stopped: bool) -> &str {
        if self.stopped {
            return &self.line;
        }
        self.stopped = stopped;
        let bank = self.bank.clone();
        let link = match self.mode {
            ModbusMode::Off => false,
            ModbusMode::TcpServer | ModbusMode::RtuServer => bank.served_within(SERVER_LINK_WINDOW),
            ModbusMode::TcpClient | ModbusMode::RtuClient => bank.client_link_ok(),
        };
        let ack = bank.writable()[usize::from(registers::HR_FEEDING_ACK - registers::HR_WRITABLE_START)];
        let u = shared.with_health(|h| {
            let u = self.update(h, link, ack, now, stopped);
            h.updates += 1;
            u
        });
        bank.publish_update(&u, self.order);
        if let Some(h) = &self.history {
            h.send(crate::history::HistoryRow::from(&u));
        }
        if let Some(m) = &mut self.mqtt {
            m.send(u);
        }
        self.last_publish = Some(now);
        crate::output::serial_line::format_line(&u, &mut self.line);
        &self.line
    }
}

/// Which publish [`publish_and_send`] makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Publish {
    /// An update (a frame's, or the first one at start).
    Update,
    /// The keepalive's: only when no update went out for `0` (the registers keep moving while the
    /// pipeline makes no samples).
    IfQuietFor(Duration),
    /// The final "stopped" update; then the history and MQTT are let go (it is their last).
    Stopped,
}

/// Locks the publisher, publishes (as `what` says) and sends the serial line to `serial` (never
/// waiting on a slow logger). Returns whether it published.
pub fn publish_and_send(
    publisher: &Mutex<Publisher>,
    shared: &Shared,
    serial: Option<&SyncSender<String>>,
    what: Publish,
) -> bool {
    let mut p = publisher.lock().unwrap_or_else(|p| p.into_inner());
    if let Publish::IfQuietFor(quiet) = what
        && p.last_publish.is_some_and(|t| t.elapsed() < quiet)
    {
        return false;
    }
    let stopped = what == Publish::Stopped;
    let line = p.publish(shared, Instant::now(), stopped);
    if let Some(tx) = serial {
        let _ = tx.try_send(line.to_string());
    }
    if stopped {
        // The "stopped" row is the history's last: the writer drains, fsyncs and ends.
        p.set_history(None);
        // MQTT: delivers what it holds, publishes status "offline" (retained), disconnects.
        p.set_mqtt(None);
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use fme_core::pipeline::{ActivitySample, QualityFlags, ScaleSource};
    use fme_core::units::{MetresPerSecond, Seconds};

    fn health(unlike_fish: bool, now: Instant) -> Health {
        let mut h = Shared::new(String::new(), 4).health();
        h.camera_ok = true;
        h.stage.detector_ok = true;
        h.stage.depth_ok = true;
        h.frames_processed = 1;
        h.last_processed_at = Some(now);
        h.last_sample_at = Some(now);
        h.last_sample = Some(ActivitySample {
            timestamp: Seconds(1.0),
            mean: MetresPerSecond(0.5),
            mean_body_lengths: 1.4,
            smoothed: MetresPerSecond(0.5),
            ci95_half: MetresPerSecond(0.05),
            fish: 20,
            latency: Seconds(0.5),
            flags: QualityFlags { unlike_fish, ..QualityFlags::default() },
            scale: ScaleSource::References,
        });
        h
    }

    fn publisher(cfg: &Config) -> Publisher {
        let timing = super::super::timing::Timing::from_config(cfg).expect("default timing");
        Publisher::new(cfg, &timing, Arc::new(RegisterBank::new()))
    }

    #[test]
    fn unlike_fish_sets_bit_10_and_fault_7_and_the_feeding_rule_does_not_act() {
        let cfg = Config::default();
        let mut p = publisher(&cfg);
        let t0 = Instant::now();
        let mut h = health(false, t0);
        h.started = t0;
        // Well above feeding.on_above_mps for longer than min_off_s: feeding goes on.
        let mut feeding_on_at = None;
        for s in 0..=cfg.feeding.min_off_s as u64 + 1 {
            let now = t0 + Duration::from_secs(s);
            (h.last_sample_at, h.last_processed_at) = (Some(now), Some(now));
            let inp = p.update(&h, true, 0, now, false);
            assert!(!inp.status.contains(StatusBits::UNLIKE_FISH));
            assert_eq!(inp.fault, FaultCode::None);
            if inp.feeding && feeding_on_at.is_none() {
                feeding_on_at = Some(s);
            }
        }
        assert!(feeding_on_at.is_some(), "feeding on with a familiar value");
        // The same value, flagged: bit 10, fault 7, feeding off at once, and not back on while flagged.
        let mut flagged = health(true, t0);
        flagged.started = t0;
        for s in 0..2 * cfg.feeding.min_off_s as u64 {
            let now = t0 + Duration::from_secs(cfg.feeding.min_off_s as u64 + 2 + s);
            (flagged.last_sample_at, flagged.last_processed_at) = (Some(now), Some(now));
            let inp = p.update(&flagged, true, 0, now, false);
            assert!(inp.status.contains(StatusBits::UNLIKE_FISH), "bit 10 at {s} s");
            assert_eq!(inp.fault, FaultCode::UnlikeFish);
            assert!(!inp.feeding, "the feeding rule does not act on a flagged value ({s} s)");
            assert!((inp.mean_mps - 0.5).abs() < 1e-9, "the value itself is still published");
        }
        // A camera fault is more severe.
        flagged.camera_ok = false;
        let inp = p.update(&flagged, true, 0, t0 + Duration::from_secs(10_000), false);
        assert_eq!(inp.fault, FaultCode::Camera);
        assert!(inp.status.contains(StatusBits::UNLIKE_FISH));
    }

    #[test]
    fn start_up_is_no_fault_until_the_camera_fails_or_stays_silent() {
        let cfg = Config::default();
        let mut p = publisher(&cfg);
        let t0 = Instant::now();
        let mut h = Shared::new(String::new(), 4).health();
        h.started = t0;
        // The first block, before the capture thread has a frame: no fault, camera bit clear.
        let inp = p.update(&h, true, 0, t0, false);
        assert_eq!(inp.fault, FaultCode::None);
        assert!(!inp.status.contains(StatusBits::CAMERA_OK));
        // First frame captured, none processed yet: not a stall.
        h.camera_ok = true;
        h.frames_captured = 1;
        assert_eq!(p.update(&h, true, 0, t0 + Duration::from_millis(50), false).fault, FaultCode::None);
        // A camera silent past service.stall_after_s, or one that failed, is a camera fault.
        let mut silent = Shared::new(String::new(), 4).health();
        silent.started = t0;
        let stall = super::super::timing::Timing::from_config(&cfg).expect("default timing").stall_after;
        let late = t0 + stall + Duration::from_secs(1);
        assert_eq!(p.update(&silent, true, 0, late, false).fault, FaultCode::Camera);
        silent.capture_errors = 1;
        assert_eq!(p.update(&silent, true, 0, t0, false).fault, FaultCode::Camera);
    }
}
