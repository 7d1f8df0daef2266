//! `--tracks`: one row per fish seen on each frame, as the estimator saw it.

use super::{FrameTruth, Scorer};
use crate::eval::report::FishRow;
use crate::eval::{EvalError, EvalReport};
use fme_core::pipeline::FrameOutcome;

/// Collects the rows.
#[derive(Debug, Default)]
pub struct FishRows {
    rows: Vec<FishRow>,
}

impl Scorer for FishRows {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        self.rows.extend(o.fish_seen().map(|v| FishRow {
            frame: truth.frame,
            t: o.t.0,
            id: v.id,
            centre: v.bbox.center(),
            size: (v.bbox.w, v.bbox.h),
            depth_raw_m: v.depth_measured.map(|d| d.0),
            depth_m: v.depth.map(|d| d.0),
            speed_mps: v.speed.map(|s| s.0),
        }));
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        report.tracks = self.rows;
        Ok(())
    }
}
