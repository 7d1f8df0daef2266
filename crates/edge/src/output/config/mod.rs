//! `[output]` and its tables: the outputs' configuration types and their checks, one file per
//! output, beside the outputs that read them. `crate::config` composes and re-exports them.

mod feeding;
mod metrics;
mod modbus;
mod mqtt;
mod serial;

pub use feeding::FeedingConfig;
pub use metrics::MetricsConfig;
pub use modbus::{ModbusConfig, ModbusMode, Parity, WordOrder};
pub use mqtt::{MqttConfig, valid_topic_level};
pub use serial::SerialLineConfig;

use crate::config::{KeyError, ensure};
use serde::{Deserialize, Serialize};

/// `[output]`: update rate and staleness, plus `[output.modbus]`, `[output.serial]` and
/// `[output.metrics]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Activity updates sent to the outputs, Hz (the heartbeat register increments at this rate).
    pub rate_hz: f64,
    /// A value older than this is flagged stale and published as NaN, s.
    pub stale_after_s: f64,
    /// `[output.modbus]`.
    pub modbus: ModbusConfig,
    /// `[output.serial]`.
    pub serial: SerialLineConfig,
    /// `[output.mqtt]`: fleet telemetry to an MQTT broker (docs/mqtt.md).
    pub mqtt: MqttConfig,
    /// `[output.metrics]`: the Prometheus endpoint (`docs/metrics.md`).
    pub metrics: MetricsConfig,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1.0,
            stale_after_s: 5.0,
            modbus: ModbusConfig::default(),
            serial: SerialLineConfig::default(),
            mqtt: MqttConfig::default(),
            metrics: MetricsConfig::default(),
        }
    }
}

impl OutputConfig {
    /// What the ranges (`crate::config::ranges`) cannot check, table by table; the serial line has
    /// nothing more.
    pub fn validate(&self) -> Result<(), KeyError> {
        self.modbus.validate()?;
        self.mqtt.validate()?;
        self.metrics.validate()
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

/// `key` must be HOST:PORT.
fn host_port(key: &str, got: &str) -> Result<(), KeyError> {
    ensure(is_host_port(got), key, format!("must be HOST:PORT, got {got:?}"))
}
