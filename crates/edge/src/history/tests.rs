use super::*;

fn row(unix_ms: i64, v: f64) -> HistoryRow {
    HistoryRow {
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
    let nan = HistoryRow { activity_mps: f64::NAN, smoothed_mps: f64::NAN, bls: f64::NAN, ..r };
    line.clear();
    format_row(&nan, &mut line);
    assert!(parse_row(line.trim_end()).expect("parses").activity_mps.is_nan(), "{line}");
    assert!(parse_row("2126-12-04T16:14:34.123Z,0.1").is_err());
    assert!(parse_row("2126-12-04T16:14:34.123Z,x,,,1,,0,0,0").is_err());
    // The scale column: round trip, a bad name, and rows written before it (9 fields).
    for scale in [ScaleSource::References, ScaleSource::Fish, ScaleSource::None] {
        line.clear();
        format_row(&HistoryRow { scale, ..r }, &mut line);
        assert_eq!(parse_row(line.trim_end()).expect("parses").scale, scale, "{line}");
    }
    let e = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0,ruler").unwrap_err();
    assert!(e.starts_with("scale:"), "{e}");
    let old = parse_row("2126-12-04T16:14:34.123Z,0.1,,,1,,0,0,0").expect("a row without the scale column");
    assert_eq!(old.scale, ScaleSource::None);
    // The unlike_fish column: round trip, a bad value, and rows written before it (10 fields).
    for unlike_fish in [true, false] {
        line.clear();
        format_row(&HistoryRow { unlike_fish, ..r }, &mut line);
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
    let rows: Vec<HistoryRow> =
        codes.iter().enumerate().map(|(i, &c)| HistoryRow { fault: c, ..row(base + i as i64 * 1000, 0.1) }).collect();
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
