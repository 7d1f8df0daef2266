//! The activity history (`docs/history.md`): rows survive a SIGKILL of `fme run` with every
//! complete row readable; an unwritable history directory pauses the history (logged once,
//! counted) while the registers keep updating; `fme report` summarises and plots a day and names
//! the file and line of bad input.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::history::{self, DayWriter, HistoryRow};
use fme::service::{Daemon, RunOptions};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn fme() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fme"));
    c.env_remove("NOTIFY_SOCKET").env_remove("WATCHDOG_USEC").env_remove("STATE_DIRECTORY");
    c
}

/// Complete lines (header included) in the day files of `dir`.
fn complete_lines(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    entries
        .flatten()
        .filter_map(|e| std::fs::read(e.path()).ok())
        .map(|b| b.iter().filter(|&&c| c == b'\n').count())
        .sum()
}

#[test]
fn history_rows_survive_sigkill_and_every_complete_row_reads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hist = dir.path().join("history");
    let mut child = fme()
        .args(["run", "--source", "tests/data/swarm20", "--set"])
        .arg(format!("history.dir={:?}", hist.to_string_lossy()))
        .args(["--set", "output.rate_hz=50", "--set", "output.modbus.mode=\"off\"", "--set", "history.fsync_s=0.1"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn fme run");
    // Wait for rows (start-up loads the models), then kill -9 while rows are being written.
    let deadline = Instant::now() + Duration::from_secs(60);
    while complete_lines(&hist) < 60 && Instant::now() < deadline && child.try_wait().ok().flatten().is_none() {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().expect("SIGKILL");
    let status = child.wait().expect("wait");
    assert_eq!(std::os::unix::process::ExitStatusExt::signal(&status), Some(9), "killed, not exited: {status:?}");
    let mut rows: Vec<HistoryRow> = Vec::new();
    let mut files = 0;
    for e in std::fs::read_dir(&hist).expect("history dir").flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        assert!(name.strip_suffix(".csv").and_then(history::parse_day).is_some(), "only day files: {name}");
        // Every complete line must parse; only a torn last line may be skipped.
        let f = history::read_day_file(&e.path()).unwrap_or_else(|err| panic!("{err}"));
        rows.extend(f.rows);
        files += 1;
    }
    assert!((1..=2).contains(&files), "{files} day files");
    assert!(rows.len() >= 59, "at least 59 rows, got {}", rows.len());
    assert!(rows.windows(2).all(|w| w[1].unix_ms >= w[0].unix_ms), "rows in time order");
    assert!(rows.iter().any(|r| r.activity_mps.is_finite() && r.n_fish > 0), "activity values recorded");
    assert!(rows.iter().all(|r| r.fault != 6), "killed: no clean-stop row");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unwritable_history_dir_pauses_history_and_registers_keep_updating() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 40, 160, 96, 30);
    // A directory below a regular file cannot be created, even by root (who may write into a
    // read-only directory): the write error a read-only or full disk gives.
    let blocker = dir.path().join("not-a-dir");
    std::fs::write(&blocker, "x").expect("write");
    let mut cfg = support::test_config(&dir.path().join("seq"));
    cfg.history.dir = blocker.join("history");
    let source: Box<dyn FrameSource> =
        Box::new(RecordedSource::open(&dir.path().join("seq"), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let hb0 = daemon.bank().block()[12];
    let deadline = Instant::now() + Duration::from_secs(20);
    let failed = || shared.history.failed.load(std::sync::atomic::Ordering::Relaxed);
    while (failed() < 10 || daemon.bank().block()[12].wrapping_sub(hb0) < 10) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let hb1 = daemon.bank().block()[12];
    assert!(failed() >= 10, "rows counted as failed: {}", failed());
    assert!(hb1.wrapping_sub(hb0) >= 10, "registers keep updating: heartbeat {hb0} -> {hb1}");
    assert!(shared.history.paused.load(std::sync::atomic::Ordering::Relaxed));
    assert_eq!(shared.history.written.load(std::sync::atomic::Ordering::Relaxed), 0);
    let logs = shared.last_logs(200);
    assert_eq!(logs.iter().filter(|l| l.contains("history: cannot write")).count(), 1, "logged once: {logs:?}");
    let mut out = String::new();
    fme::console::Session::default().command("counters", &shared, daemon.bank(), &mut out);
    let shown = out.lines().find_map(|l| l.strip_prefix("history-failed ")).and_then(|n| n.trim().parse::<u64>().ok());
    assert!(shown.is_some_and(|n| n >= 10), "console counters: {out}");
    let mut out = String::new();
    fme::console::Session::default().command("status", &shared, daemon.bank(), &mut out);
    assert!(out.contains("history paused"), "{out}");
    daemon.shutdown().await;
}

/// A clean start and an orderly stop are no faults, and the history summary (console `history`,
/// `fme report`), the console and the MQTT events agree on it: one definition.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clean_start_and_stop_are_no_faults_anywhere() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(&dir.path().join("seq"), 40, 160, 96, 30);
    let mut cfg = support::test_config(&dir.path().join("seq"));
    let hist = dir.path().join("history");
    cfg.history.dir = hist.clone();
    cfg.history.fsync_s = 0.0;
    let source: Box<dyn FrameSource> =
        Box::new(RecordedSource::open(&dir.path().join("seq"), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let bank = daemon.bank().clone();
    let deadline = Instant::now() + Duration::from_secs(20);
    while shared.history.written.load(std::sync::atomic::Ordering::Relaxed) < 5 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    daemon.shutdown().await;
    let mut rows: Vec<HistoryRow> = Vec::new();
    for e in std::fs::read_dir(&hist).expect("history dir").flatten() {
        rows.extend(history::read_day_file(&e.path()).unwrap_or_else(|err| panic!("{err}")).rows);
    }
    rows.sort_by_key(|r| r.unix_ms);
    assert!(rows.len() >= 6, "{} rows", rows.len());
    assert_eq!(rows[0].fault, 0, "the first block, before the camera's first frame, is no camera fault");
    let last = rows[rows.len() - 1];
    assert_eq!(last.fault, 6, "the clean stop is the last row (fault code 6, stopped)");
    assert_eq!(last.status & fme::output::StatusBits::RUNNING.bits(), 0);
    let codes: Vec<u16> = rows.iter().map(|r| r.fault).collect();
    assert!(rows.iter().all(|r| !fme::status::is_fault_code(r.fault)), "no fault: {codes:?}");
    // The history summary (console `history`, `fme report`): no fault rows.
    let first_hour = rows[0].unix_ms.div_euclid(3_600_000) * 3_600_000;
    let hours = history::summarize_hours(&rows, first_hour, 2);
    assert_eq!(hours.iter().map(|h| h.fault_rows).sum::<u32>(), 0, "{hours:?}");
    // MQTT: no fault event.
    let mut events = fme::output::mqtt::EventTracker::default();
    for r in &rows {
        let u = fme::output::Update {
            status: fme::output::StatusBits::from_word(r.status),
            fault: fme::status::FaultCode::from_code(r.fault).expect("a code this version writes"),
            feeding: r.feeding,
            scale: r.scale,
            ..Default::default()
        };
        let ev = events.update(&u);
        assert!(
            !ev.iter().any(|e| matches!(
                e,
                fme::output::mqtt::EventKind::FaultRaised(_) | fme::output::mqtt::EventKind::FaultCleared(_)
            )),
            "{ev:?} at fault {}",
            r.fault
        );
    }
    // The console: the stopped block names no fault.
    assert!(!fme::console::activity_line(&shared, &bank).contains(" fault "));
    let mut out = String::new();
    fme::console::Session::default().command("status", &shared, &bank, &mut out);
    assert!(out.contains("fault 6 (stopped, not a fault)"), "{out}");
}

fn day_ms(day: &str) -> i64 {
    history::parse_day(day).expect("day") * 86_400_000
}

/// A day of rows every 10 s: activity 0.1-0.3 m/s, feeding 12:00-13:00, a camera fault at 03:00.
fn write_day(dir: &Path, day: &str) {
    let mut w = DayWriter::new(dir, 3650, 3600.0);
    let t0 = day_ms(day);
    for i in 0..8640i64 {
        let h = i as f64 / 360.0;
        let fault = u16::from((3.0..3.2).contains(&h));
        w.write(&HistoryRow {
            unix_ms: t0 + i * 10_000,
            activity_mps: if fault == 0 { 0.2 + 0.1 * (h / 24.0 * std::f64::consts::TAU).sin() } else { f64::NAN },
            smoothed_mps: 0.2,
            ci95_mps: 0.02,
            n_fish: 15 + (i % 5) as u32,
            bls: 0.6,
            status: 15,
            fault,
            feeding: (12.0..13.0).contains(&h),
            scale: fme::pipeline::ScaleSource::Fish,
            unlike_fish: false,
        })
        .expect("write");
    }
    w.sync().expect("sync");
}

#[test]
fn report_summarises_and_plots_a_day() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_day(dir.path(), "2026-12-04");
    let png = dir.path().join("day.png");
    let out = fme()
        .args(["report", "--history"])
        .arg(dir.path())
        .args(["--day", "2026-12-04", "--plot"])
        .arg(&png)
        .output()
        .expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("8640 rows"), "{text}");
    let hour12 = text.lines().find(|l| l.starts_with("2026-12-04 12:00")).expect("hour 12");
    assert!(hour12.contains(" 60.0 "), "feeding minutes: {hour12}");
    let hour3 = text.lines().find(|l| l.starts_with("2026-12-04 03:00")).expect("hour 3");
    assert!(hour3.trim_end().ends_with(" 72"), "fault rows: {hour3}");
    assert_eq!(image::image_dimensions(&png).expect("a PNG"), fme::history::plot::SIZE);
}

#[test]
fn report_bad_input_exits_2_naming_the_file_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run =
        |day: &str| fme().args(["report", "--history"]).arg(dir.path()).args(["--day", day]).output().expect("run");
    let out = run("2026-12-04");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("2026-12-04.csv"), "missing file named");
    let out = run("2026-13-04");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--day"));
    let mut text = format!("{}\n", history::HEADER);
    for i in 0..3 {
        history::format_row(
            &HistoryRow {
                unix_ms: day_ms("2026-12-04") + i * 1000,
                activity_mps: 0.1,
                smoothed_mps: 0.1,
                ci95_mps: 0.01,
                n_fish: 3,
                bls: 0.3,
                status: 15,
                fault: 0,
                feeding: false,
                scale: fme::pipeline::ScaleSource::References,
                unlike_fish: false,
            },
            &mut text,
        );
    }
    // A torn last line is skipped; a bad line before it is an error at its line.
    std::fs::write(dir.path().join("2026-12-04.csv"), format!("{text}2026-12-04T00:00:09.000Z,0.1,0.")).expect("write");
    let out = run("2026-12-04");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("1 torn last line"));
    std::fs::write(dir.path().join("2026-12-04.csv"), format!("{text}garbage,1\n{text}")).expect("write");
    let out = run("2026-12-04");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("2026-12-04.csv:5:"), "{err}");
}
