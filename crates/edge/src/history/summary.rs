//! Hourly summaries of the history (console `history`, `fme report`).

use super::{HistoryError, HistoryRow, format_time, read_range};
use std::fmt::Write as _;
use std::path::Path;

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
pub fn summarize_hours(rows: &[HistoryRow], first_hour_ms: i64, hours: usize) -> Vec<HourSummary> {
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
