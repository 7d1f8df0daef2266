//! `fme report --plot`: one day of history as a PNG: activity with its 95 % interval band and the
//! smoothed value, fish count, feeding recommended and fault codes, against UTC hour of day.

use super::Row;
use plotters::prelude::*;
use std::path::Path;

/// Size of the day plot, px.
pub const SIZE: (u32, u32) = (1400, 1000);

/// Runs of consecutive rows with no gap longer than `gap_ms` between them (the daemon was down in
/// a gap: lines are not drawn across it).
fn runs(rows: &[Row], gap_ms: i64) -> Vec<&[Row]> {
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

/// Runs of rows where `key` gives the same `Some` value, as (first hour, last hour + one row, value).
/// The fault a row shows in red: its code when it is a fault ([`crate::status::is_fault_code`]).
fn fault_of(r: &Row) -> Option<u16> {
    crate::status::is_fault_code(r.fault).then_some(r.fault)
}

fn spans(rows: &[Row], gap_ms: i64, key: impl Fn(&Row) -> Option<u16>) -> Vec<(f64, f64, u16)> {
    let mut out: Vec<(f64, f64, u16)> = Vec::new();
    let mut prev: Option<(i64, u16)> = None;
    for r in rows {
        let k = key(r);
        let continues = matches!((prev, k), (Some((t, a)), Some(b)) if a == b && r.unix_ms - t <= gap_ms);
        if let Some(v) = k {
            let x = hour(r.unix_ms);
            match out.last_mut() {
                Some(last) if continues => last.1 = x,
                _ => out.push((x, x, v)),
            }
        }
        prev = k.map(|v| (r.unix_ms, v));
    }
    // Give a one-row span a visible width (one minute).
    for s in &mut out {
        s.1 = s.1.max(s.0 + 1.0 / 60.0);
    }
    out
}

fn hour(unix_ms: i64) -> f64 {
    unix_ms.rem_euclid(86_400_000) as f64 / 3_600_000.0
}

/// Draws `rows` (one UTC day, sorted by time) titled `title` to `path`. Errors are plotters' or
/// the file's, as text.
pub fn plot_day(path: &Path, title: &str, rows: &[Row]) -> Result<(), String> {
    crate::eval::plot::register_font();
    let e = |x: &dyn std::fmt::Display| format!("{}: {x}", path.display());
    let mut dts: Vec<i64> = rows.windows(2).map(|w| w[1].unix_ms - w[0].unix_ms).filter(|d| *d > 0).collect();
    dts.sort_unstable();
    let gap_ms = dts.get(dts.len() / 2).map_or(10_000, |m| (5 * m).max(10_000));
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(|x| e(&x))?;
    let (top, rest) = root.split_vertically(SIZE.1 * 52 / 100);
    let (mid, bottom) = rest.split_vertically(SIZE.1 * 22 / 100);

    let v_max = rows
        .iter()
        .map(|r| r.activity_mps + if r.ci95_mps.is_finite() { r.ci95_mps } else { 0.0 })
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .clamp(0.1, 5.0)
        * 1.1;
    let mut c = ChartBuilder::on(&top)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..24.0, 0.0..v_max)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_labels(25)
        .y_desc("activity (m/s)")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|x| e(&x))?;
    let band = RGBColor(160, 190, 240);
    let valued: Vec<Row> = rows.iter().copied().filter(|r| r.activity_mps.is_finite()).collect();
    let mut labelled = false;
    for run in runs(&valued, gap_ms) {
        let with_ci: Vec<&Row> = run.iter().filter(|r| r.ci95_mps.is_finite()).collect();
        if with_ci.len() >= 2 {
            let mut poly: Vec<(f64, f64)> =
                with_ci.iter().map(|r| (hour(r.unix_ms), (r.activity_mps + r.ci95_mps).min(v_max))).collect();
            poly.extend(with_ci.iter().rev().map(|r| (hour(r.unix_ms), (r.activity_mps - r.ci95_mps).max(0.0))));
            c.draw_series(std::iter::once(Polygon::new(poly, band.mix(0.6).filled()))).map_err(|x| e(&x))?;
        }
        let mean = c
            .draw_series(LineSeries::new(
                run.iter().map(|r| (hour(r.unix_ms), r.activity_mps.min(v_max))),
                BLUE.stroke_width(1),
            ))
            .map_err(|x| e(&x))?;
        if !labelled {
            mean.label("activity (swarm mean, eq. 5) with its 95 % interval")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        }
        let sm: Vec<(f64, f64)> = run
            .iter()
            .filter(|r| r.smoothed_mps.is_finite())
            .map(|r| (hour(r.unix_ms), r.smoothed_mps.min(v_max)))
            .collect();
        let smooth = c.draw_series(LineSeries::new(sm, BLACK.stroke_width(2))).map_err(|x| e(&x))?;
        if !labelled {
            smooth.label("smoothed").legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        labelled = true;
    }
    if labelled {
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|x| e(&x))?;
    }

    let f_max = rows.iter().map(|r| r.n_fish).max().unwrap_or(0).max(1) as f64 * 1.1;
    let mut c = ChartBuilder::on(&mid)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..24.0, 0.0..f_max)
        .map_err(|x| e(&x))?;
    c.configure_mesh().x_labels(25).y_desc("fish").label_style(("sans-serif", 14)).draw().map_err(|x| e(&x))?;
    for run in runs(rows, gap_ms) {
        c.draw_series(LineSeries::new(
            run.iter().map(|r| (hour(r.unix_ms), f64::from(r.n_fish))),
            RGBColor(0, 120, 60).stroke_width(1),
        ))
        .map_err(|x| e(&x))?;
    }

    let mut c = ChartBuilder::on(&bottom)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..24.0, -0.5..8.0)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_labels(25)
        .x_desc("hour of day (UTC)")
        .y_desc("fault code / feeding")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|x| e(&x))?;
    let green = RGBColor(40, 170, 60);
    c.draw_series(
        spans(rows, gap_ms, |r| r.feeding.then_some(1))
            .into_iter()
            .map(|(a, b, _)| Rectangle::new([(a, -0.4), (b, 0.4)], green.mix(0.7).filled())),
    )
    .map_err(|x| e(&x))?
    .label("feeding recommended (at 0)")
    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], green.filled()));
    c.draw_series(
        spans(rows, gap_ms, fault_of).into_iter().map(|(a, b, v)| {
            Rectangle::new([(a, f64::from(v) - 0.35), (b, f64::from(v) + 0.35)], RED.mix(0.8).filled())
        }),
    )
    .map_err(|x| e(&x))?
    .label("fault code (1 camera, 2 detector, 3 depth, 4 stalled, 5 PLC link, 7 unlike fish)")
    .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], RED.filled()));
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(s: i64, fault: u16, feeding: bool) -> Row {
        Row {
            unix_ms: s * 1000,
            activity_mps: 0.1,
            smoothed_mps: 0.1,
            ci95_mps: 0.01,
            n_fish: 3,
            bls: 0.3,
            status: 0,
            fault,
            feeding,
            scale: crate::pipeline::ScaleSource::Fish,
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
        assert!((s[0].0 - hour(1000)).abs() < 1e-12 && (s[0].1 - (hour(1000) + 1.0 / 60.0)).abs() < 1e-12);
        assert!((s[1].0 - hour(100_000)).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn a_clean_stop_draws_no_fault() {
        let rows = [r(0, 0, false), r(1, 6, false), r(2, 1, false)];
        let s = spans(&rows, 10_000, fault_of);
        assert_eq!(s.iter().map(|x| x.2).collect::<Vec<_>>(), [1], "code 6 (stopped) is no fault: {s:?}");
    }
}
