//! `fme report`: one day of the activity history (`docs/history.md`): an hourly summary on stdout
//! and, with `--plot`, a PNG of the day.

use super::UsageError;
use crate::history;
use std::path::PathBuf;

/// Arguments of `fme report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The history directory (the day files `YYYY-MM-DD.csv`).
    #[arg(long, value_name = "DIR")]
    pub history: PathBuf,
    /// The UTC day to report, `YYYY-MM-DD` (default: today, UTC).
    #[arg(long, value_name = "YYYY-MM-DD")]
    pub day: Option<String>,
    /// Draw the day (activity with its interval, fish count, feeding recommended, faults) as a PNG.
    #[arg(long, value_name = "PNG")]
    pub plot: Option<PathBuf>,
}

/// Runs `fme report`. A missing or malformed day file, or a bad `--day`, exits 2 naming the file
/// and line (a torn last line is skipped, as after a power cut).
pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    let usage = |m: String| anyhow::Error::new(UsageError(m));
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
    let hours = history::summarize_hours(&rows, day * 86_400_000, 24);
    let mut text = format!("{}: {} rows\n", path.display(), rows.len());
    text.push_str(&history::format_summary(&hours, usize::from(file.torn_last_line)));
    if let Some(png) = &a.plot {
        let title = format!("fme history {} (UTC)", history::day_name(day));
        history::plot::plot_day(png, &title, &rows).map_err(|e| anyhow::anyhow!("--plot {e}"))?;
        text.push_str(&format!("plot: {}\n", png.display()));
    }
    super::write_stdout(&text)
}
