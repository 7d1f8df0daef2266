//! A small, full or stalled disk under the state directory (docs/recording.md, docs/history.md):
//! a freeze that fails or was killed leaves no `.partial-*`, the ring on a 3 MB disk keeps its
//! reserve and keeps recording, the history resumes within seconds of space coming back, and a
//! stalled write raises status bit 7 without holding the registers or the shutdown.
//! The disk-full cases mount a tmpfs of a few MB (root); where that is not permitted they say so
//! and pass without checking anything.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::output::registers::StatusBits;
use fme::record::freeze::{self, FreezeInputs};
use fme::record::ring::{Ring, RingEntry, fs_space};
use fme::service::{Daemon, RunOptions};
use fme::status::Shared;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A tmpfs of `mb` MB on a temporary directory, unmounted when dropped.
struct Tmpfs {
    dir: tempfile::TempDir,
}

impl Tmpfs {
    /// `None`, with the reason printed, where mounting is not permitted (not root).
    fn mount(mb: u32) -> Option<Self> {
        use std::os::unix::ffi::OsStrExt as _;
        let dir = tempfile::tempdir().expect("tempdir");
        let target = std::ffi::CString::new(dir.path().as_os_str().as_bytes()).expect("path");
        let opts = std::ffi::CString::new(format!("size={mb}m")).expect("options");
        // SAFETY: NUL-terminated strings that outlive the call.
        let rc = unsafe { libc::mount(c"tmpfs".as_ptr(), target.as_ptr(), c"tmpfs".as_ptr(), 0, opts.as_ptr().cast()) };
        if rc != 0 {
            eprintln!(
                "SKIPPED: cannot mount a {mb} MB tmpfs on {} ({}): this disk-full test needs root",
                dir.path().display(),
                std::io::Error::last_os_error()
            );
            return None;
        }
        Some(Self { dir })
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        use std::os::unix::ffi::OsStrExt as _;
        if let Ok(p) = std::ffi::CString::new(self.dir.path().as_os_str().as_bytes()) {
            // SAFETY: a NUL-terminated path. Lazy: a thread still writing there does not keep it.
            unsafe { libc::umount2(p.as_ptr(), libc::MNT_DETACH) };
        }
    }
}

/// Fills the file system of `dir` with `dir/filler` until it refuses more; returns the file.
fn fill(dir: &Path) -> PathBuf {
    let p = dir.join("filler");
    let mut f = std::fs::File::create(&p).expect("create filler");
    let page = [0x5au8; 4096];
    while f.write_all(&page).is_ok() {}
    let _ = f.write_all(&[0]);
    p
}

fn partials(recordings: &Path) -> Vec<String> {
    let Ok(rd) = std::fs::read_dir(recordings) else { return Vec::new() };
    rd.flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(freeze::PARTIAL_PREFIX))
        .collect()
}

fn entry(seq: u64) -> RingEntry {
    RingEntry { seq, t: seq as f64 / 30.0, size: (64, 48), bytes: 0, overlays: Default::default(), sample: None }
}

/// A freeze that fails for want of space removes its staged folder: its hard links would pin the
/// ring's frames on the full disk.
#[test]
fn a_freeze_that_fails_on_a_full_disk_leaves_no_partial() {
    let Some(fs) = Tmpfs::mount(3) else { return };
    let mut ring = Ring::open(&fs.path().join("ring"), 60.0, 1 << 30).expect("open ring");
    for seq in 1..=20 {
        ring.push(entry(seq), &[0xab; 3000]).expect("push");
    }
    let recordings = fs.path().join("recordings");
    std::fs::create_dir_all(&recordings).expect("recordings");
    fill(fs.path());
    let inputs = FreezeInputs { calibration: None, config_text: "# config\n".repeat(10_000) };
    let e =
        freeze::freeze(&ring, &recordings, "20260101T000000Z", "alarm-high", &inputs).expect_err("the disk is full");
    assert!(e.contains("No space left"), "{e}");
    assert_eq!(partials(&recordings), Vec::<String>::new(), "a failed freeze cleans up after itself");
}

/// A freeze killed midway (SIGKILL, power cut) leaves a staged folder of hard links into the ring;
/// the next start removes it and keeps the finished recordings. (The leftover is made by hand as
/// the killed freeze leaves it: a kill cannot be timed into the middle of a freeze.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_freeze_killed_midway_leaves_no_partial_after_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 20, 160, 96, 30);
    let state = dir.path().join("state");
    let recordings = state.join("recordings");
    let staged = recordings.join(".partial-20260101T000000Z-fault-camera");
    std::fs::create_dir_all(staged.join("img1")).expect("staged");
    std::fs::create_dir_all(state.join("ring")).expect("ring");
    let frame = state.join("ring/000000000001.jpg");
    std::fs::write(&frame, [0xab; 3000]).expect("frame");
    std::fs::hard_link(&frame, staged.join("img1/000001.jpg")).expect("link");
    let kept = recordings.join("20251231T000000Z-manual");
    std::fs::create_dir_all(&kept).expect("a finished recording");
    let mut cfg = support::test_config(&dir.path().join("seq"));
    cfg.service.state_dir = state.clone();
    let source: Box<dyn FrameSource> =
        Box::new(RecordedSource::open(&dir.path().join("seq"), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let deadline = Instant::now() + Duration::from_secs(10);
    // The folder goes first, the log line right after it: wait for both.
    let logged = |d: &Daemon| d.shared().last_logs(50).iter().any(|l| l.contains("unfinished recording"));
    while !(partials(&recordings).is_empty() && logged(&daemon)) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let left = partials(&recordings);
    let logs = daemon.shared().last_logs(50);
    daemon.shutdown().await;
    assert_eq!(left, Vec::<String>::new(), "stale .partial-* removed at start-up: {logs:?}");
    assert!(kept.is_dir(), "finished recordings are kept");
    assert!(logs.iter().any(|l| l.contains("unfinished recording")), "{logs:?}");
}

/// The default ring (500 MB) on a 3 MB state directory: it stays within the free space less the
/// reserve (a quarter of this small disk), frames keep flowing, the history keeps writing, and
/// there is no disk fault.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_ring_on_a_3_mb_disk_keeps_its_reserve_and_keeps_recording() {
    let Some(fs) = Tmpfs::mount(3) else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 40, 320, 240, 30);
    let mut cfg = support::test_config(&dir.path().join("seq"));
    cfg.service.state_dir = fs.path().to_path_buf();
    let reserve = (cfg.record.reserve_mb * 1_000_000).min(fs_space(fs.path()).expect("statvfs").total / 4);
    // As fast as the pipeline goes: the ring meets the end of the disk within a second or two.
    let source: Box<dyn FrameSource> =
        Box::new(RecordedSource::open(&dir.path().join("seq"), false, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let free = || fs_space(fs.path()).map_or(0, |s| s.free);
    // Until the ring is bounded by the disk (it would hold 1800 frames of ring_s = 60 s otherwise).
    let deadline = Instant::now() + Duration::from_secs(30);
    while free() > reserve + 64 * 1024 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let filled = free();
    let (written0, hist0) = (shared.health().record.frames_written, shared.history.written.load(Ordering::Relaxed));
    let (mut min_free, mut bits) = (u64::MAX, 0u16);
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        min_free = min_free.min(free());
        bits |= daemon.bank().block()[10];
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let h = shared.health();
    let hist1 = shared.history.written.load(Ordering::Relaxed);
    daemon.shutdown().await;
    eprintln!(
        "3 MB disk: reserve {reserve} B, free when full {filled} B, least free {min_free} B, ring {} frames {} B, \
         frames written +{} in 3 s, dropped {}, write errors {}, history rows +{}",
        h.record.ring_frames,
        h.record.ring_bytes,
        h.record.frames_written - written0,
        h.record.frames_dropped,
        h.record.write_errors,
        hist1 - hist0
    );
    assert!(filled <= reserve + 64 * 1024, "the ring grew to the reserve: {filled} B free");
    // One frame (two 4 kB pages here) and the history's rows may be written before the ring sheds.
    assert!(min_free + 16 * 1024 >= reserve, "the ring took the reserve: {min_free} B free, reserve {reserve} B");
    assert!(
        h.record.frames_written > written0 + 30,
        "frames keep flowing: {} -> {}",
        written0,
        h.record.frames_written
    );
    assert!(!h.record.disk_fault && h.record.write_errors == 0, "no pause: {:?}", h.record);
    assert_eq!(bits & StatusBits::RECORD_FAULT.bits(), 0, "status bit 7 stays clear: {bits:#06x}");
    assert!(hist1 > hist0, "the history keeps writing: {hist0} -> {hist1}");
}

fn row(unix_ms: i64) -> fme::history::HistoryRow {
    fme::history::HistoryRow {
        unix_ms,
        activity_mps: 0.2,
        smoothed_mps: 0.2,
        ci95_mps: 0.01,
        n_fish: 10,
        bls: 0.7,
        status: 0x4b,
        fault: 0,
        feeding: false,
        scale: fme::pipeline::ScaleSource::References,
        unlike_fish: false,
    }
}

/// The history on a full disk holds its rows in memory and, once space is freed, writes again
/// within seconds, with the rows of the pause.
#[test]
fn the_history_resumes_within_seconds_of_space_freed() {
    let Some(fs) = Tmpfs::mount(3) else { return };
    let dir = fs.path().join("history");
    let shared = Arc::new(Shared::new(String::new(), 50));
    let filler = fill(fs.path());
    let (tx, thread) = fme::history::spawn(dir.clone(), 90, 0.0, shared.clone()).expect("spawn");
    let st = &shared.history;
    let mut sent = 0u64;
    let send = |sent: &mut u64| {
        tx.send(row(fme::history::now_unix_ms()));
        *sent += 1;
        std::thread::sleep(Duration::from_millis(50));
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    while !(st.paused.load(Ordering::Relaxed) && shared.health().disk.history_fault) && Instant::now() < deadline {
        send(&mut sent);
    }
    assert!(st.paused.load(Ordering::Relaxed), "a full disk pauses the history");
    // Long enough for a fixed or fully backed-off retry delay to be the thing measured.
    for _ in 0..40 {
        send(&mut sent);
    }
    assert_eq!(st.written.load(Ordering::Relaxed), 0);
    std::fs::remove_file(&filler).expect("free the space");
    let freed = Instant::now();
    let deadline = freed + Duration::from_secs(15);
    while st.written.load(Ordering::Relaxed) == 0 && Instant::now() < deadline {
        send(&mut sent);
    }
    let resumed = freed.elapsed();
    send(&mut sent);
    drop(tx);
    thread.join().expect("history thread");
    let rows: usize = std::fs::read_dir(&dir)
        .expect("history dir")
        .flatten()
        .map(|e| fme::history::read_day_file(&e.path()).expect("day file").rows.len())
        .sum();
    eprintln!(
        "history: resumed {} ms after space was freed; {rows} of {sent} rows in the day files; failed {}",
        resumed.as_millis(),
        st.failed.load(Ordering::Relaxed)
    );
    assert!(resumed <= Duration::from_secs(5), "writing again {} ms after space came back", resumed.as_millis());
    assert_eq!(rows as u64, sent, "the rows of the pause were held and written");
    assert!(!st.paused.load(Ordering::Relaxed) && !shared.health().disk.history_fault);
}

static STALLED: AtomicBool = AtomicBool::new(false);

/// A ring writer that blocks while [`STALLED`] is set (a frozen file system), at most a minute.
fn stalling_write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let t = Instant::now();
    while STALLED.load(Ordering::SeqCst) && t.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
    fme::record::ring::write_file(path, bytes)
}

/// Thaws the disk even when an assertion fails.
struct Thaw;

impl Drop for Thaw {
    fn drop(&mut self) {
        STALLED.store(false, Ordering::SeqCst);
    }
}

/// A ring write that does not return (a frozen disk): status bit 7 rises within 5 s while the
/// registers keep updating, and the shutdown does not wait for the write.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_write_raises_bit_7_and_shutdown_does_not_wait_for_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 40, 160, 96, 30);
    let mut cfg = support::test_config(&dir.path().join("seq"));
    cfg.service.state_dir = dir.path().join("state");
    let source: Box<dyn FrameSource> =
        Box::new(RecordedSource::open(&dir.path().join("seq"), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let opts = RunOptions { ring_writer: Some(stalling_write), ..RunOptions::default() };
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, opts).await.expect("start");
    let shared = daemon.shared().clone();
    let deadline = Instant::now() + Duration::from_secs(20);
    while shared.health().record.frames_written < 10 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(shared.health().record.frames_written >= 10, "the ring writes before the stall");
    assert_eq!(daemon.bank().block()[10] & StatusBits::RECORD_FAULT.bits(), 0, "bit 7 clear on a working disk");
    let _thaw = Thaw;
    STALLED.store(true, Ordering::SeqCst);
    let (stalled, hb0) = (Instant::now(), daemon.bank().block()[12]);
    while daemon.bank().block()[10] & StatusBits::RECORD_FAULT.bits() == 0
        && stalled.elapsed() < Duration::from_secs(10)
    {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let rise = stalled.elapsed();
    let block = daemon.bank().block();
    let t = Instant::now();
    let done = tokio::time::timeout(Duration::from_secs(10), daemon.shutdown()).await;
    let stop = t.elapsed();
    eprintln!("stalled write: bit 7 after {} ms, shutdown in {} ms", rise.as_millis(), stop.as_millis());
    assert_ne!(block[10] & StatusBits::RECORD_FAULT.bits(), 0, "status bit 7 within 10 s: {:#06x}", block[10]);
    assert!(rise <= Duration::from_secs(5), "bit 7 after {} ms", rise.as_millis());
    assert!(block[12].wrapping_sub(hb0) >= 10, "registers keep updating: heartbeat {hb0} -> {}", block[12]);
    assert!(done.is_ok() && stop <= Duration::from_secs(3), "shutdown with a write stuck took {} ms", stop.as_millis());
}
