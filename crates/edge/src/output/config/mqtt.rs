//! `[output.mqtt]`: the broker, topics, queue, credentials and TLS files, and their check.

use super::host_port;
use crate::config::{KeyError, ensure};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[output.mqtt]`: activity, status, events and the effective config published to an MQTT broker
/// under `<prefix>/<box_id>/` (docs/mqtt.md). The pipeline and Modbus never wait on it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MqttConfig {
    /// Publish to the broker.
    pub enabled: bool,
    /// The broker, HOST:PORT (a name is resolved at each connect).
    pub broker: String,
    /// Client id and topic level of this box; empty = the host name.
    pub box_id: String,
    /// First topic level.
    pub prefix: String,
    /// QoS of every message: 0 (at most once) or 1 (at least once).
    pub qos: u8,
    /// MQTT keep-alive, s: the broker publishes the Last Will ("offline") after 1.5 x this without
    /// a packet from a box that vanished without closing its connection.
    pub keepalive_s: u64,
    /// Longest wait for the broker's CONNACK after starting a connection (TCP, TLS and CONNECT
    /// together), s. Generous, for slow links (4G, satellite: 300-700 ms round trip); a connection
    /// that takes longer is closed and retried after the backoff.
    pub connect_timeout_s: u64,
    /// Messages held while the broker is away; when full, the oldest is dropped and counted.
    pub queue_messages: usize,
    /// First reconnect delay, ms (doubles up to `reconnect_max_ms`).
    pub reconnect_min_ms: u64,
    /// Longest reconnect delay, ms.
    pub reconnect_max_ms: u64,
    /// User name; empty = none.
    pub username: String,
    /// File holding the password (first line; read at each connect, never logged); empty = none.
    pub password_file: PathBuf,
    /// Connect with TLS (rustls).
    pub tls: bool,
    /// TLS: CA certificate(s) (PEM) the broker's certificate must chain to; empty = the system's roots.
    pub ca_file: PathBuf,
    /// TLS: client certificate chain (PEM), for brokers that require one; empty = none.
    pub cert_file: PathBuf,
    /// TLS: the client certificate's private key (PEM); needed with `cert_file`.
    pub key_file: PathBuf,
}

impl Default for MqttConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            broker: "localhost:1883".into(),
            box_id: String::new(),
            prefix: "fme".into(),
            qos: 1,
            keepalive_s: 30,
            connect_timeout_s: 20,
            queue_messages: 1000,
            reconnect_min_ms: 1000,
            reconnect_max_ms: 60_000,
            username: String::new(),
            password_file: PathBuf::new(),
            tls: false,
            ca_file: PathBuf::new(),
            cert_file: PathBuf::new(),
            key_file: PathBuf::new(),
        }
    }
}

impl MqttConfig {
    /// The broker (when enabled), the topic levels, the reconnect delays' order and which
    /// credential and TLS keys need one another.
    pub fn validate(&self) -> Result<(), KeyError> {
        if self.enabled {
            host_port("output.mqtt.broker", &self.broker)?;
        }
        ensure(
            valid_topic_level(&self.prefix) && !self.prefix.is_empty(),
            "output.mqtt.prefix",
            format!("must be a non-empty topic level without / + # or spaces, got {:?}", self.prefix),
        )?;
        ensure(
            valid_topic_level(&self.box_id),
            "output.mqtt.box_id",
            format!("must be a topic level without / + # or spaces (empty = host name), got {:?}", self.box_id),
        )?;
        let delays = self.reconnect_min_ms <= self.reconnect_max_ms;
        ensure(delays, "output.mqtt.reconnect_min_ms", "must be <= output.mqtt.reconnect_max_ms")?;
        let (no_cert, no_key) = (self.cert_file.as_os_str().is_empty(), self.key_file.as_os_str().is_empty());
        ensure(
            no_cert == no_key,
            if no_key { "output.mqtt.key_file" } else { "output.mqtt.cert_file" },
            "a client certificate needs both output.mqtt.cert_file and output.mqtt.key_file",
        )?;
        let tls_files = !self.ca_file.as_os_str().is_empty() || !no_cert;
        ensure(!tls_files || self.tls, "output.mqtt.tls", "must be true when output.mqtt.ca_file or cert_file is set")?;
        ensure(
            self.password_file.as_os_str().is_empty() || !self.username.is_empty(),
            "output.mqtt.username",
            "must be set when output.mqtt.password_file is set",
        )
    }
}

/// Whether `s` may be one level of an MQTT topic: no `/`, no wildcards `+` `#`, no spaces or
/// control characters, at most 64 bytes (empty is allowed here; callers decide).
pub fn valid_topic_level(s: &str) -> bool {
    s.len() <= 64 && !s.chars().any(|c| c == '/' || c == '+' || c == '#' || c.is_whitespace() || c.is_control())
}
