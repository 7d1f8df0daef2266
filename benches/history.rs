//! Benchmark (not a test): cost of the activity history per output update (`docs/history.md`): the
//! publisher's non-blocking send, the writer's formatting + one whole-line append, with fsync every
//! row and at the default `history.fsync_s`, and the bytes per row and per day at 1 Hz.
//! `cargo bench --bench history [DIR]` (or `make bench-history`); DIR (default: a temporary
//! directory) should be on the disk the box writes to.

use fme::history::{DayWriter, HistoryRow, format_row};
use std::hint::black_box;
use std::time::Instant;

fn row(i: i64) -> HistoryRow {
    let v = 0.2 + 0.1 * ((i as f64) * 0.01).sin();
    HistoryRow {
        unix_ms: 1_796_400_000_000 + i * 1000, // 1 Hz rows on 2026-12-04
        activity_mps: v,
        smoothed_mps: v * 0.95,
        ci95_mps: 0.021,
        n_fish: 17,
        bls: v / 0.35,
        status: 15,
        fault: 0,
        feeding: v > 0.25,
        scale: fme::pipeline::ScaleSource::Fish,
        unlike_fish: false,
    }
}

fn writer(dir: &std::path::Path, label: &str, fsync_s: f64, n: i64) {
    let sub = dir.join(label);
    let mut w = DayWriter::new(&sub, 90, fsync_s);
    w.write(&row(0)).expect("write"); // open the file outside the timing
    let t0 = Instant::now();
    for i in 1..=n {
        w.write(&row(i)).expect("write");
    }
    let us = t0.elapsed().as_secs_f64() * 1e6 / n as f64;
    w.sync().expect("sync");
    println!("writer thread, fsync_s = {fsync_s:>4}: {us:8.2} us/row ({n} rows)");
    let _ = std::fs::remove_dir_all(&sub);
}

fn main() {
    let arg = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = arg.map_or_else(|| tmp.path().to_path_buf(), std::path::PathBuf::from);
    println!("history on {}", dir.display());

    let n = 200_000i64;
    let mut line = String::with_capacity(160);
    let mut bytes = 0usize;
    let t0 = Instant::now();
    for i in 0..n {
        line.clear();
        format_row(black_box(&row(i)), &mut line);
        bytes += line.len();
    }
    let ns = t0.elapsed().as_secs_f64() * 1e9 / n as f64;
    let per_row = bytes as f64 / n as f64;
    println!("format: {ns:.0} ns/row, {per_row:.1} bytes/row");
    println!(
        "disk at output.rate_hz = 1: {:.2} MB/day, {:.1} MB/hour, {:.0} MB for keep_days = 90",
        per_row * 86_400.0 / 1e6,
        per_row * 3_600.0 / 1e6,
        per_row * 86_400.0 * 90.0 / 1e6
    );

    // The publisher's side: a try_send into the bounded queue, drained by the writer thread.
    let shared = std::sync::Arc::new(fme::status::Shared::new(String::new(), 10));
    let (tx, handle) = fme::history::spawn(dir.join("send"), 90, 10.0, shared.clone()).expect("spawn");
    // Batches smaller than the queue, each drained before the next: the queue has room, as at 1-100 Hz.
    let (batches, batch) = (100i64, 128i64);
    let mut sending = std::time::Duration::ZERO;
    for b in 0..batches {
        let t0 = Instant::now();
        for i in 0..batch {
            tx.send(row(b * batch + i));
        }
        sending += t0.elapsed();
        let want = ((b + 1) * batch) as u64;
        while shared.history.written.load(std::sync::atomic::Ordering::Relaxed) < want {
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    }
    let ns = sending.as_secs_f64() * 1e9 / (batches * batch) as f64;
    drop(tx);
    let _ = handle.join();
    let dropped = shared.history.dropped.load(std::sync::atomic::Ordering::Relaxed);
    println!("publisher send (try_send, the pipeline's cost): {ns:.0} ns/row ({dropped} dropped)");
    let _ = std::fs::remove_dir_all(dir.join("send"));

    writer(&dir, "fsync10", 10.0, 100_000);
    writer(&dir, "fsync0", 0.0, 2_000);
}
