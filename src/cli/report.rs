//! `fme report`: the activity history (`docs/history.md`): an hourly summary on stdout and, with
//! `--plot`, a PNG in local time. One UTC day file (`--day`) or any stretch (`--from`, `--to`).

use super::UsageError;
use crate::history;
use jiff::tz::TimeZone;
use std::path::PathBuf;

/// Arguments of `fme report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The history directory (the day files `YYYY-MM-DD.csv`).
    #[arg(long, value_name = "DIR")]
    pub history: PathBuf,
    /// The UTC day to report, `YYYY-MM-DD` (default: today, UTC). The plot spans its rows.
    #[arg(long, value_name = "YYYY-MM-DD", conflicts_with_all = ["from", "to"])]
    pub day: Option<String>,
    /// Start of the stretch to report, in the --tz zone: `YYYY-MM-DD`, `YYYY-MM-DD HH:MM[:SS]`, or
    /// with an offset (`YYYY-MM-DDTHH:MMZ`, `...+01:00`). Alone: one day from it.
    #[arg(long, value_name = "TIME")]
    pub from: Option<String>,
    /// End of the stretch (exclusive), as --from. Alone: the day before it.
    #[arg(long, value_name = "TIME")]
    pub to: Option<String>,
    /// The zone of the plot's time axis and of --from/--to: an IANA name (`Europe/Oslo`), `UTC`, or
    /// an offset (`+05:30`). Default: the box's zone (`TZ`, else /etc/localtime).
    #[arg(long, value_name = "ZONE")]
    pub tz: Option<String>,
    /// Draw the stretch (activity with its interval and the feeding thresholds of the config, fish
    /// count, feeding recommended, faults) as a PNG.
    #[arg(long, value_name = "PNG")]
    pub plot: Option<PathBuf>,
    /// The configuration (its `[feeding]` thresholds are drawn).
    #[command(flatten)]
    pub config: super::ConfigArgs,
}

/// `--tz`: an IANA name, `UTC`, or `+HH:MM` / `-HH:MM`.
pub fn parse_tz(s: &str) -> Result<TimeZone, String> {
    let b = s.as_bytes();
    if let (Some(&sign @ (b'+' | b'-')), 6) = (b.first(), b.len()) {
        let num = |r: std::ops::Range<usize>| s.get(r).and_then(|t| t.parse::<i32>().ok());
        if let (Some(h), b':', Some(m)) = (num(1..3), b[3], num(4..6))
            && h <= 14
            && m < 60
        {
            let secs = (h * 3600 + m * 60) * if sign == b'-' { -1 } else { 1 };
            return jiff::tz::Offset::from_seconds(secs).map(TimeZone::fixed).map_err(|e| format!("--tz {s:?}: {e}"));
        }
        return Err(format!("--tz {s:?}: an offset is +HH:MM or -HH:MM"));
    }
    TimeZone::get(s).map_err(|e| format!("--tz {s:?}: not a known time zone ({e}); e.g. Europe/Oslo, UTC, +05:30"))
}

/// `--from`/`--to`: a date (midnight), a date and time in `tz`, or an instant with an offset.
pub fn parse_when(flag: &str, s: &str, tz: &TimeZone) -> Result<i64, String> {
    let t = s.trim();
    let ts = if let Ok(ts) = t.parse::<jiff::Timestamp>() {
        Ok(ts)
    } else if let Ok(dt) = t.parse::<jiff::civil::DateTime>() {
        dt.to_zoned(tz.clone()).map(|z| z.timestamp())
    } else if let Ok(d) = t.parse::<jiff::civil::Date>() {
        d.to_zoned(tz.clone()).map(|z| z.timestamp())
    } else {
        return Err(format!("{flag} {s:?}: must be YYYY-MM-DD, YYYY-MM-DD HH:MM[:SS] or with an offset"));
    };
    ts.map(|t| t.as_millisecond()).map_err(|e| format!("{flag} {s:?}: {e}"))
}

/// The rows a report covers, the summary's hours and the plot's time range.
#[derive(Debug)]
struct Selection {
    /// The first line of the text (what was read).
    text: String,
    rows: Vec<history::HistoryRow>,
    torn: usize,
    hours_from: i64,
    hours: usize,
    /// The plot's time axis, ms since 1970 UTC.
    range: (i64, i64),
}

/// `--day` (the rows of one UTC day file; the plot spans them) or `--from`/`--to` (the rows in that
/// stretch, from every day file it touches; the plot spans the stretch).
fn select(a: &ReportArgs, tz: &TimeZone) -> anyhow::Result<Selection> {
    let usage = |m: String| anyhow::Error::new(UsageError(m));
    const DAY: i64 = 86_400_000;
    Ok(if a.from.is_some() || a.to.is_some() {
        let from = a.from.as_deref().map(|s| parse_when("--from", s, tz)).transpose().map_err(usage)?;
        let to = a.to.as_deref().map(|s| parse_when("--to", s, tz)).transpose().map_err(usage)?;
        let (from, to) = match (from, to) {
            (Some(f), Some(t)) => (f, t),
            (Some(f), None) => (f, f + DAY),
            (None, Some(t)) => (t - DAY, t),
            (None, None) => return Err(usage("--from or --to: no time given".into())),
        };
        if from >= to {
            return Err(usage(format!("--from {:?} is not before --to {:?}", a.from, a.to)));
        }
        let (rows, torn) = history::read_range(&a.history, from, to).map_err(|e| usage(e.to_string()))?;
        if rows.is_empty() {
            return Err(usage(format!(
                "{}: no history rows from {} to {}",
                a.history.display(),
                stamp(from, tz),
                stamp(to, tz)
            )));
        }
        let first = from.div_euclid(3_600_000) * 3_600_000;
        let hours = ((to - first + 3_599_999) / 3_600_000).clamp(1, 24 * 62) as usize;
        Selection {
            text: format!("{}: {} rows\n", a.history.display(), rows.len()),
            rows,
            torn,
            hours_from: first,
            hours,
            range: (from, to),
        }
    } else {
        let day = match &a.day {
            Some(d) => history::parse_day(d).ok_or_else(|| usage(format!("--day {d:?}: must be a date YYYY-MM-DD")))?,
            None => history::day_of(history::now_unix_ms()),
        };
        let path = history::day_path(&a.history, day);
        let file = history::read_day_file(&path).map_err(|e| usage(e.to_string()))?;
        let mut rows = file.rows;
        if let Some(i) = rows.iter().position(|r| history::day_of(r.unix_ms) != day) {
            return Err(usage(format!(
                "{}:{}: row of another day in the file of {}",
                path.display(),
                i + 2,
                history::day_name(day)
            )));
        }
        rows.sort_by_key(|r| r.unix_ms);
        // The plot spans the rows (at least ten minutes); a day file without rows, the whole day.
        let range = match (rows.first(), rows.last()) {
            (Some(f), Some(l)) => (f.unix_ms, l.unix_ms.max(f.unix_ms + 600_000)),
            _ => (day * DAY, (day + 1) * DAY),
        };
        let text = format!("{}: {} rows\n", path.display(), rows.len());
        Selection { text, rows, torn: usize::from(file.torn_last_line), hours_from: day * DAY, hours: 24, range }
    })
}

/// Local `YYYY-MM-DD HH:MM` of an instant.
fn stamp(ms: i64, tz: &TimeZone) -> String {
    jiff::Timestamp::from_millisecond(ms)
        .map(|t| t.to_zoned(tz.clone()).strftime("%Y-%m-%d %H:%M").to_string())
        .unwrap_or_default()
}

/// Runs `fme report`. A missing or malformed day file, a stretch with no rows, or a bad `--day`,
/// `--from`, `--to` or `--tz` exits 2 naming the file and line or the flag (a torn last line is
/// skipped, as after a power cut).
pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    let usage = |m: String| anyhow::Error::new(UsageError(m));
    let tz = match &a.tz {
        Some(z) => parse_tz(z).map_err(usage)?,
        None => TimeZone::system(),
    };
    let Selection { mut text, rows, torn, hours_from, hours, range } = select(&a, &tz)?;
    let summary = history::summarize_hours(&rows, hours_from, hours);
    text.push_str(&history::format_summary(&summary, torn));
    if let Some(png) = &a.plot {
        let (cfg, _) = a.config.load(&[])?;
        let opts = history::plot::PlotOptions {
            from_ms: range.0,
            to_ms: range.1,
            tz: tz.clone(),
            feeding: Some((cfg.feeding.on_above_mps, cfg.feeding.off_below_mps)),
        };
        let title = format!(
            "fme activity {} to {} ({})",
            stamp(range.0, &tz),
            stamp(range.1, &tz),
            history::plot::zone_name(&tz, range.0)
        );
        history::plot::plot_day(png, &title, &rows, &opts).map_err(|e| anyhow::anyhow!("--plot {e}"))?;
        text.push_str(&format!("plot: {}\n", png.display()));
    }
    super::write_stdout(&text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::HistoryRow;

    const H: i64 = 3_600_000;

    fn day_ms(d: &str) -> i64 {
        history::parse_day(d).expect("day") * 86_400_000
    }

    /// Day files with a row every 10 minutes over each of `spans` (from, to), ms.
    fn write(dir: &std::path::Path, spans: &[(i64, i64)]) {
        let mut files: std::collections::BTreeMap<i64, String> = std::collections::BTreeMap::new();
        for &(a, b) in spans {
            for t in (a..b).step_by(600_000) {
                let text = files.entry(history::day_of(t)).or_insert_with(|| format!("{}\n", history::HEADER));
                let r = HistoryRow {
                    unix_ms: t,
                    activity_mps: 0.2,
                    smoothed_mps: 0.2,
                    ci95_mps: 0.01,
                    n_fish: 5,
                    bls: 0.5,
                    status: 15,
                    fault: 0,
                    feeding: false,
                    scale: crate::pipeline::ScaleSource::Fish,
                    unlike_fish: false,
                };
                history::format_row(&r, text);
            }
        }
        for (day, text) in files {
            std::fs::write(history::day_path(dir, day), text).expect("write");
        }
    }

    fn args(dir: &std::path::Path, day: Option<&str>, from: Option<&str>, to: Option<&str>) -> ReportArgs {
        ReportArgs {
            history: dir.to_path_buf(),
            day: day.map(str::to_string),
            from: from.map(str::to_string),
            to: to.map(str::to_string),
            tz: None,
            plot: None,
            config: super::super::ConfigArgs::default(),
        }
    }

    #[test]
    fn time_range_follows_the_data_or_from_to_in_the_zone() {
        let dir = tempfile::tempdir().expect("tempdir");
        // Three consecutive UTC days, any will do; their names are written as the flags take them.
        let day = history::day_of(0) + 21_000;
        let (n4, n5, n6) = (history::day_name(day), history::day_name(day + 1), history::day_name(day + 2));
        let (d4, d5) = (day_ms(&n4), day_ms(&n5));
        write(dir.path(), &[(d4 + 6 * H, d4 + 8 * H), (d5, d5 + 2 * H)]);
        let utc = TimeZone::UTC;
        // --day: the plot spans the day's rows.
        let s = select(&args(dir.path(), Some(&n4), None, None), &utc).expect("day");
        assert_eq!(s.range, (d4 + 6 * H, d4 + 8 * H - 600_000));
        assert_eq!(s.rows.len(), 12);
        // --from/--to in UTC: across the day files, `to` exclusive.
        let (from, to) = (format!("{n4} 07:00"), format!("{n5}T01:00"));
        let a = args(dir.path(), None, Some(&from), Some(&to));
        let s = select(&a, &utc).expect("range");
        assert_eq!(s.range, (d4 + 7 * H, d5 + H));
        assert_eq!(s.rows.len(), 6 + 6, "07:00-08:00 on the first day, 00:00-01:00 on the second");
        // The same wall times in +05:30 are 5.5 h earlier: only the first day's rows.
        let s = select(&a, &parse_tz("+05:30").expect("tz")).expect("range");
        assert_eq!(s.range, (d4 + 7 * H - 11 * H / 2, d5 + H - 11 * H / 2));
        assert_eq!(s.rows.len(), 12, "{:?}", s.range);
        // --from alone: one day; an instant with an offset ignores --tz.
        let instant = format!("{n4}T23:00Z");
        let s = select(&args(dir.path(), None, Some(&instant), None), &utc).expect("from");
        assert_eq!(s.range, (d4 + 23 * H, d5 + 23 * H));
        // Empty or reversed stretches are errors naming the flags.
        let e = select(&args(dir.path(), None, Some(&n6), None), &utc).expect_err("no rows");
        assert!(e.to_string().contains("no history rows"), "{e}");
        let e = select(&args(dir.path(), None, Some(&n5), Some(&n4)), &utc).expect_err("reversed");
        assert!(e.to_string().contains("not before --to"), "{e}");
        // Day first, dotted: not a form --from takes.
        let (y, m, d) = (&n4[..4], &n4[5..7], &n4[8..]);
        assert!(parse_when("--from", &format!("{d}.{m}.{y}"), &utc).is_err());
    }

    #[test]
    fn zones_by_name_or_offset() {
        let t = jiff::Timestamp::from_second(0).expect("epoch");
        assert_eq!(parse_tz("+05:30").expect("offset").to_offset(t).seconds(), 19_800);
        assert_eq!(parse_tz("-03:00").expect("offset").to_offset(t).seconds(), -10_800);
        assert_eq!(parse_tz("UTC").expect("utc").to_offset(t).seconds(), 0);
        assert_eq!(parse_tz("Asia/Kolkata").expect("iana").to_offset(t).seconds(), 19_800);
        for bad in ["Mars/Base", "+5:30", "+25:00"] {
            assert!(parse_tz(bad).is_err(), "{bad}");
        }
    }
}
