//! The history writer: [`DayWriter`] (rotation, retention, fsync policy, torn-tail repair) and the
//! `fme-history` thread that feeds it from the publisher without ever making it wait.

use super::{
    HEADER, HistoryRow, PENDING_ROWS, QUEUE_ROWS, RETRY_MAX, RETRY_MIN, day_of, day_path, format_row, now_unix_ms,
    parse_day,
};
use crate::status::{HistoryStatus, Shared};
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::os::unix::fs::FileExt as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::{Duration, Instant};
use tracing::Level;

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
    pub fn write(&mut self, r: &HistoryRow) -> std::io::Result<OpenReport> {
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
    tx: SyncSender<HistoryRow>,
    shared: Arc<Shared>,
}

impl HistorySender {
    /// Queues a row; a full queue drops it (counted as `history-dropped`).
    pub fn send(&self, row: HistoryRow) {
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
    rows: std::collections::VecDeque<HistoryRow>,
    retry_at: Option<Instant>,
    backoff: crate::backoff::Backoff,
    lost: u64,
}

fn writer_loop(mut w: DayWriter, rx: &Receiver<HistoryRow>, shared: &Shared) {
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

fn report_open(w: &DayWriter, row: &HistoryRow, rep: OpenReport, shared: &Shared) {
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
