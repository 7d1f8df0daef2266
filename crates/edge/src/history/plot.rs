//! `fme report --plot`: a stretch of history as a PNG for the farm manager: activity with its 95 %
//! interval band and the smoothed value, the feeding thresholds, the fish count, feeding recommended
//! and fault codes, against local time (the box's zone or `--tz`).

use super::HistoryRow;
use jiff::tz::TimeZone;
use plotters::prelude::*;
use std::path::Path;

/// Size of the plot, px.
pub const SIZE: (u32, u32) = (1400, 1000);

/// The colours of the feeding thresholds (on, off): unique in the plot, so a test can find them.
pub const THRESHOLD_COLOURS: [RGBColor; 2] = [RGBColor(230, 120, 0), RGBColor(150, 70, 200)];

/// What the plot shows besides the rows.
#[derive(Debug, Clone)]
pub struct PlotOptions {
    /// Start of the time axis, ms since 1970 UTC.
    pub from_ms: i64,
    /// End of the time axis, ms since 1970 UTC (> `from_ms`).
    pub to_ms: i64,
    /// The zone the axis is labelled in.
    pub tz: TimeZone,
    /// The feeding rule's thresholds (on at or above, off at or below), m/s; None: not drawn.
    pub feeding: Option<(f64, f64)>,
}

/// A linear f64 axis with the tick positions given (plotters' `WithKeyPoints` lacks the default
/// label formatting that `x_label_formatter` builds on).
#[derive(Debug, Clone)]
struct Ticked {
    range: std::ops::Range<f64>,
    ticks: Vec<f64>,
}

impl Ticked {
    fn new(range: std::ops::Range<f64>, ticks: Vec<f64>) -> Self {
        Self { range, ticks }
    }
}

impl Ranged for Ticked {
    type FormatOption = plotters::coord::ranged1d::DefaultFormatting;
    type ValueType = f64;
    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        plotters::coord::types::RangedCoordf64::from(self.range.clone()).map(v, limit)
    }
    fn key_points<H: plotters::coord::ranged1d::KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() { Vec::new() } else { self.ticks.clone() }
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.range.clone()
    }
}

/// Runs of consecutive rows with no gap longer than `gap_ms` between them (the daemon was down in
/// a gap: lines are not drawn across it).
fn runs(rows: &[HistoryRow], gap_ms: i64) -> Vec<&[HistoryRow]> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=rows.len() {
        if i == rows.len() || rows[i].unix_ms - rows[i - 1].unix_ms > gap_ms {
            if i > start {
                out.push(&rows[start..i]);
            }
            start = i;
        }
    }
    out
}

/// The fault a row shows in red: its code when it is a fault ([`crate::status::is_fault_code`]).
fn fault_of(r: &HistoryRow) -> Option<u16> {
    crate::status::is_fault_code(r.fault).then_some(r.fault)
}

/// Runs of rows where `key` gives the same `Some` value, as (first ms, last ms, value); a one-row
/// run gets one minute so that it shows.
fn spans(rows: &[HistoryRow], gap_ms: i64, key: impl Fn(&HistoryRow) -> Option<u16>) -> Vec<(i64, i64, u16)> {
    let mut out: Vec<(i64, i64, u16)> = Vec::new();
    let mut prev: Option<(i64, u16)> = None;
    for r in rows {
        let k = key(r);
        let continues = matches!((prev, k), (Some((t, a)), Some(b)) if a == b && r.unix_ms - t <= gap_ms);
        if let Some(v) = k {
            match out.last_mut() {
                Some(last) if continues => last.1 = r.unix_ms,
                _ => out.push((r.unix_ms, r.unix_ms, v)),
            }
        }
        prev = k.map(|v| (r.unix_ms, v));
    }
    for s in &mut out {
        s.1 = s.1.max(s.0 + 60_000);
    }
    out
}

/// Seconds east of UTC of `tz` at `ms`.
fn offset_s(tz: &TimeZone, ms: i64) -> i64 {
    jiff::Timestamp::from_millisecond(ms).map_or(0, |t| i64::from(tz.to_offset(t).seconds()))
}

/// Tick instants (ms) at whole local steps (15 min .. days, about 6 to 16 of them) from `from_ms`
/// to `to_ms`, and whether their labels need the date.
pub fn time_ticks(from_ms: i64, to_ms: i64, tz: &TimeZone) -> (Vec<i64>, bool) {
    let span_h = (to_ms - from_ms) as f64 / 3_600_000.0;
    let step_s: i64 = match span_h {
        h if h <= 2.5 => 900,
        h if h <= 5.0 => 1800,
        h if h <= 14.0 => 3600,
        h if h <= 30.0 => 2 * 3600,
        h if h <= 72.0 => 6 * 3600,
        h if h <= 8.0 * 24.0 => 12 * 3600,
        h => 86_400 * (h / 24.0 / 10.0).ceil() as i64,
    };
    let off = offset_s(tz, from_ms);
    let first = (from_ms.div_euclid(1000) + off + step_s - 1).div_euclid(step_s) * step_s;
    let mut ticks = Vec::new();
    let mut l = first;
    while (l - off) * 1000 <= to_ms && ticks.len() < 64 {
        ticks.push((l - off) * 1000);
        l += step_s;
    }
    (ticks, span_h > 24.0)
}

/// The label of a tick: local `HH:MM`, with `MM-DD` before it when the range spans days.
pub fn tick_label(ms: i64, tz: &TimeZone, with_date: bool) -> String {
    let Ok(t) = jiff::Timestamp::from_millisecond(ms) else { return String::new() };
    t.to_zoned(tz.clone()).strftime(if with_date { "%m-%d %H:%M" } else { "%H:%M" }).to_string()
}

/// The zone's name for people: the IANA name, else its current offset.
pub fn zone_name(tz: &TimeZone, ms: i64) -> String {
    match tz.iana_name() {
        Some(n) => n.to_string(),
        None => {
            let o = offset_s(tz, ms);
            format!("UTC{}{:02}:{:02}", if o < 0 { '-' } else { '+' }, o.abs() / 3600, o.abs() / 60 % 60)
        }
    }
}

/// Whole-number ticks for a count axis up to `max`: steps of 1, 2, 5, 10, 20, ...
pub fn count_ticks(max: u32) -> Vec<f64> {
    let mut step = 1u32;
    for k in 0.. {
        let s = [1, 2, 5][k % 3] * 10u32.pow((k / 3) as u32);
        if max / s <= 8 {
            step = s;
            break;
        }
    }
    (0..=max / step + 1).map(|i| f64::from(i * step)).collect()
}

/// The time axis the three panels share, and how an error names the file.
struct TimeAxis<'a> {
    path: &'a Path,
    from: i64,
    x_end: f64,
    xs: Vec<f64>,
    tz: TimeZone,
    with_date: bool,
    /// Rows further apart than this are not joined by a line (the daemon was down).
    gap_ms: i64,
}

impl TimeAxis<'_> {
    /// Hours since the start of the axis.
    fn x(&self, ms: i64) -> f64 {
        (ms - self.from) as f64 / 3_600_000.0
    }
    fn range(&self) -> Ticked {
        Ticked::new(0.0..self.x_end, self.xs.clone())
    }
    fn label(&self, x: &f64) -> String {
        tick_label(self.from + (x * 3_600_000.0).round() as i64, &self.tz, self.with_date)
    }
    fn err(&self, x: &dyn std::fmt::Display) -> String {
        format!("{}: {x}", self.path.display())
    }
}

type Area<'b> = DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>;

/// Draws `rows` (sorted by time) titled `title` to `path`. Errors are plotters' or the file's, as
/// text.
pub fn plot_day(path: &Path, title: &str, rows: &[HistoryRow], o: &PlotOptions) -> Result<(), String> {
    crate::draw::register_plot_font();
    let mut dts: Vec<i64> = rows.windows(2).map(|w| w[1].unix_ms - w[0].unix_ms).filter(|d| *d > 0).collect();
    dts.sort_unstable();
    let gap_ms = dts.get(dts.len() / 2).map_or(10_000, |m| (5 * m).max(10_000));
    let (from, to) = (o.from_ms, o.to_ms.max(o.from_ms + 60_000));
    let rows: Vec<HistoryRow> = rows.iter().copied().filter(|r| (from..=to).contains(&r.unix_ms)).collect();
    let (ticks, with_date) = time_ticks(from, to, &o.tz);
    let hours = |ms: i64| (ms - from) as f64 / 3_600_000.0;
    let t = TimeAxis {
        path,
        from,
        x_end: hours(to),
        xs: ticks.iter().map(|&ms| hours(ms)).collect(),
        tz: o.tz.clone(),
        with_date,
        gap_ms,
    };
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|x| t.err(&x))?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(|x| t.err(&x))?;
    let (top, rest) = root.split_vertically(SIZE.1 * 52 / 100);
    let (mid, bottom) = rest.split_vertically(SIZE.1 * 22 / 100);
    activity_panel(&top, &t, &rows, o)?;
    fish_panel(&mid, &t, &rows)?;
    faults_panel(&bottom, &t, &rows, o)?;
    root.present().map_err(|x| t.err(&x))?;
    Ok(())
}

/// The top panel: activity, its 95 % band, the smoothed value and the feeding thresholds.
fn activity_panel(area: &Area<'_>, t: &TimeAxis<'_>, rows: &[HistoryRow], o: &PlotOptions) -> Result<(), String> {
    let v_max = rows
        .iter()
        .map(|r| r.activity_mps + if r.ci95_mps.is_finite() { r.ci95_mps } else { 0.0 })
        .chain(o.feeding.map(|f| f.0.max(f.1)))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .clamp(0.1, 5.0)
        * 1.15;
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(t.range(), 0.0..v_max)
        .map_err(|x| t.err(&x))?;
    c.configure_mesh()
        .x_label_formatter(&|x| t.label(x))
        .y_desc("activity (m/s)")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|x| t.err(&x))?;
    let band = RGBColor(160, 190, 240);
    let valued: Vec<HistoryRow> = rows.iter().copied().filter(|r| r.activity_mps.is_finite()).collect();
    let mut labelled = false;
    for run in runs(&valued, t.gap_ms) {
        let with_ci: Vec<&HistoryRow> = run.iter().filter(|r| r.ci95_mps.is_finite()).collect();
        if with_ci.len() >= 2 {
            let mut poly: Vec<(f64, f64)> =
                with_ci.iter().map(|r| (t.x(r.unix_ms), (r.activity_mps + r.ci95_mps).min(v_max))).collect();
            poly.extend(with_ci.iter().rev().map(|r| (t.x(r.unix_ms), (r.activity_mps - r.ci95_mps).max(0.0))));
            let b =
                c.draw_series(std::iter::once(Polygon::new(poly, band.mix(0.6).filled()))).map_err(|x| t.err(&x))?;
            if !labelled {
                b.label("likely range of the activity (95 %)")
                    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], band.filled()));
            }
        }
        let mean = c
            .draw_series(LineSeries::new(
                run.iter().map(|r| (t.x(r.unix_ms), r.activity_mps.min(v_max))),
                BLUE.stroke_width(1),
            ))
            .map_err(|x| t.err(&x))?;
        if !labelled {
            mean.label("activity: average swimming speed of the fish in view")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        }
        let sm: Vec<(f64, f64)> = run
            .iter()
            .filter(|r| r.smoothed_mps.is_finite())
            .map(|r| (t.x(r.unix_ms), r.smoothed_mps.min(v_max)))
            .collect();
        let smooth = c.draw_series(LineSeries::new(sm, BLACK.stroke_width(2))).map_err(|x| t.err(&x))?;
        if !labelled {
            smooth
                .label("smoothed activity (what the feeding advice follows)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        labelled = true;
    }
    if let Some((on, off)) = o.feeding {
        for (v, colour, text) in [
            (on, THRESHOLD_COLOURS[0], format!("feeding advised from {on:.2} m/s (smoothed)")),
            (off, THRESHOLD_COLOURS[1], format!("feeding advice ends at {off:.2} m/s")),
        ] {
            c.draw_series(DashedLineSeries::new([(0.0, v), (t.x_end, v)], 10, 6, colour.stroke_width(2)))
                .map_err(|x| t.err(&x))?
                .label(text)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
            labelled = true;
        }
    }
    if labelled {
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|x| t.err(&x))?;
    }
    Ok(())
}

/// The middle panel: fish in view.
fn fish_panel(area: &Area<'_>, t: &TimeAxis<'_>, rows: &[HistoryRow]) -> Result<(), String> {
    let f_max = rows.iter().map(|r| r.n_fish).max().unwrap_or(0).max(1);
    let f_ticks = count_ticks(f_max);
    let f_top = f_ticks.last().copied().unwrap_or(1.0);
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(t.range(), Ticked::new(0.0..f_top, f_ticks))
        .map_err(|x| t.err(&x))?;
    c.configure_mesh()
        .x_label_formatter(&|x| t.label(x))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .y_desc("fish in view")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|x| t.err(&x))?;
    for run in runs(rows, t.gap_ms) {
        c.draw_series(LineSeries::new(
            run.iter().map(|r| (t.x(r.unix_ms), f64::from(r.n_fish))),
            RGBColor(0, 120, 60).stroke_width(1),
        ))
        .map_err(|x| t.err(&x))?;
    }
    Ok(())
}

/// The bottom panel: feeding recommended and fault codes.
fn faults_panel(area: &Area<'_>, t: &TimeAxis<'_>, rows: &[HistoryRow], o: &PlotOptions) -> Result<(), String> {
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t.range(), Ticked::new(-0.5..8.0, (0..=7).map(f64::from).collect()))
        .map_err(|x| t.err(&x))?;
    c.configure_mesh()
        .x_label_formatter(&|x| t.label(x))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .x_desc(format!("local time ({})", zone_name(&o.tz, t.from)))
        .y_desc("fault code / feeding")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|x| t.err(&x))?;
    let green = RGBColor(40, 170, 60);
    c.draw_series(
        spans(rows, t.gap_ms, |r| r.feeding.then_some(1))
            .into_iter()
            .map(|(a, b, _)| Rectangle::new([(t.x(a), -0.4), (t.x(b), 0.4)], green.mix(0.7).filled())),
    )
    .map_err(|x| t.err(&x))?
    .label("feeding recommended (at 0)")
    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], green.filled()));
    c.draw_series(spans(rows, t.gap_ms, fault_of).into_iter().map(|(a, b, v)| {
        Rectangle::new([(t.x(a), f64::from(v) - 0.35), (t.x(b), f64::from(v) + 0.35)], RED.mix(0.8).filled())
    }))
    .map_err(|x| t.err(&x))?
    .label("fault code (1 camera, 2 detector, 3 depth, 4 stalled, 5 PLC link, 7 unlike fish)")
    .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], RED.filled()));
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|x| t.err(&x))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(s: i64, fault: u16, feeding: bool) -> HistoryRow {
        HistoryRow {
            unix_ms: s * 1000,
            activity_mps: 0.1,
            smoothed_mps: 0.1,
            ci95_mps: 0.01,
            n_fish: 3,
            bls: 0.3,
            status: 0,
            fault,
            feeding,
            scale: fme_core::pipeline::ScaleSource::Fish,
            unlike_fish: false,
        }
    }

    #[test]
    fn runs_break_at_gaps_and_spans_follow_values() {
        let rows = [r(0, 0, false), r(1, 1, true), r(2, 1, true), r(100, 1, true), r(101, 0, false)];
        assert_eq!(runs(&rows, 10_000).iter().map(|x| x.len()).collect::<Vec<_>>(), [3, 2]);
        let s = spans(&rows, 10_000, |x| (x.fault != 0).then_some(x.fault));
        assert_eq!(s.len(), 2, "{s:?}");
        assert_eq!(s[0].2, 1);
        // Spans stop at the gap; a short span is widened to one minute so that it shows.
        assert_eq!((s[0].0, s[0].1), (1000, 61_000));
        assert_eq!(s[1].0, 100_000, "{s:?}");
    }

    #[test]
    fn ticks_at_whole_local_hours_labelled_in_the_zone() {
        let from = 20_791 * 86_400_000; // a midnight, UTC
        let utc = TimeZone::UTC;
        let kolkata = TimeZone::fixed(jiff::tz::Offset::from_seconds(19_800).expect("offset"));
        let (t_utc, date) = time_ticks(from, from + 12 * 3_600_000, &utc);
        assert!(!date);
        assert_eq!(t_utc[0], from);
        assert_eq!(t_utc[1] - t_utc[0], 3_600_000, "hourly over 12 h");
        assert_eq!(tick_label(t_utc[0], &utc, false), "00:00");
        // +05:30: the first whole local hour is 06:00 local, 00:30 UTC; --tz changes the labels.
        let (t_k, _) = time_ticks(from, from + 12 * 3_600_000, &kolkata);
        assert_eq!(t_k[0], from + 1_800_000);
        assert_eq!(tick_label(t_k[0], &kolkata, false), "06:00");
        assert_ne!(tick_label(from, &utc, false), tick_label(from, &kolkata, false));
        // Longer spans: fewer ticks, with the date.
        let (t, date) = time_ticks(from, from + 48 * 3_600_000, &utc);
        assert!(date && t.len() <= 16, "{}", t.len());
        assert_eq!(tick_label(t[1], &utc, true), "12-04 06:00");
        assert_eq!(zone_name(&kolkata, from), "UTC+05:30");
    }

    #[test]
    fn fish_axis_has_whole_numbers() {
        assert_eq!(count_ticks(3), [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(count_ticks(22), [0.0, 5.0, 10.0, 15.0, 20.0, 25.0]);
        assert!(count_ticks(137).iter().all(|v| v.fract() == 0.0));
    }

    #[test]
    fn feeding_thresholds_drawn_where_configured() {
        let dir = tempfile::tempdir().expect("tempdir");
        let rows: Vec<HistoryRow> = (0..600).map(|i| r(i * 10, 0, i > 300)).collect();
        let count = |feeding: Option<(f64, f64)>, name: &str| {
            let path = dir.path().join(name);
            let o = PlotOptions { from_ms: 0, to_ms: 6_000_000, tz: TimeZone::UTC, feeding };
            plot_day(&path, "test", &rows, &o).expect("plot");
            let img = image::open(&path).expect("png").to_rgb8();
            THRESHOLD_COLOURS.map(|c| img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count())
        };
        let [on, off] = count(Some((0.25, 0.15)), "with.png");
        assert!(on > 500 && off > 500, "dashed lines across the plot: {on} {off}");
        assert_eq!(count(None, "without.png"), [0, 0]);
    }

    #[test]
    fn a_clean_stop_draws_no_fault() {
        let rows = [r(0, 0, false), r(1, 6, false), r(2, 1, false)];
        let s = spans(&rows, 10_000, fault_of);
        assert_eq!(s.iter().map(|x| x.2).collect::<Vec<_>>(), [1], "code 6 (stopped) is no fault: {s:?}");
    }
}
