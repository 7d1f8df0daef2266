//! The files `fme eval` writes beside its report: `--series` and `--tracks`.

use super::EvalError;
use super::report::{FishRow, ScoredRow};
use std::io::Write;
use std::path::Path;

/// Writes a CSV file: `header`, then one line per item from `line` (empty field where a value is
/// missing: [`csv_opt`]). Errors name the file.
fn write_csv<T>(
    path: &Path,
    header: &str,
    items: &[T],
    mut line: impl FnMut(&mut dyn Write, &T) -> std::io::Result<()>,
) -> Result<(), EvalError> {
    let err = |e: std::io::Error| EvalError::Output { path: path.to_path_buf(), msg: e.to_string() };
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).map_err(err)?);
    writeln!(out, "{header}").map_err(err)?;
    for item in items {
        line(&mut out, item).map_err(err)?;
    }
    out.flush().map_err(err)
}

fn csv_opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

/// Writes the series the pipeline computed, in the columns of `fme run --series` (so the two files
/// compare column by column) followed by the truth: `true_mps` (at `t - latency`) and `true_now_mps`.
pub fn write_series(path: &Path, series: &[ScoredRow]) -> Result<(), EvalError> {
    let err = |msg: String| EvalError::Output { path: path.to_path_buf(), msg };
    let mut w = fme_edge::sequence::SeriesWriter::create(path, ",true_mps,true_now_mps").map_err(err)?;
    for r in series {
        w.write_with(&r.row, format_args!(",{},{}", csv_opt(r.true_mps), csv_opt(r.true_now_mps))).map_err(err)?;
    }
    w.finish().map_err(err)
}

/// Writes the per-fish rows as CSV with header `frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps`
/// (empty field where a value is missing).
pub fn write_tracks(path: &Path, rows: &[FishRow]) -> Result<(), EvalError> {
    write_csv(path, "frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps", rows, |out, r| {
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{}",
            r.frame,
            r.t,
            r.id,
            r.centre.u,
            r.centre.v,
            r.size.0,
            r.size.1,
            csv_opt(r.depth_raw_m),
            csv_opt(r.depth_m),
            csv_opt(r.speed_mps)
        )
    })
}
