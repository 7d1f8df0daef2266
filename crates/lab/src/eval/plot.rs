//! `--plot`: estimated vs true swarm speed over time (like the paper's Fig. 11), as a PNG.

use super::{EvalError, EvalReport};
use fme_edge::draw::register_plot_font;
use plotters::prelude::*;
use std::path::Path;

/// Draws the report's series (true, estimated, and estimated without post-processing) to `path`.
pub fn plot_series(path: &Path, report: &EvalReport) -> Result<(), EvalError> {
    register_plot_font();
    let err = |e: String| EvalError::Output { path: path.to_path_buf(), msg: e };
    let s = &report.series;
    let t_max = s.iter().map(super::ScoredRow::t).fold(0.0, f64::max).max(1e-3);
    let v_max =
        s.iter().flat_map(|r| [r.true_mps, r.est_mps(), r.true_now_mps]).flatten().fold(0.0, f64::max).clamp(0.1, 5.0)
            * 1.1;
    let root = BitMapBackend::new(path, (1200, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let title = format!(
        "{}  RMSE {:.3} m/s (against the truth now {:.3})  DistCorr {:.3}",
        Path::new(&report.sequence).file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned()),
        report.speed_rmse_mps,
        report.speed_rmse_now_mps,
        report.speed_distcorr
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_max, 0.0..v_max)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("swarm mean speed (m/s)")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|e| err(e.to_string()))?;
    let line = |f: fn(&super::ScoredRow) -> Option<f64>| -> Vec<(f64, f64)> {
        s.iter().filter_map(|r| f(r).map(|v| (r.t(), v.min(v_max)))).collect()
    };
    let now_color = RGBColor(170, 170, 170);
    chart
        .draw_series(LineSeries::new(line(|r| r.true_now_mps), now_color.stroke_width(1)))
        .map_err(|e| err(e.to_string()))?
        .label("ground truth at t")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], now_color));
    chart
        .draw_series(LineSeries::new(line(|r| r.true_mps), BLACK.stroke_width(2)))
        .map_err(|e| err(e.to_string()))?
        .label(format!("ground truth at t - {:.2} s (estimate latency)", report.latency_s))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .draw_series(LineSeries::new(line(super::ScoredRow::est_mps), BLUE.stroke_width(2)))
        .map_err(|e| err(e.to_string()))?
        .label("estimated (fme)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}
