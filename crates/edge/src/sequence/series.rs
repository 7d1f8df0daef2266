//! The per-frame series of the activity index as the pipeline computed it (`fme run --series`,
//! `fme eval --series`): one CSV row per frame, so a recording's output can be compared frame by frame.

use fme_core::pipeline::ActivitySample;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The CSV header of [`SeriesWriter`].
pub const HEADER: &str =
    "frame,t,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,latency_s,too_few_fish,uncalibrated,scale,unlike_fish";

/// One row: the frame number (1-based, in delivery order) and the sample computed on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesRow {
    /// 1-based frame number.
    pub frame: u64,
    /// The sample.
    pub sample: ActivitySample,
}

/// Writes the series as CSV; a missing value (NaN) is an empty field. Errors name the file.
#[derive(Debug)]
pub struct SeriesWriter {
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
}

fn opt(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

struct Field(Option<f64>);

impl std::fmt::Display for Field {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(v) => write!(f, "{v}"),
            None => Ok(()),
        }
    }
}

impl SeriesWriter {
    /// Creates `path` and writes the header, followed by `extra` (more columns, starting with a
    /// comma, that [`Self::write_with`] fills; empty for none).
    pub fn create(path: &Path, extra: &str) -> Result<Self, String> {
        let err = |e: std::io::Error| format!("{}: {e}", path.display());
        let f = std::fs::File::create(path).map_err(err)?;
        let mut out = std::io::BufWriter::new(f);
        writeln!(out, "{HEADER}{extra}").map_err(err)?;
        Ok(Self { path: path.to_path_buf(), out })
    }

    /// Appends one row.
    pub fn write(&mut self, row: &SeriesRow) -> Result<(), String> {
        self.write_with(row, format_args!(""))
    }

    /// Appends one row followed by `extra` (the extra columns, starting with a comma).
    pub fn write_with(&mut self, row: &SeriesRow, extra: std::fmt::Arguments<'_>) -> Result<(), String> {
        let s = &row.sample;
        writeln!(
            self.out,
            "{},{},{},{},{},{},{},{},{},{},{},{}{extra}",
            row.frame,
            s.timestamp.0,
            Field(opt(s.mean.0)),
            Field(opt(s.smoothed.0)),
            Field(opt(s.ci95_half.0)),
            s.fish,
            Field(opt(s.mean_body_lengths)),
            s.latency.0,
            u8::from(s.flags.too_few_fish),
            u8::from(s.flags.unfitted),
            s.scale.name(),
            u8::from(s.flags.unlike_fish)
        )
        .map_err(|e| format!("{}: {e}", self.path.display()))
    }

    /// Flushes what is buffered.
    pub fn finish(mut self) -> Result<(), String> {
        self.out.flush().map_err(|e| format!("{}: {e}", self.path.display()))
    }
}
