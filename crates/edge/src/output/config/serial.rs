//! `[output.serial]`: the ASCII line output's port. The ranges (`crate::config::ranges`) are its
//! only checks.

use serde::{Deserialize, Serialize};

/// `[output.serial]`: one ASCII line per update for simple data loggers.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SerialLineConfig {
    /// Write the line output.
    pub enabled: bool,
    /// Serial device.
    pub device: String,
    /// Baud rate, bit/s.
    pub baud: u32,
}

impl Default for SerialLineConfig {
    fn default() -> Self {
        Self { enabled: false, device: "/dev/ttyUSB1".into(), baud: 9600 }
    }
}
