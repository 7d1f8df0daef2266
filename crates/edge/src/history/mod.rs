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

use crate::status::{HistoryStatus, Shared};
use fme_core::pipeline::ScaleSource;
use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::os::unix::fs::FileExt as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::{Duration, Instant};
use tracing::Level;

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

/// One output update, as written to the history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
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
pub fn format_row(r: &Row, out: &mut String) {
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
pub fn parse_row(line: &str) -> Result<Row, String> {
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
    Ok(Row {
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
    pub rows: Vec<Row>,
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
pub fn read_range(dir: &Path, from_ms: i64, to_ms: i64) -> Result<(Vec<Row>, usize), HistoryError> {
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

/// Longest gap between rows still counted as feeding time, ms (a longer gap is the daemon down).
const FEEDING_GAP_MS: i64 = 60_000;

/// One hour of history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HourSummary {
    /// Start of the hour, ms since 1970 UTC.
    pub start_ms: i64,
    /// Rows in the hour.
    pub rows: u32,
    /// Rows with an activity value.
    pub valued: u32,
    /// Least activity, m/s (NaN without values).
    pub min_mps: f64,
    /// Mean activity, m/s (NaN without values).
    pub mean_mps: f64,
    /// Greatest activity, m/s (NaN without values).
    pub max_mps: f64,
    /// Time with feeding recommended, s (each row until the next, gaps over 60 s not counted).
    pub feeding_s: f64,
    /// Rows with a fault ([`crate::status::is_fault_code`]: not 0 none, not 6 stopped).
    pub fault_rows: u32,
}

/// Hourly summaries of `rows` (sorted by time) for the `hours` UTC hours from `first_hour_ms`.
pub fn summarize_hours(rows: &[Row], first_hour_ms: i64, hours: usize) -> Vec<HourSummary> {
    let mut out: Vec<HourSummary> = (0..hours)
        .map(|i| HourSummary {
            start_ms: first_hour_ms + i as i64 * 3_600_000,
            rows: 0,
            valued: 0,
            min_mps: f64::INFINITY,
            mean_mps: 0.0,
            max_mps: f64::NEG_INFINITY,
            feeding_s: 0.0,
            fault_rows: 0,
        })
        .collect();
    for (i, r) in rows.iter().enumerate() {
        let k = (r.unix_ms - first_hour_ms).div_euclid(3_600_000);
        let Some(h) = usize::try_from(k).ok().and_then(|k| out.get_mut(k)) else { continue };
        h.rows += 1;
        h.fault_rows += u32::from(crate::status::is_fault_code(r.fault));
        if r.activity_mps.is_finite() {
            h.valued += 1;
            h.min_mps = h.min_mps.min(r.activity_mps);
            h.max_mps = h.max_mps.max(r.activity_mps);
            h.mean_mps += r.activity_mps;
        }
        if r.feeding
            && let Some(next) = rows.get(i + 1)
        {
            let dt = next.unix_ms - r.unix_ms;
            if (0..=FEEDING_GAP_MS).contains(&dt) {
                h.feeding_s += dt as f64 / 1000.0;
            }
        }
    }
    for h in &mut out {
        if h.valued == 0 {
            (h.min_mps, h.mean_mps, h.max_mps) = (f64::NAN, f64::NAN, f64::NAN);
        } else {
            h.mean_mps /= f64::from(h.valued);
        }
    }
    out
}

/// The console's `history [hours]` text: one line per UTC hour with rows among the last `hours`
/// hours up to `now_ms`, read from `dir`; a box without rows in that time says so in one line.
pub fn hourly_report(dir: &Path, now_ms: i64, hours: usize) -> Result<String, HistoryError> {
    let first = (now_ms.div_euclid(3_600_000) - hours as i64 + 1) * 3_600_000;
    let (rows, torn) = read_range(dir, first, now_ms + 1)?;
    if rows.is_empty() {
        return Ok(format!("no history yet: no rows in the last {hours} hours ({})\n", dir.display()));
    }
    Ok(format_summary(&summarize_hours(&rows, first, hours), torn))
}

/// Formats hourly summaries as a table (m/s, feeding minutes); only hours with rows are listed
/// (a box that was off, or new, has no line of zeros).
pub fn format_summary(hours: &[HourSummary], torn: usize) -> String {
    let mut s = String::from("hour (UTC)        rows   min    mean   max  m/s  feeding-min  fault-rows\n");
    let v = |x: f64| if x.is_finite() { format!("{x:6.3}") } else { "     -".to_string() };
    for h in hours.iter().filter(|h| h.rows > 0) {
        let mut t = String::new();
        format_time(h.start_ms, &mut t);
        let _ = writeln!(
            s,
            "{} {}  {:5} {} {} {}  {:11.1}  {:10}",
            &t[..10],
            &t[11..16],
            h.rows,
            v(h.min_mps),
            v(h.mean_mps),
            v(h.max_mps),
            h.feeding_s / 60.0,
            h.fault_rows
        );
    }
    if torn > 0 {
        let _ = writeln!(s, "({torn} torn last line(s) skipped)");
    }
    s
}

/// Writes rows to the day files of one directory: rotation at the UTC day of each row, retention,
/// fsync policy, repair of a torn tail. Synchronous; [`spawn`] runs it on its own thread.
#[derive(Debug)]
pub struct DayWriter {
    dir: PathBuf,
    keep_days: u32,
    fsync_ms: i64,
    file: Option<OpenDay>,
    line: String,
    last_sync_ms: i64,
    unsynced: u32,
}

#[derive(Debug)]
struct OpenDay {
    day: i64,
    file: File,
    len: u64,
}

/// What opening a day file found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OpenReport {
    /// Bytes of a torn or zero-filled tail cut off.
    pub cut_bytes: u64,
    /// Old day files deleted (retention).
    pub deleted: usize,
}

impl DayWriter {
    /// A writer into `dir` keeping `keep_days` days (today included) and fsyncing every `fsync_s`
    /// seconds of row time (0 = every row).
    pub fn new(dir: &Path, keep_days: u32, fsync_s: f64) -> Self {
        Self {
            dir: dir.to_path_buf(),
            keep_days: keep_days.max(1),
            fsync_ms: (fsync_s.max(0.0) * 1000.0) as i64,
            file: None,
            line: String::with_capacity(160),
            last_sync_ms: i64::MIN,
            unsynced: 0,
        }
    }

    /// Appends one row (one `write` of the whole line), opening the row's day file first when the
    /// day changed. On an error the file is cut back to its last complete row and closed; the
    /// next call opens it again. Returns what an open found (torn tail cut, old files deleted).
    pub fn write(&mut self, r: &Row) -> std::io::Result<OpenReport> {
        let day = day_of(r.unix_ms);
        let mut report = OpenReport::default();
        if self.file.as_ref().is_none_or(|f| f.day != day) {
            let _ = self.sync();
            self.file = None;
            report = self.open(day)?;
        }
        self.line.clear();
        format_row(r, &mut self.line);
        let Some(f) = self.file.as_mut() else { return Ok(report) };
        if let Err(e) = f.file.write_all(self.line.as_bytes()) {
            // A partial line (disk full mid-write) must not stay in the middle of the file.
            let _ = f.file.set_len(f.len);
            self.file = None;
            return Err(e);
        }
        f.len += self.line.len() as u64;
        self.unsynced += 1;
        if self.fsync_ms == 0
            || r.unix_ms < self.last_sync_ms
            || r.unix_ms.saturating_sub(self.last_sync_ms) >= self.fsync_ms
        {
            self.last_sync_ms = r.unix_ms;
            self.sync()?;
        }
        Ok(report)
    }

    /// fsyncs the open file if rows were written since the last fsync.
    pub fn sync(&mut self) -> std::io::Result<()> {
        if let Some(f) = &self.file
            && self.unsynced > 0
        {
            f.file.sync_data()?;
            self.unsynced = 0;
        }
        Ok(())
    }

    /// fsyncs when rows wait and the fsync period has passed at wall time `now_ms` (the writer
    /// thread calls this when no row came for a while).
    pub fn sync_if_due(&mut self, now_ms: i64) -> std::io::Result<()> {
        if self.unsynced > 0
            && (now_ms < self.last_sync_ms || now_ms.saturating_sub(self.last_sync_ms) >= self.fsync_ms)
        {
            self.last_sync_ms = now_ms;
            self.sync()?;
        }
        Ok(())
    }

    fn open(&mut self, day: i64) -> std::io::Result<OpenReport> {
        std::fs::create_dir_all(&self.dir)?;
        let path = day_path(&self.dir, day);
        let existed = path.exists();
        let mut file = OpenOptions::new().read(true).append(true).create(true).open(&path)?;
        let len = file.metadata()?.len();
        let keep = complete_prefix(&file, len)?;
        let mut report = OpenReport { cut_bytes: len - keep, deleted: 0 };
        if keep < len {
            file.set_len(keep)?;
        }
        let mut len = keep;
        if len == 0 {
            file.write_all(format!("{HEADER}\n").as_bytes())?;
            len = HEADER.len() as u64 + 1;
            file.sync_data()?;
        }
        if !existed {
            // The new file's directory entry must survive a power cut too.
            File::open(&self.dir)?.sync_all()?;
        }
        self.file = Some(OpenDay { day, file, len });
        report.deleted = self.prune(day);
        Ok(report)
    }

    /// Deletes day files older than `keep_days` before `today` (only files named `YYYY-MM-DD.csv`);
    /// returns how many.
    pub fn prune(&self, today: i64) -> usize {
        let Ok(entries) = std::fs::read_dir(&self.dir) else { return 0 };
        let oldest_kept = today - i64::from(self.keep_days) + 1;
        let mut n = 0;
        for e in entries.flatten() {
            let name = e.file_name();
            let day = name.to_str().and_then(|n| n.strip_suffix(".csv")).and_then(parse_day);
            if day.is_some_and(|d| d < oldest_kept) && std::fs::remove_file(e.path()).is_ok() {
                n += 1;
            }
        }
        n
    }
}

/// Length of the part of a file of `len` bytes that ends with its last complete line: a tail torn
/// by a kill, or zero-filled by a power cut, is not part of it.
fn complete_prefix(file: &File, len: u64) -> std::io::Result<u64> {
    if len == 0 {
        return Ok(0);
    }
    let start = len.saturating_sub(64 * 1024);
    let mut tail = vec![0u8; (len - start) as usize];
    file.read_exact_at(&mut tail, start)?;
    let clean = tail.iter().position(|&b| b == 0).unwrap_or(tail.len());
    Ok(match tail[..clean].iter().rposition(|&b| b == b'\n') {
        Some(i) => start + i as u64 + 1,
        None if start == 0 => 0,
        None => start, // a line over 64 KiB: not ours; keep what precedes the inspected tail
    })
}

/// The publisher's end of the history queue. Sending never waits.
#[derive(Debug, Clone)]
pub struct HistorySender {
    tx: SyncSender<Row>,
    shared: Arc<Shared>,
}

impl HistorySender {
    /// Queues a row; a full queue drops it (counted as `history-dropped`).
    pub fn send(&self, row: Row) {
        match self.tx.try_send(row) {
            Ok(()) => {}
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.shared.history.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// Starts the history writer thread on `dir`. The thread ends when every [`HistorySender`] is
/// dropped, after writing what was queued and an fsync.
pub fn spawn(
    dir: PathBuf,
    keep_days: u32,
    fsync_s: f64,
    shared: Arc<Shared>,
) -> std::io::Result<(HistorySender, std::thread::JoinHandle<()>)> {
    let (tx, rx) = std::sync::mpsc::sync_channel(QUEUE_ROWS);
    shared.history.set_dir(&dir);
    let sh = shared.clone();
    let handle = std::thread::Builder::new()
        .name("fme-history".into())
        .spawn(move || writer_loop(DayWriter::new(&dir, keep_days, fsync_s), &rx, &sh))?;
    Ok((HistorySender { tx, shared }, handle))
}

/// Marks the history's write in flight (health `disk.history_since`, status bit 7 once it has
/// waited `service.disk_stall_s`) while `f` runs.
fn timed<R>(shared: &Shared, f: impl FnOnce() -> R) -> R {
    shared.with_health(|h| h.disk.history_since = Some(Instant::now()));
    let r = f();
    shared.with_health(|h| h.disk.history_since = None);
    r
}

/// The writer thread's state between rows: rows waiting for the disk and when to try it again.
struct Pending {
    rows: std::collections::VecDeque<Row>,
    retry_at: Option<Instant>,
    backoff: crate::backoff::Backoff,
    lost: u64,
}

fn writer_loop(mut w: DayWriter, rx: &Receiver<Row>, shared: &Shared) {
    let st: &HistoryStatus = &shared.history;
    let mut p = Pending {
        rows: std::collections::VecDeque::new(),
        retry_at: None,
        backoff: crate::backoff::Backoff::new(RETRY_MIN, RETRY_MAX),
        lost: 0,
    };
    loop {
        let wait = p.retry_at.map_or(Duration::from_millis(500), |t| {
            t.saturating_duration_since(Instant::now()).clamp(Duration::from_millis(1), Duration::from_millis(500))
        });
        match rx.recv_timeout(wait) {
            Ok(row) => {
                if p.retry_at.is_some() {
                    st.failed.fetch_add(1, Ordering::Relaxed);
                }
                if p.rows.len() >= PENDING_ROWS {
                    p.rows.pop_front();
                    p.lost += 1;
                }
                p.rows.push_back(row);
            }
            Err(RecvTimeoutError::Timeout) => {
                if p.retry_at.is_none() {
                    let _ = timed(shared, || w.sync_if_due(now_unix_ms()));
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if p.retry_at.is_none_or(|t| Instant::now() >= t) {
            drain(&mut w, &mut p, shared);
        }
    }
    // One last try for what waits (the final "stopped" row among it), then the final fsync.
    drain(&mut w, &mut p, shared);
    if let Err(e) = timed(shared, || w.sync()) {
        shared.log(Level::WARN, format!("history: final fsync of {}: {e}", w.dir.display()));
    }
}

/// Writes the waiting rows in order; on an error keeps them and schedules the next try.
fn drain(w: &mut DayWriter, p: &mut Pending, shared: &Shared) {
    let st: &HistoryStatus = &shared.history;
    while let Some(row) = p.rows.front().copied() {
        match timed(shared, || w.write(&row)) {
            Ok(rep) => {
                p.rows.pop_front();
                st.written.fetch_add(1, Ordering::Relaxed);
                if p.retry_at.take().is_some() {
                    p.backoff.reset();
                    st.paused.store(false, Ordering::Relaxed);
                    shared.with_health(|h| h.disk.history_fault = false);
                    shared.log(
                        Level::INFO,
                        format!(
                            "history: writing again to {} ({} held rows follow, {} lost)",
                            w.dir.display(),
                            p.rows.len(),
                            p.lost
                        ),
                    );
                    p.lost = 0;
                }
                report_open(w, &row, rep, shared);
            }
            Err(e) => {
                // Logged once per pause: a full disk must not also fill the journal.
                if p.retry_at.is_none() {
                    st.failed.fetch_add(p.rows.len() as u64, Ordering::Relaxed);
                    st.paused.store(true, Ordering::Relaxed);
                    shared.with_health(|h| h.disk.history_fault = true);
                    shared.log(
                        Level::ERROR,
                        format!(
                            "history: cannot write to {}: {e}; history paused (rows counted as history-failed, up to {PENDING_ROWS} held in memory), retrying with backoff up to {} s; the outputs are not affected",
                            w.dir.display(),
                            RETRY_MAX.as_secs()
                        ),
                    );
                }
                p.retry_at = Some(Instant::now() + p.backoff.next_delay());
                return;
            }
        }
    }
}

fn report_open(w: &DayWriter, row: &Row, rep: OpenReport, shared: &Shared) {
    if rep.cut_bytes > 0 {
        shared.log(
            Level::WARN,
            format!(
                "history: cut a torn last line ({} bytes) of {} (power cut or kill mid-write)",
                rep.cut_bytes,
                day_path(&w.dir, day_of(row.unix_ms)).display()
            ),
        );
    }
    if rep.deleted > 0 {
        shared.log(Level::INFO, format!("history: deleted {} day file(s) past history.keep_days", rep.deleted));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(unix_ms: i64, v: f64) -> Row {
        Row {
            unix_ms,
            activity_mps: v,
            smoothed_mps: v,
            ci95_mps: 0.01,
            n_fish: 12,
            bls: v / 0.3,
            status: 0x4b,
            fault: 0,
            feeding: v > 0.2,
            scale: ScaleSource::References,
            unlike_fish: false,
        }
    }

    #[test]
    fn day_names_parse_and_print() {
        assert_eq!(day_name(days_from_civil(2126, 12, 4)), "2126-12-04");
        assert_eq!(parse_day("2126-02-29"), None);
        assert_eq!(parse_day("2124-02-29"), Some(days_from_civil(2124, 2, 29)));
        assert_eq!(parse_day("2124-2-29"), None);
        assert_eq!(parse_day("2124-13-01"), None);
    }

    #[test]
    fn row_round_trip() {
        let t = days_from_civil(2126, 12, 4) * DAY_MS + 16 * 3_600_000 + 14 * 60_000 + 34_123;
        let mut s = String::new();
        format_time(t, &mut s);
        assert_eq!(s, "2126-12-04T16:14:34.123Z");
        assert_eq!(parse_time(&s), Some(t));
        let r = row(t, 0.25);
        let mut line = String::new();
        format_row(&r, &mut line);
        assert!(line.ends_with('\n'));
        let back = parse_row(line.trim_end()).expect("parses");
        assert_eq!((back.unix_ms, back.n_fish, back.status, back.feeding), (t, 12, 0x4b, true));
        assert!((back.activity_mps - 0.25).abs() < 1e-9);
        let nan = Row { activity_mps: f64::NAN, smoothed_mps: f64::NAN, bls: f64::NAN, ..r };
        line.clear();
        format_row(&nan, &mut line);
        assert!(parse_row(line.trim_end()).expect("parses").activity_mps.is_nan(), "{line}");
        assert!(parse_row("2126-12-04T16:14:34.123Z,0.1").is_err());
        assert!(parse_row("2126-12-04T16:14:34.123Z,x,,,1,,0,0,0").is_err());
        // The scale column: round trip, a bad name, and rows written before it (9 fields).
        for scale in [ScaleSource::References, ScaleSource::Fish, ScaleSource::None] {
            line.clear();
            format_row(&Row { scale, ..r }, &mut line);
            assert_eq!(parse_row(line.trim_end()).expect("parses").scale, scale, "{line}");
        }
        let e = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0,ruler").unwrap_err();
        assert!(e.starts_with("scale:"), "{e}");
        let old = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0").expect("a row without the scale column");
        assert_eq!(old.scale, ScaleSource::None);
        // The unlike_fish column: round trip, a bad value, and rows written before it (10 fields).
        for unlike_fish in [true, false] {
            line.clear();
            format_row(&Row { unlike_fish, ..r }, &mut line);
            assert!(line.trim_end().ends_with(if unlike_fish { ",1" } else { ",0" }), "{line}");
            assert_eq!(parse_row(line.trim_end()).expect("parses").unlike_fish, unlike_fish, "{line}");
        }
        let e = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0,fish,yes").unwrap_err();
        assert!(e.starts_with("unlike_fish:"), "{e}");
        let old = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0,fish").expect("a row without unlike_fish");
        assert!(!old.unlike_fish);
        assert_eq!(old.scale, ScaleSource::Fish);
    }

    #[test]
    fn day_files_from_before_the_unlike_fish_column_are_read() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("2126-11-03.csv");
        let rows = "2126-11-03T00:00:01.000Z,0.1,0.1,0.01,3,0.3,15,0,0,fish\n\
                    2126-11-03T00:00:02.000Z,0.1,0.1,0.01,3,0.3,1039,7,0,fish,1\n";
        std::fs::write(&p, format!("{HEADER_WITHOUT_UNLIKE_FISH}\n{rows}")).expect("write");
        let f = read_day_file(&p).expect("reads");
        assert_eq!(f.rows.len(), 2);
        assert!(!f.rows[0].unlike_fish, "an old row");
        assert!(f.rows[1].unlike_fish, "a new row continuing the old file");
    }

    #[test]
    fn day_files_from_before_the_scale_column_are_read() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("2126-11-02.csv");
        std::fs::write(&p, format!("{HEADER_WITHOUT_SCALE}\n2126-11-02T00:00:01.000Z,0.1,0.1,0.01,3,0.3,15,0,0\n"))
            .expect("write");
        let f = read_day_file(&p).expect("reads");
        assert_eq!(f.rows.len(), 1);
        assert_eq!(f.rows[0].scale, ScaleSource::None);
    }

    fn ms(y: i64, m: u32, d: u32, h: i64) -> i64 {
        days_from_civil(y, m, d) * DAY_MS + h * 3_600_000
    }

    #[test]
    fn day_rotation_and_keep_days() {
        let dir = tempfile::tempdir().expect("tempdir");
        // An old file and a foreign file: only the old day file is deleted.
        std::fs::write(dir.path().join("2126-11-01.csv"), format!("{HEADER}\n")).expect("write");
        std::fs::write(dir.path().join("notes.txt"), "keep me").expect("write");
        let mut w = DayWriter::new(dir.path(), 3, 10.0);
        for d in 1..=5u32 {
            for h in [0, 12, 23] {
                w.write(&row(ms(2126, 12, d, h), 0.1)).expect("write");
            }
        }
        w.sync().expect("sync");
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .expect("ls")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["2126-12-03.csv", "2126-12-04.csv", "2126-12-05.csv", "notes.txt"]);
        let f = read_day_file(&dir.path().join("2126-12-04.csv")).expect("read");
        assert_eq!(f.rows.len(), 3);
        assert!(!f.torn_last_line);
        assert!(f.rows.iter().all(|r| day_of(r.unix_ms) == days_from_civil(2126, 12, 4)));
        // Reopening the same day appends (a restart), and the header is written once.
        let mut w = DayWriter::new(dir.path(), 3, 0.0);
        w.write(&row(ms(2126, 12, 5, 23) + 1000, 0.3)).expect("write");
        let text = std::fs::read_to_string(dir.path().join("2126-12-05.csv")).expect("read");
        assert_eq!(text.matches("time_utc").count(), 1);
        assert_eq!(text.lines().count(), 5);
    }

    #[test]
    fn torn_tail_is_skipped_by_the_reader_and_cut_by_the_writer() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = day_path(dir.path(), days_from_civil(2126, 12, 4));
        let mut text = format!("{HEADER}\n");
        format_row(&row(ms(2126, 12, 4, 1), 0.1), &mut text);
        text.push_str("2126-12-04T02:00:00.000Z,0.1");
        std::fs::write(&p, &text).expect("write");
        let f = read_day_file(&p).expect("a torn last line is not an error");
        assert_eq!((f.rows.len(), f.torn_last_line), (1, true));
        // A zero-filled tail (power cut) too.
        let mut bytes = text.clone().into_bytes();
        bytes.extend_from_slice(&[0u8; 100]);
        std::fs::write(&p, &bytes).expect("write");
        assert_eq!(read_day_file(&p).expect("read").rows.len(), 1);
        let mut w = DayWriter::new(dir.path(), 30, 0.0);
        let rep = w.write(&row(ms(2126, 12, 4, 3), 0.2)).expect("write");
        assert!(rep.cut_bytes > 100, "{rep:?}");
        let f = read_day_file(&p).expect("read");
        assert_eq!((f.rows.len(), f.torn_last_line), (2, false));
        // A bad line in the middle is an error naming the file and line.
        std::fs::write(&p, format!("{HEADER}\nnonsense\n")).expect("write");
        let e = read_day_file(&p).expect_err("bad line").to_string();
        assert!(e.contains("2126-12-04.csv:2:"), "{e}");
    }

    #[test]
    fn disk_full_is_an_error_and_leaves_no_partial_line() {
        let dir = tempfile::tempdir().expect("tempdir");
        let day = days_from_civil(2126, 12, 4);
        if !Path::new("/dev/full").exists() {
            return;
        }
        std::os::unix::fs::symlink("/dev/full", day_path(dir.path(), day)).expect("symlink");
        let mut w = DayWriter::new(dir.path(), 30, 0.0);
        let e = w.write(&row(ms(2126, 12, 4, 1), 0.1)).expect_err("disk full");
        assert_eq!(e.raw_os_error(), Some(libc::ENOSPC), "{e}");
    }

    #[test]
    fn hourly_summary() {
        let base = ms(2126, 12, 4, 10);
        let mut rows = Vec::new();
        for s in 0..7200 {
            // Hour 10: 0.1 m/s, no feeding; hour 11: 0.1..0.3 m/s, feeding for the last 30 min.
            let v = if s < 3600 { 0.1 } else { 0.1 + 0.2 * f64::from(s - 3600) / 3599.0 };
            let mut r = row(base + i64::from(s) * 1000, v);
            r.feeding = s >= 5400;
            r.fault = u16::from(s < 10);
            rows.push(r);
        }
        let h = summarize_hours(&rows, base - 3_600_000, 3);
        assert_eq!(h[0].rows, 0);
        assert!(h[0].mean_mps.is_nan());
        assert_eq!((h[1].rows, h[1].fault_rows), (3600, 10));
        assert!((h[1].mean_mps - 0.1).abs() < 1e-9 && h[1].feeding_s == 0.0);
        assert!((h[2].min_mps - 0.1).abs() < 1e-9 && (h[2].max_mps - 0.3).abs() < 1e-9);
        assert!((h[2].mean_mps - 0.2).abs() < 1e-6);
        assert!((h[2].feeding_s - 1799.0).abs() < 1e-9, "{}", h[2].feeding_s);
        let text = format_summary(&h, 0);
        assert_eq!(text.lines().count(), 3, "the header and the two hours with rows: {text}");
        assert!(text.lines().nth(2).is_some_and(|l| l.starts_with("2126-12-04 11:00") && l.contains("30.0")), "{text}");
    }

    #[test]
    fn start_up_and_clean_stop_rows_are_not_fault_rows() {
        let base = ms(2126, 12, 4, 10);
        let codes = [0u16, 0, 1, 4, 0, 6, 7];
        let rows: Vec<Row> =
            codes.iter().enumerate().map(|(i, &c)| Row { fault: c, ..row(base + i as i64 * 1000, 0.1) }).collect();
        assert_eq!(summarize_hours(&rows, base, 1)[0].fault_rows, 3, "1, 4 and 7; not 6 (stopped)");
    }

    #[test]
    fn a_new_box_has_no_history_yet() {
        let dir = tempfile::tempdir().expect("tempdir");
        let text = hourly_report(dir.path(), ms(2126, 12, 4, 10), 24).expect("an empty directory reads");
        assert!(text.starts_with("no history yet"), "{text}");
        assert_eq!(text.lines().count(), 1, "{text}");
        let mut w = DayWriter::new(dir.path(), 30, 0.0);
        w.write(&row(ms(2126, 12, 4, 9) + 5000, 0.1)).expect("write");
        let text = hourly_report(dir.path(), ms(2126, 12, 4, 10), 24).expect("read");
        assert_eq!(text.lines().count(), 2, "the header and the one hour with a row: {text}");
        assert!(text.lines().nth(1).is_some_and(|l| l.starts_with("2126-12-04 09:00")), "{text}");
    }
}
