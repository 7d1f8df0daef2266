//! Activity history: one CSV row per output update in daily files `YYYY-MM-DD.csv` (UTC day),
//! kept `history.keep_days` days. The file format and its power-cut guarantees are in
//! `docs/history.md`.
//!
//! ```text
//! Publisher::publish -> HistorySender::send (try_send, never waits; full queue: dropped, counted)
//!     -> fme-history thread -> DayWriter (one write(2) of a whole line per row, fsync policy)
//! ```
//! A row is written with a single `write` of the whole line to a file opened for appending (no
//! user-space buffer), so a killed process loses at most the row in flight. The data is fsynced
//! every `history.fsync_s` seconds (0 = every row), at each day change and at shutdown, so a power
//! cut loses at most the rows of that window. A file is never left unreadable: the writer cuts a
//! torn or zero-filled tail back to the last complete line when it opens a file again, and
//! [`read_day_file`] skips a torn last line. Disk full or a read-only directory pauses the history
//! (logged once per pause, rows counted as failed, status bit 7): the rows wait in memory (at most
//! [`PENDING_ROWS`], the oldest dropped first) and the writer tries again with backoff from
//! [`RETRY_MIN`] to [`RETRY_MAX`], so the history resumes within seconds of space coming back,
//! with the rows of the pause; the registers are never affected.

pub mod config;
pub mod plot;
mod summary;
mod writer;

pub use summary::{HourSummary, format_summary, hourly_report, summarize_hours};
pub use writer::{DayWriter, HistorySender, OpenReport, spawn};

use crate::output::Update;
use fme_core::pipeline::ScaleSource;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// First line of every day file.
pub const HEADER: &str =
    "time_utc,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,status,fault,feeding,scale,unlike_fish";
/// First line of day files written before the `unlike_fish` column: still read, and rows without
/// the column read as `unlike_fish` 0 (a day file begun before an upgrade is continued with the new
/// rows).
pub const HEADER_WITHOUT_UNLIKE_FISH: &str =
    "time_utc,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,status,fault,feeding,scale";
/// First line of day files written before the `scale` column: still read, and rows without the
/// column read as scale `none` (a day file begun before an upgrade is continued with the new rows).
pub const HEADER_WITHOUT_SCALE: &str = "time_utc,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,status,fault,feeding";
/// Rows held between the publisher and the writer thread; when full, rows are dropped and counted.
pub const QUEUE_ROWS: usize = 256;
/// After a write error (disk full, read-only), the first retry comes this soon...
pub const RETRY_MIN: Duration = Duration::from_millis(250);
/// ...and the delay doubles up to this (a failed append of one line costs next to nothing).
pub const RETRY_MAX: Duration = Duration::from_secs(4);
/// Rows held in memory while the disk takes no writes (an hour at `output.rate_hz` = 1, ~60 kB).
pub const PENDING_ROWS: usize = 3600;
const DAY_MS: i64 = 86_400_000;

/// One history row: the columns of one published update, as written to and read from a day file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HistoryRow {
    /// Wall-clock time of the update, ms since the Unix epoch (UTC).
    pub unix_ms: i64,
    /// Swarm mean speed (paper eq. 5), m/s; NaN when stale or unavailable.
    pub activity_mps: f64,
    /// Smoothed activity, m/s; NaN when unavailable.
    pub smoothed_mps: f64,
    /// Half-width of the 95 % interval of the mean, m/s; NaN when unavailable.
    pub ci95_mps: f64,
    /// Fish contributing to the mean.
    pub n_fish: u32,
    /// Mean speed in body lengths per second; NaN when unavailable.
    pub bls: f64,
    /// Status bits of input register 10.
    pub status: u16,
    /// Fault code of input register 11.
    pub fault: u16,
    /// Feeding recommended.
    pub feeding: bool,
    /// What set the metric scale (`depth.scale`; status bit 8).
    pub scale: ScaleSource,
    /// The detections looked unlike fish (status bit 10, `[familiarity]`).
    pub unlike_fish: bool,
}

impl From<&Update> for HistoryRow {
    /// The history's columns of a published update.
    fn from(u: &Update) -> Self {
        Self {
            unix_ms: u.unix_ms,
            activity_mps: u.mean_mps,
            smoothed_mps: u.smoothed_mps,
            ci95_mps: u.ci95_half_mps,
            n_fish: u.fish,
            bls: u.mean_bls,
            status: u.status.bits(),
            fault: u.fault as u16,
            feeding: u.feeding,
            scale: u.scale,
            unlike_fish: u.unlike_fish(),
        }
    }
}

use crate::civil::{civil_from_days, days_from_civil};

/// UTC day number of a time in ms since the Unix epoch.
pub fn day_of(unix_ms: i64) -> i64 {
    unix_ms.div_euclid(DAY_MS)
}

/// `YYYY-MM-DD` of a day number.
pub fn day_name(day: i64) -> String {
    let (y, m, d) = civil_from_days(day);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Parses `YYYY-MM-DD` to a day number; `None` unless it is a real date in that exact form.
pub fn parse_day(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 10 || b[4] != b'-' || b[7] != b'-' {
        return None;
    }
    let num = |r: std::ops::Range<usize>| -> Option<u32> {
        let t = &s[r];
        t.bytes().all(|c| c.is_ascii_digit()).then(|| t.parse().ok()).flatten()
    };
    let (y, m, d) = (num(0..4)?, num(5..7)?, num(8..10)?);
    let day = days_from_civil(i64::from(y), m, d);
    (civil_from_days(day) == (i64::from(y), m, d) && (1..=12).contains(&m) && d >= 1).then_some(day)
}

/// The day file of `day` in `dir`.
pub fn day_path(dir: &Path, day: i64) -> PathBuf {
    dir.join(format!("{}.csv", day_name(day)))
}

/// Appends RFC 3339 UTC time with milliseconds (`YYYY-MM-DDThh:mm:ss.sssZ`).
pub fn format_time(unix_ms: i64, out: &mut String) {
    let (y, mo, d) = civil_from_days(day_of(unix_ms));
    let ms = unix_ms.rem_euclid(DAY_MS);
    let (h, mi, s, f) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
    let _ = write!(out, "{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{f:03}Z");
}

/// Parses the time format of [`format_time`] (exactly that form).
pub fn parse_time(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 24 || b[10] != b'T' || b[13] != b':' || b[16] != b':' || b[19] != b'.' || b[23] != b'Z' {
        return None;
    }
    let day = parse_day(&s[..10])?;
    let num = |r: std::ops::Range<usize>, max: i64| -> Option<i64> {
        let t = &s[r];
        let v: i64 = t.bytes().all(|c| c.is_ascii_digit()).then(|| t.parse().ok()).flatten()?;
        (v <= max).then_some(v)
    };
    let (h, mi, sec, f) = (num(11..13, 23)?, num(14..16, 59)?, num(17..19, 59)?, num(20..23, 999)?);
    Some(day * DAY_MS + h * 3_600_000 + mi * 60_000 + sec * 1000 + f)
}

/// Wall-clock time now, ms since 1970 UTC (0 if the clock is before 1970).
pub fn now_unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}

fn push_num(out: &mut String, v: f64, decimals: usize) {
    // NaN / infinite (no value) is an empty field.
    if v.is_finite() {
        let _ = write!(out, "{v:.decimals$}");
    }
}

/// Appends one CSV line (with its `\n`) for `r`.
pub fn format_row(r: &HistoryRow, out: &mut String) {
    format_time(r.unix_ms, out);
    out.push(',');
    push_num(out, r.activity_mps, 4);
    out.push(',');
    push_num(out, r.smoothed_mps, 4);
    out.push(',');
    push_num(out, r.ci95_mps, 4);
    let _ = write!(out, ",{},", r.n_fish);
    push_num(out, r.bls, 3);
    let _ = writeln!(
        out,
        ",{},{},{},{},{}",
        r.status,
        r.fault,
        u8::from(r.feeding),
        r.scale.name(),
        u8::from(r.unlike_fish)
    );
}

/// Parses one line (without its `\n`) written by [`format_row`].
pub fn parse_row(line: &str) -> Result<HistoryRow, String> {
    let f: Vec<&str> = line.split(',').collect();
    if !(9..=11).contains(&f.len()) {
        return Err(format!("expected 11 fields ({HEADER}), got {}", f.len()));
    }
    let num = |i: usize, name: &str| -> Result<f64, String> {
        if f[i].is_empty() {
            return Ok(f64::NAN);
        }
        f[i].parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("{name}: not a number: {:?}", f[i]))
    };
    let int = |i: usize, name: &str| -> Result<u32, String> {
        f[i].parse::<u32>().map_err(|_| format!("{name}: not a whole number: {:?}", f[i]))
    };
    let small = |i: usize, name: &str| -> Result<u16, String> {
        u16::try_from(int(i, name)?).map_err(|_| format!("{name}: out of range: {}", f[i]))
    };
    Ok(HistoryRow {
        unix_ms: parse_time(f[0]).ok_or_else(|| format!("time_utc: not YYYY-MM-DDTHH:MM:SS.mmmZ: {:?}", f[0]))?,
        activity_mps: num(1, "activity_mps")?,
        smoothed_mps: num(2, "smoothed_mps")?,
        ci95_mps: num(3, "ci95_mps")?,
        n_fish: int(4, "n_fish")?,
        bls: num(5, "bls")?,
        status: small(6, "status")?,
        fault: small(7, "fault")?,
        feeding: match f[8] {
            "0" => false,
            "1" => true,
            o => return Err(format!("feeding: must be 0 or 1, got {o:?}")),
        },
        scale: match f.get(9) {
            None => ScaleSource::None,
            Some(v) => ScaleSource::parse(v).ok_or_else(|| format!("scale: references, fish or none, got {v:?}"))?,
        },
        unlike_fish: match f.get(10) {
            None | Some(&"0") => false,
            Some(&"1") => true,
            Some(o) => return Err(format!("unlike_fish: must be 0 or 1, got {o:?}")),
        },
    })
}

/// Errors reading history files.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// A file or directory could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line is not a history row.
    #[error("{}:{line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// The rows of one day file.
#[derive(Debug, Clone, Default)]
pub struct DayFile {
    /// Complete rows, in file order.
    pub rows: Vec<HistoryRow>,
    /// The file ended in an incomplete line (a power cut or a kill mid-write), which was skipped.
    pub torn_last_line: bool,
}

/// Reads a day file. A last line without its `\n` (torn by a kill or power cut) is skipped and
/// flagged; any other line that is not a row is an error naming the file and line.
pub fn read_day_file(path: &Path) -> Result<DayFile, HistoryError> {
    let bytes = std::fs::read(path).map_err(|source| HistoryError::Io { path: path.to_path_buf(), source })?;
    let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let mut out = DayFile { rows: Vec::new(), torn_last_line: complete < bytes.len() };
    let bad = |line: usize, message: String| HistoryError::Line { path: path.to_path_buf(), line, message };
    for (i, raw) in bytes[..complete].split(|&b| b == b'\n').enumerate() {
        if i == 0 && complete > 0 {
            if ![HEADER, HEADER_WITHOUT_UNLIKE_FISH, HEADER_WITHOUT_SCALE].iter().any(|h| raw == h.as_bytes()) {
                return Err(bad(1, format!("not a history file: the first line must be `{HEADER}`")));
            }
            continue;
        }
        if raw.is_empty() {
            continue; // the end after the last '\n'
        }
        let line = std::str::from_utf8(raw).map_err(|_| bad(i + 1, "not text".into()))?;
        out.rows.push(parse_row(line).map_err(|m| bad(i + 1, m))?);
    }
    Ok(out)
}

/// Rows of `dir` with `from_ms <= time < to_ms`, from the day files covering that range (missing
/// days are skipped). Returns the rows and the number of torn last lines skipped.
pub fn read_range(dir: &Path, from_ms: i64, to_ms: i64) -> Result<(Vec<HistoryRow>, usize), HistoryError> {
    let mut rows = Vec::new();
    let mut torn = 0;
    for day in day_of(from_ms)..=day_of(to_ms - 1) {
        let p = day_path(dir, day);
        if !p.exists() {
            continue;
        }
        let f = read_day_file(&p)?;
        torn += usize::from(f.torn_last_line);
        rows.extend(f.rows.into_iter().filter(|r| (from_ms..to_ms).contains(&r.unix_ms)));
    }
    rows.sort_by_key(|r| r.unix_ms);
    Ok((rows, torn))
}

#[cfg(test)]
mod tests;
