//! The documented range of every duration, rate, size and count key: one table that `fme config
//! check` and every command that loads a configuration apply alike. A value outside its range stops
//! the command with exit 2 and names the key, so nothing downstream (durations, timers, buffers) is
//! ever built from 0, a negative, an infinite, a NaN or an absurdly large value.
//!
//! `config/fme.toml` states each range above its key (a test checks it, and that every key here
//! exists in the configuration); README.md's Configuration section describes the rule.

/// One key's range: `lo..=hi` in `unit`, plus 0 when `zero` says what 0 means (`"off"`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Dotted key, e.g. `output.stale_after_s`.
    pub key: &'static str,
    /// Smallest value accepted (besides 0 when `zero` is set).
    pub lo: f64,
    /// Largest value accepted.
    pub hi: f64,
    /// Unit, for messages (`s`, `ms`, `Hz`, `px`).
    pub unit: &'static str,
    /// What 0 means, when 0 is accepted outside `lo..=hi` (`"off"`, `"every frame"`).
    pub zero: Option<&'static str>,
}

const fn r(key: &'static str, lo: f64, hi: f64, unit: &'static str) -> Range {
    Range { key, lo, hi, unit, zero: None }
}

const fn z(key: &'static str, lo: f64, hi: f64, unit: &'static str, zero: &'static str) -> Range {
    Range { key, lo, hi, unit, zero: Some(zero) }
}

const HOUR_S: f64 = 3600.0;
const DAY_S: f64 = 86_400.0;
const WEEK_S: f64 = 7.0 * DAY_S;
const HOUR_MS: f64 = 3_600_000.0;

/// Every range, in `config/fme.toml` order. The tracker's score thresholds have none: any score
/// (the SORT preset's `-inf`: no threshold) is a threshold; NaN is refused by the tracker's check.
pub const RANGES: &[Range] = &[
    r("source.width", 1.0, 8192.0, "px"),
    r("source.height", 1.0, 8192.0, "px"),
    r("source.fps", 1.0, 1000.0, "frames/s"),
    r("source.buffers", 1.0, 32.0, "buffers"),
    r("source.timeout_ms", 1.0, 600_000.0, "ms"),
    r("source.queue_frames", 1.0, 256.0, "frames"),
    r("source.reconnect_min_ms", 1.0, HOUR_MS, "ms"),
    r("source.reconnect_max_ms", 1.0, HOUR_MS, "ms"),
    z("source.max_pixels", 1.0, 268_435_456.0, "px", "4 x the frame size"),
    z("detector.rate_hz", 0.01, 1000.0, "Hz", "every frame"),
    r("detector.confidence", 0.0, 1.0, ""),
    r("detector.nms_iou", 0.0, 1.0, ""),
    r("detector.threads", 1.0, 64.0, "threads"),
    r("detector.max_detections", 1.0, 256.0, "detections"),
    r("detector.max_candidates", 1.0, 1_000_000.0, "candidates"),
    z("depth.rate_hz", 0.01, 1000.0, "Hz", "every frame"),
    r("depth.threads", 1.0, 64.0, "threads"),
    r("depth.sample_radius", 0.0, 3.0, "map px"),
    r("tracker.iou_threshold", 0.0, 1.0, ""),
    r("tracker.low_iou_threshold", 0.0, 1.0, ""),
    r("tracker.unconfirmed_iou_threshold", 0.0, 1.0, ""),
    r("tracker.min_hits", 0.0, 1000.0, "detections"),
    r("tracker.max_age_s", 0.0, HOUR_S, "s"),
    r("tracker.max_age_frames", 0.0, 100_000.0, "frames"),
    r("tracker.depth_weight", 0.0, 1000.0, ""),
    r("tracker.buffer_rate", 0.0, 1000.0, "1/s"),
    r("tracker.buffer_max", 0.0, 10.0, ""),
    r("tracker.max_tracks", 1.0, 128.0, "tracks"),
    r("tracker.noise.meas", 1e-6, 1000.0, ""),
    r("tracker.noise.accel", 1e-6, 1000.0, ""),
    r("tracker.noise.init_vel", 1e-6, 1000.0, ""),
    r("postprocess.box_window_s", 0.01, HOUR_S, "s"),
    r("postprocess.box_ewma_s", 0.001, HOUR_S, "s"),
    r("postprocess.box_min_history", 0.0, 10_000.0, "changes"),
    r("postprocess.depth_jump_m", 0.001, 1000.0, "m"),
    r("postprocess.depth_window_s", 0.01, HOUR_S, "s"),
    r("postprocess.depth_max_hold_s", 0.01, HOUR_S, "s"),
    z("postprocess.depth_smoothing_s", 0.001, HOUR_S, "s", "off"),
    z("motion.body_length_m", 0.001, 10.0, "m", "estimated per fish"),
    r("motion.body_length_cv", 0.0, 0.5, ""),
    r("motion.min_fish", 0.0, 10_000.0, "fish"),
    r("motion.smoothing_s", 0.01, WEEK_S, "s"),
    z("motion.speed_span_s", 0.001, 60.0, "s", "frame to frame"),
    z("motion.min_age_s", 0.001, HOUR_S, "s", "at once"),
    r("motion.body_width_ratio", 0.0, 0.5, ""),
    r("motion.track_timeout_s", 0.01, HOUR_S, "s"),
    r("motion.max_speed_mps", 0.001, 1000.0, "m/s"),
    r("output.rate_hz", 0.001, 100.0, "Hz"),
    r("output.stale_after_s", 0.1, DAY_S, "s"),
    r("output.modbus.unit_id", 1.0, 247.0, ""),
    r("output.modbus.baud", 50.0, 4_000_000.0, "bit/s"),
    r("output.modbus.stop_bits", 1.0, 2.0, "bits"),
    r("output.modbus.timeout_ms", 1.0, 600_000.0, "ms"),
    r("output.modbus.reconnect_min_ms", 1.0, HOUR_MS, "ms"),
    r("output.modbus.reconnect_max_ms", 1.0, HOUR_MS, "ms"),
    r("output.modbus.max_connections", 1.0, 64.0, "connections"),
    r("output.modbus.max_connections_per_peer", 1.0, 64.0, "connections"),
    z("output.modbus.idle_timeout_ms", 1.0, 24.0 * HOUR_MS, "ms", "never"),
    z("output.modbus.priority_after_ms", 100.0, HOUR_MS, "ms", "no priority connections"),
    r("output.serial.baud", 50.0, 4_000_000.0, "bit/s"),
    r("output.mqtt.qos", 0.0, 1.0, ""),
    r("output.mqtt.keepalive_s", 5.0, HOUR_S, "s"),
    r("output.mqtt.connect_timeout_s", 1.0, 600.0, "s"),
    r("output.mqtt.queue_messages", 1.0, 100_000.0, "messages"),
    r("output.mqtt.reconnect_min_ms", 1.0, HOUR_MS, "ms"),
    r("output.mqtt.reconnect_max_ms", 1.0, HOUR_MS, "ms"),
    r("output.metrics.max_connections", 1.0, 1024.0, "connections"),
    r("output.metrics.max_connections_per_peer", 1.0, 64.0, "connections"),
    r("output.metrics.header_timeout_ms", 100.0, 60_000.0, "ms"),
    r("web.max_connections", 1.0, 1024.0, "connections"),
    r("web.max_connections_per_peer", 1.0, 64.0, "connections"),
    r("web.max_requests", 1.0, 1024.0, "requests"),
    r("web.header_timeout_ms", 100.0, 60_000.0, "ms"),
    r("web.request_timeout_ms", 100.0, 600_000.0, "ms"),
    r("console.baud", 50.0, 4_000_000.0, "bit/s"),
    r("console.log_lines", 1.0, 10_000.0, "lines"),
    r("feeding.on_above_mps", 0.0, 100.0, "m/s"),
    r("feeding.off_below_mps", 0.0, 100.0, "m/s"),
    r("feeding.min_on_s", 0.0, WEEK_S, "s"),
    r("feeding.min_off_s", 0.0, WEEK_S, "s"),
    r("service.stall_after_s", 0.1, HOUR_S, "s"),
    z("service.live_view_s", 0.05, HOUR_S, "s", "off"),
    r("service.stop_grace_ms", 0.0, 1500.0, "ms"),
    r("service.disk_stall_s", 0.5, 600.0, "s"),
    r("record.ring_s", 0.1, DAY_S, "s"),
    r("record.max_disk_mb", 1.0, 1_000_000.0, "MB"),
    r("record.reserve_mb", 0.0, 1_000_000.0, "MB"),
    z("record.snapshot_every_s", 0.1, WEEK_S, "s", "off"),
    r("record.keep_snapshots", 1.0, 100_000.0, "snapshots"),
    z("record.keep_recordings", 1.0, 100_000.0, "recordings", "keep all"),
    z("record.alarm_low_mps", 0.001, 100.0, "m/s", "off"),
    z("record.alarm_high_mps", 0.001, 100.0, "m/s", "off"),
    r("record.freeze_min_gap_s", 0.0, WEEK_S, "s"),
    r("record.queue_frames", 1.0, 1024.0, "frames"),
    r("history.keep_days", 1.0, 36_500.0, "days"),
    r("history.fsync_s", 0.0, HOUR_S, "s"),
];

impl Range {
    /// Whether `v` is accepted.
    pub fn accepts(&self, v: f64) -> bool {
        v.is_finite() && ((v >= self.lo && v <= self.hi) || (v == 0.0 && self.zero.is_some()))
    }

    /// What the key accepts, for messages and docs: `0.1..=86400 s`, `0.05..=3600 s (0 = off)`.
    pub fn describe(&self) -> String {
        let unit = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        match self.zero {
            Some(z) => format!("{}..={}{unit} (0 = {z})", self.lo, self.hi),
            None => format!("{}..={}{unit}", self.lo, self.hi),
        }
    }
}

/// The range of `key`, if it has one.
pub fn range_of(key: &str) -> Option<&'static Range> {
    RANGES.iter().find(|r| r.key == key)
}

/// Checks every ranged key of `doc` (the configuration as a TOML value); the first one out of
/// range is the error.
pub fn check(doc: &toml::Value) -> Result<(), super::KeyError> {
    for range in RANGES {
        let Some(v) = lookup(doc, range.key) else { continue };
        let Some(x) = v.as_float().or_else(|| v.as_integer().map(|i| i as f64)) else { continue };
        if !range.accepts(x) {
            // 1e20, not twenty-one digits.
            let got = if x != 0.0 && x.is_finite() && !(1e-4..1e9).contains(&x.abs()) {
                format!("{x:e}")
            } else {
                format!("{x}")
            };
            return Err(super::KeyError::new(range.key, format!("must be {}, got {got}", range.describe())));
        }
    }
    Ok(())
}

/// The value at dotted `key` in `doc`.
pub fn lookup<'a>(doc: &'a toml::Value, key: &str) -> Option<&'a toml::Value> {
    key.split('.').try_fold(doc, |v, seg| v.get(seg))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn every_ranged_key_exists_is_numeric_and_its_default_is_accepted() {
        let doc = toml::Value::try_from(Config::default()).expect("the defaults serialize");
        for range in RANGES {
            let v = lookup(&doc, range.key).unwrap_or_else(|| panic!("{} is not a key of the config", range.key));
            let x = v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
            let x = x.unwrap_or_else(|| panic!("{} is not a number", range.key));
            assert!(range.accepts(x), "{}: default {x} outside {}", range.key, range.describe());
            assert!(range.lo <= range.hi && range.lo.is_finite() && range.hi.is_finite(), "{}", range.key);
        }
        let mut keys: Vec<_> = RANGES.iter().map(|r| r.key).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), RANGES.len(), "a key is listed twice");
    }

    /// config/fme.toml states every range in the comments above its key.
    #[test]
    fn shipped_config_documents_every_range() {
        let text =
            std::fs::read_to_string(std::path::Path::new(fme_core::REPO_DIR).join("config/fme.toml")).expect("read");
        let lines: Vec<&str> = text.lines().collect();
        for range in RANGES {
            let (section, name) = range.key.rsplit_once('.').expect("dotted");
            let header = lines
                .iter()
                .position(|l| l.trim_start_matches("# ") == format!("[{section}]"))
                .unwrap_or_else(|| panic!("no [{section}] in config/fme.toml"));
            let at = (header + 1..lines.len())
                .find(|&i| lines[i].trim_start_matches("# ").starts_with(&format!("{name} = ")))
                .unwrap_or_else(|| panic!("{} not in config/fme.toml", range.key));
            let block = lines[header + 1..at].iter().rev().take_while(|l| !l.is_empty() && !l.starts_with('['));
            let want = format!("{}..={}", range.lo, range.hi);
            assert!(block.clone().any(|l| l.starts_with('#') && l.contains(&want)), "{}: say {want}", range.key);
        }
    }

    #[test]
    fn zero_only_where_it_means_something() {
        let live = range_of("service.live_view_s").expect("listed");
        assert!(live.accepts(0.0) && live.accepts(0.5) && !live.accepts(0.01) && !live.accepts(f64::INFINITY));
        let stale = range_of("output.stale_after_s").expect("listed");
        for bad in [0.0, -1.0, 1e-300, 1e20, f64::NAN, f64::INFINITY] {
            assert!(!stale.accepts(bad), "{bad}");
        }
        assert!(stale.describe().contains("0.1..=86400 s"), "{}", stale.describe());
        let doc = toml::Value::try_from(Config {
            output: crate::config::OutputConfig { stale_after_s: 1e20, ..Default::default() },
            ..Default::default()
        })
        .expect("serializes");
        assert_eq!(check(&doc).map_err(|e| e.message), Err("must be 0.1..=86400 s, got 1e20".to_string()));
    }
}
