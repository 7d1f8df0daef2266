//! `[history]`: the daily CSV files' switch, directory, retention and fsync interval. The ranges
//! (`crate::config::ranges`) are its only checks.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[history]`: one CSV row per output update in daily files `YYYY-MM-DD.csv` (`docs/history.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct HistoryConfig {
    /// Write the history (when a directory resolves: `dir`, else the state directory's `history/`).
    pub enabled: bool,
    /// Days of files kept (today included); older day files are deleted.
    pub keep_days: u32,
    /// Directory of the day files; empty = `history/` in the state directory.
    pub dir: PathBuf,
    /// fsync the day file at most this often, s (0 = after every row). A killed process loses at
    /// most the row in flight; a power cut at most this many seconds of rows.
    pub fsync_s: f64,
}

impl Default for HistoryConfig {
    fn default() -> Self {
        Self { enabled: true, keep_days: 90, dir: PathBuf::new(), fsync_s: 10.0 }
    }
}
