//! The TOML configuration: one section per pipeline stage, validated with errors naming the key.
//!
//! [`Config::load`] parses `config/fme.toml`-style files. Every error names the file, the line and
//! the dotted key (`output.modbus.mode`), so a technician can fix the file without reading code.

mod schema;
mod stages;

pub use schema::*;

use std::path::{Path, PathBuf};

/// A configuration error: the file, the 1-based line (0 when unknown), the dotted key and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A key is unknown, has the wrong type, or a bad value.
    #[error("{path}:{line}: key `{key}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the key (0 when unknown).
        line: usize,
        /// Dotted key, e.g. `output.modbus.mode`.
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl ConfigError {
    /// Dotted key of an `Invalid` error.
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            Self::Read { .. } => None,
        }
    }
}

impl Config {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_path_buf(), source })?;
        Self::parse(&text, path)
    }

    /// Parses and validates configuration text; `path` is only used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let config: Config = toml::from_str(text).map_err(|e| {
            let (line, key) = match e.span() {
                Some(span) => locate_span(text, span.start, e.message()),
                None => (0, String::from("?")),
            };
            ConfigError::Invalid { path: path.to_path_buf(), line, key, message: e.message().trim().to_string() }
        })?;
        if let Err((key, message)) = config.validate() {
            let line = find_key_line(text, &key);
            return Err(ConfigError::Invalid { path: path.to_path_buf(), line, key, message });
        }
        Ok(config)
    }

    /// Checks values that types alone cannot: ranges, consistency between keys.
    /// Returns the first problem as (dotted key, message).
    pub fn validate(&self) -> Result<(), (String, String)> {
        fn err(key: &str, msg: impl Into<String>) -> Result<(), (String, String)> {
            Err((key.to_string(), msg.into()))
        }
        fn positive(key: &str, v: f64) -> Result<(), (String, String)> {
            if v.is_finite() && v > 0.0 { Ok(()) } else { err(key, format!("must be a positive number, got {v}")) }
        }
        fn unit_interval(key: &str, v: f64) -> Result<(), (String, String)> {
            if (0.0..=1.0).contains(&v) { Ok(()) } else { err(key, format!("must be between 0 and 1, got {v}")) }
        }
        let s = &self.source;
        if s.path.as_os_str().is_empty() {
            return err("source.path", "must name a /dev/videoN device or a sequence directory");
        }
        if s.width == 0 || s.height == 0 {
            return err(if s.width == 0 { "source.width" } else { "source.height" }, "must be > 0 px");
        }
        if s.fps == 0 {
            return err("source.fps", "must be > 0 frames/s");
        }
        if s.buffers == 0 || s.buffers > 32 {
            return err("source.buffers", format!("must be 1..=32, got {}", s.buffers));
        }
        if s.timeout_ms == 0 {
            return err("source.timeout_ms", "must be > 0 ms");
        }
        if s.queue_frames == 0 || s.queue_frames > 256 {
            return err("source.queue_frames", format!("must be 1..=256, got {}", s.queue_frames));
        }
        if s.reconnect_min_ms == 0 || s.reconnect_min_ms > s.reconnect_max_ms {
            return err("source.reconnect_min_ms", "must be > 0 and <= source.reconnect_max_ms");
        }
        for (key, model) in [("detector.model", &self.detector.model), ("depth.model", &self.depth.model)] {
            if model.as_os_str().is_empty() {
                return err(key, "must name an ONNX model file");
            }
        }
        positive("detector.rate_hz", self.detector.rate_hz)?;
        unit_interval("detector.confidence", self.detector.confidence)?;
        unit_interval("detector.nms_iou", self.detector.nms_iou)?;
        if self.detector.threads == 0 {
            return err("detector.threads", "must be >= 1");
        }
        positive("depth.rate_hz", self.depth.rate_hz)?;
        if self.depth.threads == 0 {
            return err("depth.threads", "must be >= 1");
        }
        if self.depth.std.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return err("depth.std", format!("must be positive, got {:?}", self.depth.std));
        }
        if self.depth.mean.iter().any(|v| !v.is_finite()) {
            return err("depth.mean", format!("must be finite, got {:?}", self.depth.mean));
        }
        if !["default", "sort"].contains(&self.tracker.preset.as_str()) {
            return err("tracker.preset", format!("must be default or sort, got {:?}", self.tracker.preset));
        }
        if self.tracker.max_tracks == 0 || self.tracker.max_tracks > crate::track::MAX_TRACKS {
            return err("tracker.max_tracks", format!("must be 1..={}", crate::track::MAX_TRACKS));
        }
        unit_interval("tracker.iou_threshold", self.tracker.iou_threshold)?;
        if self.tracker.min_hits == 0 {
            return err("tracker.min_hits", "must be >= 1");
        }
        positive("tracker.max_age_s", self.tracker.max_age_s)?;
        positive("postprocess.box_window_s", self.postprocess.box_window_s)?;
        positive("postprocess.box_ewma_s", self.postprocess.box_ewma_s)?;
        positive("postprocess.depth_jump_m", self.postprocess.depth_jump_m)?;
        positive("postprocess.depth_window_s", self.postprocess.depth_window_s)?;
        let sm = self.postprocess.depth_smoothing_s;
        if !(sm.is_finite() && sm >= 0.0) {
            return err("postprocess.depth_smoothing_s", format!("must be >= 0 s (0 = off), got {sm}"));
        }
        let m = &self.motion;
        if !(m.body_length_m.is_finite() && m.body_length_m >= 0.0) {
            return err("motion.body_length_m", format!("must be >= 0 m (0 = estimated), got {}", m.body_length_m));
        }
        if !(m.speed_span_s.is_finite() && m.speed_span_s >= 0.0) {
            return err("motion.speed_span_s", format!("must be >= 0 s, got {}", m.speed_span_s));
        }
        if !(m.min_age_s.is_finite() && m.min_age_s >= 0.0) {
            return err("motion.min_age_s", format!("must be >= 0 s (0 = off), got {}", m.min_age_s));
        }
        if !(m.body_width_ratio.is_finite() && (0.0..=0.5).contains(&m.body_width_ratio)) {
            return err("motion.body_width_ratio", format!("must be within 0..=0.5, got {}", m.body_width_ratio));
        }
        positive("motion.max_speed_mps", m.max_speed_mps)?;
        positive("motion.smoothing_s", self.motion.smoothing_s)?;
        positive("output.rate_hz", self.output.rate_hz)?;
        if self.output.rate_hz > 100.0 {
            return err("output.rate_hz", "must be <= 100 Hz");
        }
        positive("output.stale_after_s", self.output.stale_after_s)?;
        let m = &self.output.modbus;
        match m.mode {
            ModbusMode::TcpServer if !is_host_port(&m.listen) => {
                return err("output.modbus.listen", format!("must be HOST:PORT, got {:?}", m.listen));
            }
            ModbusMode::TcpClient if !is_host_port(&m.peer) => {
                return err("output.modbus.peer", format!("must be HOST:PORT, got {:?}", m.peer));
            }
            ModbusMode::RtuServer | ModbusMode::RtuClient if m.serial_device.is_empty() => {
                return err("output.modbus.serial_device", "must name a serial device");
            }
            _ => {}
        }
        if m.unit_id == 0 || m.unit_id > 247 {
            return err("output.modbus.unit_id", format!("must be 1..=247, got {}", m.unit_id));
        }
        if m.baud == 0 {
            return err("output.modbus.baud", "must be > 0");
        }
        if !(1..=2).contains(&m.stop_bits) {
            return err("output.modbus.stop_bits", "must be 1 or 2");
        }
        if m.timeout_ms == 0 {
            return err("output.modbus.timeout_ms", "must be > 0 ms");
        }
        if m.reconnect_min_ms == 0 || m.reconnect_min_ms > m.reconnect_max_ms {
            return err("output.modbus.reconnect_min_ms", "must be > 0 and <= output.modbus.reconnect_max_ms");
        }
        if m.max_connections == 0 || m.max_connections > 64 {
            return err("output.modbus.max_connections", format!("must be 1..=64, got {}", m.max_connections));
        }
        if m.max_connections_per_peer == 0 || m.max_connections_per_peer > 64 {
            return err(
                "output.modbus.max_connections_per_peer",
                format!("must be 1..=64 (at most max_connections apply), got {}", m.max_connections_per_peer),
            );
        }
        if let Err(e) = crate::output::allow::AllowList::parse(&m.allow) {
            return err("output.modbus.allow", e);
        }
        if self.output.serial.enabled && self.output.serial.baud == 0 {
            return err("output.serial.baud", "must be > 0");
        }
        if self.console.enabled && self.console.baud == 0 {
            return err("console.baud", "must be > 0");
        }
        if self.console.log_lines == 0 || self.console.log_lines > 10_000 {
            return err("console.log_lines", "must be 1..=10000");
        }
        let f = &self.feeding;
        if !(f.on_above_mps.is_finite() && f.off_below_mps.is_finite()) || f.off_below_mps > f.on_above_mps {
            return err("feeding.off_below_mps", "must be finite and <= feeding.on_above_mps (hysteresis)");
        }
        if !(f.min_on_s >= 0.0 && f.min_off_s >= 0.0) {
            return err(if f.min_on_s >= 0.0 { "feeding.min_off_s" } else { "feeding.min_on_s" }, "must be >= 0 s");
        }
        positive("service.stall_after_s", self.service.stall_after_s)?;
        if self.service.live_view_s.is_nan() || self.service.live_view_s < 0.0 {
            return err("service.live_view_s", "must be >= 0 s");
        }
        if self.service.stop_grace_ms > 1500 {
            return err("service.stop_grace_ms", "must be <= 1500 ms (shutdown must finish within 2 s)");
        }
        Ok(())
    }
}

/// Whether `s` looks like `HOST:PORT` (an IPv4/IPv6 socket address, or a host name and a port).
/// Names are resolved when used, not here: validation must not depend on DNS.
pub fn is_host_port(s: &str) -> bool {
    if s.parse::<std::net::SocketAddr>().is_ok() {
        return true;
    }
    match s.rsplit_once(':') {
        Some((host, port)) => {
            // A host of digits and dots is meant as an IPv4 address and must be one
            // (`256.256.256.256` is not a name to look up later).
            let dotted = host.chars().all(|c| c.is_ascii_digit() || c == '.');
            port.parse::<u16>().is_ok()
                && !host.is_empty()
                && host.chars().all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-')
                && (!dotted || host.parse::<std::net::Ipv4Addr>().is_ok())
        }
        None => false,
    }
}

/// 1-based line of byte offset `pos`, and the dotted key written on that line (section path + key).
/// When toml reports an unknown field, the key name is taken from the message instead.
fn locate_span(text: &str, pos: usize, message: &str) -> (usize, String) {
    let pos = pos.min(text.len());
    let line_no = text[..pos].matches('\n').count() + 1;
    let mut section = String::new();
    let mut key = String::new();
    let mut on_header = false;
    for (i, line) in text.lines().enumerate() {
        if i + 1 > line_no {
            break;
        }
        let t = line.trim();
        if let Some(h) = header_of(t) {
            section = h;
            key.clear();
            on_header = i + 1 == line_no;
        } else if i + 1 == line_no
            && let Some((k, _)) = t.split_once('=')
        {
            key = k.trim().trim_matches('"').to_string();
        }
    }
    // An unknown section (`[sourcee]`): the header itself is the key, not `sourcee.sourcee`.
    if !on_header
        && let Some(rest) = message.split("unknown field `").nth(1)
        && let Some(name) = rest.split('`').next()
    {
        key = name.to_string();
    }
    let dotted = match (section.is_empty(), key.is_empty()) {
        (true, _) => key,
        (false, true) => section,
        (false, false) => format!("{section}.{key}"),
    };
    (line_no, if dotted.is_empty() { "?".into() } else { dotted })
}

/// `[a.b]` -> `a.b`.
fn header_of(trimmed: &str) -> Option<String> {
    let inner = trimmed.strip_prefix('[')?.split(']').next()?;
    Some(inner.trim().to_string())
}

/// 1-based line where dotted `key` is set (`[section]` + `name =`), or of its section header when the
/// key is absent (defaulted), or 0.
pub fn find_key_line(text: &str, key: &str) -> usize {
    let (section, name) = key.rsplit_once('.').unwrap_or(("", key));
    let mut current = String::new();
    let mut header_line = 0;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some(h) = header_of(t) {
            current = h;
            if current == section {
                header_line = i + 1;
            }
            continue;
        }
        if current == section
            && let Some((k, _)) = t.split_once('=')
            && k.trim().trim_matches('"') == name
        {
            return i + 1;
        }
    }
    header_line
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(t: &str) -> Result<Config, ConfigError> {
        Config::parse(t, Path::new("t.toml"))
    }

    #[test]
    fn empty_file_is_defaults() {
        assert_eq!(parse("").ok(), Some(Config::default()));
    }

    #[test]
    fn unknown_key_named_with_line() {
        let e = parse("[source]\nwidth = 640\n\n[output.modbus]\nmdoe = \"tcp-server\"\n").err();
        match e {
            Some(ConfigError::Invalid { line, key, .. }) => {
                assert_eq!(line, 5);
                assert_eq!(key, "output.modbus.mdoe");
            }
            other => panic!("expected Invalid, got {other:?}"),
        }
    }

    #[test]
    fn unknown_section_named_once() {
        let e = parse("[source]\nwidth = 640\n[sourcee]\nwidth = 1\n").err();
        match e {
            Some(ConfigError::Invalid { line, key, .. }) => assert_eq!((line, key.as_str()), (3, "sourcee")),
            other => panic!("expected Invalid, got {other:?}"),
        }
        let e = parse("[output.modbuss]\nmode = \"off\"\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbuss"), "{e:?}");
    }

    #[test]
    fn modbus_allow_and_per_peer_limit_checked() {
        let e = parse("[output.modbus]\nallow = [\"192.168.1.0/24\", \"plc.local\"]\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbus.allow"), "{e:?}");
        let e = parse("[output.modbus]\nmax_connections_per_peer = 0\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbus.max_connections_per_peer"), "{e:?}");
        let c = parse("[output.modbus]\nallow = [\"10.1.2.0/24\"]\n").expect("valid");
        let l = c.output.modbus.tcp_limits();
        assert!(l.allow.permits("10.1.2.9".parse().expect("ip")) && !l.allow.permits("10.1.3.9".parse().expect("ip")));
    }

    #[test]
    fn wrong_type_named_with_line() {
        let e = parse("[detector]\n\nrate_hz = \"fast\"\n").err();
        match e {
            Some(ConfigError::Invalid { line, key, .. }) => {
                assert_eq!(line, 3);
                assert_eq!(key, "detector.rate_hz");
            }
            other => panic!("expected Invalid, got {other:?}"),
        }
    }

    #[test]
    fn spin_is_per_network_and_typed() {
        let c = parse("[detector]\nthreads = 2\nspin = true\n").ok();
        assert_eq!(c.as_ref().map(|c| (c.detector.spin, c.depth.spin)), Some((true, false)));
        let e = parse("[depth]\nspin = \"yes\"\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("depth.spin"));
    }

    #[test]
    fn bad_enum_value_named() {
        let e = parse("[output.modbus]\nmode = \"udp\"\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbus.mode"));
    }

    #[test]
    fn validation_error_names_key_and_line() {
        let e = parse("[feeding]\non_above_mps = 0.1\noff_below_mps = 0.2\n").err();
        match e {
            Some(ConfigError::Invalid { line, key, .. }) => {
                assert_eq!(key, "feeding.off_below_mps");
                assert_eq!(line, 3);
            }
            other => panic!("expected Invalid, got {other:?}"),
        }
        let e = parse("[output]\nrate_hz = -1.0\n").err();
        assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.rate_hz"));
    }

    #[test]
    fn tcp_connection_limits_checked_and_converted() {
        for bad in [0, 65] {
            let e = parse(&format!("[output.modbus]\nmax_connections = {bad}\n")).err();
            assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbus.max_connections"), "{bad}: {e:?}");
        }
        let c = parse("[output.modbus]\nmax_connections = 2\nidle_timeout_ms = 0\n").expect("valid");
        let l = c.output.modbus.tcp_limits();
        assert_eq!((l.max_connections, l.idle_timeout), (2, None), "0 ms = never close idle connections");
        let l = Config::default().output.modbus.tcp_limits();
        assert_eq!((l.max_connections, l.idle_timeout), (8, Some(std::time::Duration::from_secs(60))));
    }

    #[test]
    fn host_port_forms() {
        for ok in ["0.0.0.0:502", "[::1]:5020", "localhost:5020", "plc-1.farm.local:502"] {
            assert!(is_host_port(ok), "{ok}");
        }
        for bad in
            ["localhost", ":502", "plc:99999", "plc 1:502", "", "256.256.256.256:502", "10.0.0:502", "1.2.3.4.5:502"]
        {
            assert!(!is_host_port(bad), "{bad}");
        }
    }

    #[test]
    fn overrides_parse() {
        let c =
            parse("[source]\npath = \"tests/data/seq\"\nloop = false\n[output.modbus]\nword_order = \"low-first\"\n");
        let c = c.ok();
        assert_eq!(c.as_ref().map(|c| c.source.looping), Some(false));
        assert_eq!(c.map(|c| c.output.modbus.word_order), Some(WordOrder::LowFirst));
    }
}
