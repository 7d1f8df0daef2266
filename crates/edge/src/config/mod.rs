//! The one configuration: a TOML file whose sections mirror the pipeline, read by every command.
//!
//! [`Config::load`] reads `config/fme.toml`-style files; [`Config::load_with`] adds command-line
//! `--set section.key=value` overrides. Every error names the file (or the `--set`), the line and
//! the dotted key (`output.modbus.mode`), so a technician can fix the file without reading code.
//! Every section is its module's own type with its own check (the pipeline's in the core's stage
//! modules, the edge's in `capture/config.rs`, `output/config/`, ...); each check names the key in
//! a [`KeyError`], and this module places it in the file or the `--set`.

pub mod allow;
pub mod files;
mod key_error;
mod lines;
pub mod ranges;
mod schema;
mod stages;

pub use crate::output::config::{is_host_port, valid_topic_level};
pub use key_error::{KeyError, ensure};
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
        if let Err(KeyError { key, message }) = config.validate() {
            return Err(located(key, message));
        }
        Ok((config, effective))
    }

    /// The configuration as TOML (`fme config show`): every key with its value; reads back equal.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot show the config: {e}\n"))
    }

    /// Checks values that types alone cannot: every ranged key against its documented range
    /// ([`ranges::RANGES`]), then each section's own check in file order. The first problem is
    /// the error.
    pub fn validate(&self) -> Result<(), KeyError> {
        let doc =
            toml::Value::try_from(self).map_err(|e| KeyError::new("?", format!("cannot check the values: {e}")))?;
        ranges::check(&doc)?;
        self.source.validate()?;
        stages::check(self)?;
        self.output.validate()?;
        self.feeding.validate()?;
        self.web.validate()?;
        self.record.validate()
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
        let w = &self.web;
        if allow::open_to_all(&w.listen, &w.allow) {
            out.push((
                "web.allow".to_string(),
                format!(
                    "empty while web.listen is {:?}: every host on the network may open the web page; list who may, \
                     e.g. [\"192.168.1.0/24\"]",
                    w.listen
                ),
            ));
        }
        out
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
    fn every_section_check_returns_a_key_error() {
        let peer = ModbusConfig { mode: ModbusMode::TcpClient, peer: "x".into(), ..Default::default() };
        assert_eq!(peer.validate(), Err(KeyError::new("output.modbus.peer", "must be HOST:PORT, got \"x\"")));
        let source = SourceConfig { path: "".into(), ..Default::default() };
        assert_eq!(source.validate().map_err(|e| e.key), Err("source.path".to_string()));
        let feeding = FeedingConfig { off_below_mps: 0.5, ..Default::default() };
        assert_eq!(feeding.validate().map_err(|e| e.key), Err("feeding.off_below_mps".to_string()));
        let record = RecordConfig { alarm_low_mps: 0.5, alarm_high_mps: 0.2, ..Default::default() };
        assert_eq!(record.validate().map_err(|e| e.key), Err("record.alarm_high_mps".to_string()));
        let mqtt = MqttConfig { password_file: "/etc/fme/pw".into(), ..Default::default() };
        let e = mqtt.validate().err();
        assert_eq!(
            e.map(|e| e.to_string()).as_deref(),
            Some("key `output.mqtt.username`: must be set when output.mqtt.password_file is set")
        );
        // The composition keeps the sections' order: the first problem in the file is the error.
        let c = Config { source, output: OutputConfig { modbus: peer, ..Default::default() }, ..Default::default() };
        assert_eq!(c.validate().map_err(|e| e.key), Err("source.path".to_string()));
    }

    #[test]
    fn pipeline_section_errors_name_their_key() {
        for (text, key) in [
            ("[detector]\nmax_candidates = 1\n", "detector.max_candidates"),
            ("[depth]\nstd = [0.0, 1.0, 1.0]\n", "depth.std"),
            ("[familiarity]\nmin_out = 9\n", "familiarity.min_out"),
            ("[depth]\nscale = \"fish\"\n[motion]\nbody_length_m = 0.0\n", "depth.scale"),
        ] {
            let e = parse(text).err();
            assert_eq!(e.as_ref().and_then(|e| e.key()), Some(key), "{text}: {e:?}");
        }
        // The tracker checks itself as it is read; built in code, its check still names the key.
        let c =
            Config { tracker: TrackerConfig { det_threshold: f64::NAN, ..Default::default() }, ..Default::default() };
        assert_eq!(c.validate().map_err(|e| e.key), Err("tracker.det_threshold".to_string()));
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
