//! `[service]`: the daemon's watchdog, stop, disk-stall and state-directory settings. The ranges
//! (`crate::config::ranges`) are its only checks.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[service]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Notify systemd (READY, WATCHDOG pings from the frame loop) when started by it.
    pub systemd_notify: bool,
    /// The pipeline counts as stuck when it has not finished a frame for this long, s.
    pub stall_after_s: f64,
    /// Print a live one-line view of the activity on stderr (for demos), s between refreshes (0 = off).
    pub live_view_s: f64,
    /// On SIGTERM/SIGINT: keep serving the "stopped" registers this long before exiting, ms (<= 1500).
    pub stop_grace_ms: u64,
    /// A write to the state directory (ring frame, snapshot, history row) still in flight after this
    /// long is a stalled disk: status bit 7, s.
    pub disk_stall_s: f64,
    /// Directory for recordings, snapshots and history when `$STATE_DIRECTORY` (systemd's
    /// `StateDirectory=`) is not set; empty = none (nothing is written to disk). See
    /// [`crate::status::state_dir`].
    pub state_dir: PathBuf,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            systemd_notify: true,
            stall_after_s: 5.0,
            live_view_s: 0.0,
            stop_grace_ms: 500,
            disk_stall_s: 3.0,
            state_dir: PathBuf::new(),
        }
    }
}
