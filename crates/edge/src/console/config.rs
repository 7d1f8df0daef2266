//! `[console]`: the serial field-diagnostics console's port and log. The ranges
//! (`crate::config::ranges`) are its only checks.

use serde::{Deserialize, Serialize};

/// `[console]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ConsoleConfig {
    /// Serve the console.
    pub enabled: bool,
    /// Serial device (or a pty path).
    pub device: String,
    /// Baud rate, bit/s.
    pub baud: u32,
    /// Log lines kept for `log [n]`.
    pub log_lines: usize,
    /// Echo typed characters back (picocom/screen do not echo locally).
    pub echo: bool,
}

impl Default for ConsoleConfig {
    fn default() -> Self {
        Self { enabled: false, device: "/dev/ttyS0".into(), baud: 115_200, log_lines: 200, echo: true }
    }
}
