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
    /// with an offset (`2026-12-04T06:00Z`). Alone: one day from it.
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
    const DAY: i64 = 86_400_000;
    let (mut text, rows, torn, hours_from, hours, range) = if a.from.is_some() || a.to.is_some() {
        let from = a.from.as_deref().map(|s| parse_when("--from", s, &tz)).transpose().map_err(usage)?;
        let to = a.to.as_deref().map(|s| parse_when("--to", s, &tz)).transpose().map_err(usage)?;
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
                stamp(from, &tz),
                stamp(to, &tz)
            )));
        }
        let first = from.div_euclid(3_600_000) * 3_600_000;
        let hours = ((to - first + 3_599_999) / 3_600_000).clamp(1, 24 * 62) as usize;
        (format!("{}: {} rows\n", a.history.display(), rows.len()), rows, torn, first, hours, (from, to))
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
        (text, rows, usize::from(file.torn_last_line), day * DAY, 24, range)
    };
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
