//! The one configuration: a TOML file whose sections mirror the pipeline, read by every command.
//!
//! [`Config::load`] reads `config/fme.toml`-style files; [`Config::load_with`] adds command-line
//! `--set section.key=value` overrides. Every error names the file (or the `--set`), the line and
//! the dotted key (`output.modbus.mode`), so a technician can fix the file without reading code.
//! The pipeline sections are the stage modules' own types; this module composes and checks them.

pub mod allow;
pub mod files;
mod lines;
pub mod ranges;
mod schema;
mod stages;

pub use schema::*;

use std::path::{Path, PathBuf};

/// Where a configuration came from, for messages.
const DEFAULTS: &str = "(built-in defaults)";

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
    /// A `--set` override is malformed or gives a bad value.
    #[error("--set {assignment}: {message}")]
    Override {
        /// The override as given.
        assignment: String,
        /// What is wrong.
        message: String,
    },
}

impl ConfigError {
    /// Dotted key of an `Invalid` error.
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            Self::Read { .. } | Self::Override { .. } => None,
        }
    }
}

impl Config {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::load_with(Some(path), &[]).map(|(c, _)| c)
    }

    /// Reads `path` (`None`: the built-in defaults, which equal `config/fme.toml`), applies the
    /// `--set section.key=value` overrides in order and validates the result. Returns the config and
    /// the effective TOML text (the file with the overrides written in).
    pub fn load_with(path: Option<&Path>, sets: &[String]) -> Result<(Self, String), ConfigError> {
        match path {
            Some(p) => {
                let text =
                    std::fs::read_to_string(p).map_err(|source| ConfigError::Read { path: p.to_path_buf(), source })?;
                Self::from_text(&text, p, sets)
            }
            None => Self::from_text("", Path::new(DEFAULTS), sets),
        }
    }

    /// Parses and validates configuration text; `path` is only used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        Self::from_text(text, path, &[]).map(|(c, _)| c)
    }

    fn from_text(text: &str, path: &Path, sets: &[String]) -> Result<(Self, String), ConfigError> {
        let mut doc: toml_edit::DocumentMut = text.parse().map_err(|e: toml_edit::TomlError| {
            let line = e.span().map_or(0, |s| lines::line_of(text, s.start));
            let key = e.span().map_or_else(|| "?".to_string(), |s| lines::key_near(text, s.start));
            ConfigError::Invalid { path: path.to_path_buf(), line, key, message: e.message().trim().to_string() }
        })?;
        let mut set_keys = Vec::with_capacity(sets.len());
        for a in sets {
            set_keys.push((lines::apply_set(&mut doc, a)?, a.clone()));
        }
        let effective = if sets.is_empty() { text.to_string() } else { doc.to_string() };
        // An error in a key a `--set` gave names the `--set`; others name the file and line.
        let located = |key: String, message: String| {
            let by_set = set_keys.iter().rev().find(|(k, _)| key == *k || key.starts_with(&format!("{k}.")));
            match by_set {
                Some((_, a)) => {
                    ConfigError::Override { assignment: a.clone(), message: format!("key `{key}`: {message}") }
                }
                None => {
                    ConfigError::Invalid { path: path.to_path_buf(), line: lines::key_line(text, &key), key, message }
                }
            }
        };
        let config: Config = serde_path_to_error::deserialize(toml::Deserializer::new(&effective)).map_err(|e| {
            let message = e.inner().message().trim().to_string();
            let mut key = e.path().to_string();
            // An unknown key, or a key a section's own check names (`key `x``): name it in full.
            let named = message.split("unknown field `").nth(1).or_else(|| message.split("key `").nth(1));
            if let Some(name) = named.and_then(|r| r.split('`').next()) {
                if key == "." || key.is_empty() {
                    key = name.to_string();
                } else if !key.ends_with(&format!(".{name}")) && key != name {
                    key = format!("{key}.{name}");
                }
            }
            located(key, message)
        })?;
        if let Err((key, message)) = config.validate() {
            return Err(located(key, message));
        }
        Ok((config, effective))
    }

    /// The configuration as TOML (`fme config show`): every key with its value; reads back equal.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot show the config: {e}\n"))
    }

    /// Checks values that types alone cannot: ranges, consistency between keys.
    /// Returns the first problem as (dotted key, message).
    pub fn validate(&self) -> Result<(), (String, String)> {
        fn err(key: &str, msg: impl Into<String>) -> Result<(), (String, String)> {
            Err((key.to_string(), msg.into()))
        }
        // Every duration, rate, size and count key against its documented range (`ranges::RANGES`).
        let doc =
            toml::Value::try_from(self).map_err(|e| ("?".to_string(), format!("cannot check the values: {e}")))?;
        ranges::check(&doc)?;
        let s = &self.source;
        if s.path.as_os_str().is_empty() {
            return err("source.path", "must name a /dev/videoN device or a sequence directory");
        }
        if s.reconnect_min_ms > s.reconnect_max_ms {
            return err("source.reconnect_min_ms", "must be <= source.reconnect_max_ms");
        }
        // The pipeline sections check themselves; their messages start with or name the key.
        let keyed = |m: &str| (m.split_whitespace().next().unwrap_or("?").to_string(), m.to_string());
        let infer_err = |e: fme_core::infer::InferError| match e {
            fme_core::infer::InferError::Config { key, reason } => (key.to_string(), reason),
            other => ("?".to_string(), other.to_string()),
        };
        self.detector.validate().map_err(infer_err)?;
        self.depth.validate().map_err(infer_err)?;
        self.tracker.validate().map_err(|e| match e {
            fme_core::track::TrackerConfigError::Key(k, m) => (format!("tracker.{k}"), m),
            other => ("tracker".to_string(), other.to_string()),
        })?;
        self.postprocess.validate().map_err(keyed)?;
        self.motion.validate().map_err(keyed)?;
        self.familiarity.validate().map_err(|m| keyed(&m))?;
        if self.depth.scale == fme_core::metric::DepthScale::Fish && self.motion.body_length().is_none() {
            return err("depth.scale", "\"fish\" needs the cohort's mean length: motion.body_length_m > 0");
        }
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
        if m.reconnect_min_ms > m.reconnect_max_ms {
            return err("output.modbus.reconnect_min_ms", "must be <= output.modbus.reconnect_max_ms");
        }
        if let Err(e) = allow::AllowList::parse(&m.allow) {
            return err("output.modbus.allow", e);
        }
        let q = &self.output.mqtt;
        if q.enabled && !is_host_port(&q.broker) {
            return err("output.mqtt.broker", format!("must be HOST:PORT, got {:?}", q.broker));
        }
        if !valid_topic_level(&q.prefix) || q.prefix.is_empty() {
            return err(
                "output.mqtt.prefix",
                format!("must be a non-empty topic level without / + # or spaces, got {:?}", q.prefix),
            );
        }
        if !valid_topic_level(&q.box_id) {
            return err(
                "output.mqtt.box_id",
                format!("must be a topic level without / + # or spaces (empty = host name), got {:?}", q.box_id),
            );
        }
        if q.reconnect_min_ms > q.reconnect_max_ms {
            return err("output.mqtt.reconnect_min_ms", "must be <= output.mqtt.reconnect_max_ms");
        }
        if q.cert_file.as_os_str().is_empty() != q.key_file.as_os_str().is_empty() {
            let key = if q.key_file.as_os_str().is_empty() { "output.mqtt.key_file" } else { "output.mqtt.cert_file" };
            return err(key, "a client certificate needs both output.mqtt.cert_file and output.mqtt.key_file");
        }
        let tls_files = !q.ca_file.as_os_str().is_empty() || !q.cert_file.as_os_str().is_empty();
        if tls_files && !q.tls {
            return err("output.mqtt.tls", "must be true when output.mqtt.ca_file or cert_file is set");
        }
        if !q.password_file.as_os_str().is_empty() && q.username.is_empty() {
            return err("output.mqtt.username", "must be set when output.mqtt.password_file is set");
        }
        let mx = &self.output.metrics;
        if !mx.listen.is_empty() && !is_host_port(&mx.listen) {
            return err(
                "output.metrics.listen",
                format!("must be HOST:PORT (e.g. \"127.0.0.1:9464\") or empty (off), got {:?}", mx.listen),
            );
        }
        if let Err(e) = allow::AllowList::parse(&mx.allow) {
            return err("output.metrics.allow", e);
        }
        let f = &self.feeding;
        if f.off_below_mps > f.on_above_mps {
            return err("feeding.off_below_mps", "must be <= feeding.on_above_mps (hysteresis)");
        }
        let r = &self.record;
        if r.alarm_high_mps > 0.0 && r.alarm_high_mps <= r.alarm_low_mps {
            return err("record.alarm_high_mps", "must be > record.alarm_low_mps");
        }
        Ok(())
    }
}

impl Config {
    /// What `fme config check` warns about without failing, as (dotted key, message): a TCP server
    /// (Modbus, metrics) open to every address on the network (allow list empty, listen address
    /// not loopback).
    pub fn warnings(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let m = &self.output.modbus;
        if m.mode == ModbusMode::TcpServer && allow::open_to_all(&m.listen, &m.allow) {
            out.push((
                "output.modbus.allow".to_string(),
                format!(
                    "empty while output.modbus.listen is {:?}: every host on the network may read the registers and \
                     write HR 100-103; list the PLC's address (and any HMI/SCADA poller), e.g. [\"192.168.1.20\"]",
                    m.listen
                ),
            ));
        }
        let mx = &self.output.metrics;
        if allow::open_to_all(&mx.listen, &mx.allow) {
            out.push((
                "output.metrics.allow".to_string(),
                format!(
                    "empty while output.metrics.listen is {:?}: every host on the network may scrape; list the \
                     Prometheus server's address, e.g. [\"192.168.1.30\"]",
                    mx.listen
                ),
            ));
        }
        out
    }
}

/// Whether `s` may be one level of an MQTT topic: no `/`, no wildcards `+` `#`, no spaces or
/// control characters, at most 64 bytes (empty is allowed here; callers decide).
pub fn valid_topic_level(s: &str) -> bool {
    s.len() <= 64 && !s.chars().any(|c| c == '/' || c == '+' || c == '#' || c.is_whitespace() || c.is_control())
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
        let l = allow::AllowList::parse(&c.output.modbus.allow).expect("checked");
        assert!(l.permits("10.1.2.9".parse().expect("ip")) && !l.permits("10.1.3.9".parse().expect("ip")));
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
    fn mqtt_keys_checked() {
        for (text, key) in [
            ("enabled = true\nbroker = \"nohost\"", "output.mqtt.broker"),
            ("prefix = \"a/b\"", "output.mqtt.prefix"),
            ("box_id = \"cage#1\"", "output.mqtt.box_id"),
            ("qos = 2", "output.mqtt.qos"),
            ("keepalive_s = 1", "output.mqtt.keepalive_s"),
            ("connect_timeout_s = 0", "output.mqtt.connect_timeout_s"),
            ("queue_messages = 0", "output.mqtt.queue_messages"),
            ("reconnect_min_ms = 90000", "output.mqtt.reconnect_min_ms"),
            ("tls = true\ncert_file = \"c.pem\"", "output.mqtt.key_file"),
            ("ca_file = \"ca.pem\"", "output.mqtt.tls"),
            ("password_file = \"/etc/fme/pw\"", "output.mqtt.username"),
        ] {
            let e = parse(&format!("[output.mqtt]\n{text}\n")).err();
            assert_eq!(e.as_ref().and_then(|e| e.key()), Some(key), "{text}: {e:?}");
        }
        let c = parse("[output.mqtt]\nenabled = true\nbroker = \"broker.farm:8883\"\ntls = true\n").expect("valid");
        assert_eq!(c.output.mqtt.qos, 1);
    }

    #[test]
    fn tcp_connection_limits_checked() {
        for bad in [0, 65] {
            let e = parse(&format!("[output.modbus]\nmax_connections = {bad}\n")).err();
            assert_eq!(e.as_ref().and_then(|e| e.key()), Some("output.modbus.max_connections"), "{bad}: {e:?}");
        }
    }

    #[test]
    fn open_servers_are_warned_about() {
        let c = parse("[output.modbus]\nlisten = \"0.0.0.0:502\"\n[output.metrics]\nlisten = \"0.0.0.0:9464\"\n")
            .expect("valid");
        let keys: Vec<String> = c.warnings().into_iter().map(|w| w.0).collect();
        assert_eq!(keys, ["output.modbus.allow", "output.metrics.allow"]);
        let c = parse("[output.modbus]\nlisten = \"0.0.0.0:502\"\nallow = [\"10.0.0.5\"]\n").expect("valid");
        assert!(c.warnings().is_empty(), "{:?}", c.warnings());
        assert!(Config::default().warnings().is_empty(), "the defaults listen on loopback only");
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
