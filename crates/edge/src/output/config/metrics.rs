//! `[output.metrics]`: the Prometheus endpoint's address, allow list and limits, and their check.

use super::is_host_port;
use crate::config::{KeyError, allow::AllowList, ensure};
use serde::{Deserialize, Serialize};

/// `[output.metrics]`: a Prometheus endpoint (`GET /metrics`, text format 0.0.4; `docs/metrics.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MetricsConfig {
    /// Address to serve on, HOST:PORT (e.g. `"127.0.0.1:9464"`); empty = off (default).
    pub listen: String,
    /// Addresses or CIDR ranges allowed to connect (`["192.168.1.0/24"]`); empty = everyone. Others
    /// are closed at accept and counted.
    pub allow: Vec<String>,
    /// Connections served at once; more are refused, except that a steady scraper's new connection
    /// closes the oldest one still sending its request head.
    pub max_connections: u32,
    /// Connections served at once from one IP address (at most `max_connections`); more are refused.
    pub max_connections_per_peer: u32,
    /// A request head not complete within this long is answered 408 and the connection closed, ms.
    pub header_timeout_ms: u64,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        Self {
            listen: String::new(),
            allow: Vec::new(),
            max_connections: 32,
            max_connections_per_peer: 2,
            header_timeout_ms: 2000,
        }
    }
}

impl MetricsConfig {
    /// The address (when on) and the allow list must parse.
    pub fn validate(&self) -> Result<(), KeyError> {
        ensure(
            self.listen.is_empty() || is_host_port(&self.listen),
            "output.metrics.listen",
            format!("must be HOST:PORT (e.g. \"127.0.0.1:9464\") or empty (off), got {:?}", self.listen),
        )?;
        AllowList::parse(&self.allow).map(drop).map_err(|e| KeyError::new("output.metrics.allow", e))
    }
}
