//! What the pipeline says about itself: the depth fits (eq. 1-2) and their scale, the reference
//! objects, and the corrections of eq. 3-4.

use super::{FrameTruth, Scorer};
use crate::eval::{EvalError, EvalReport};
use fme_core::pipeline::{DepthFitState, FitStats, FrameOutcome};

/// The last frame's fit state and the corrections summed over the run.
#[derive(Debug, Default)]
pub struct PipelineState {
    fit: DepthFitState,
    fit_stats: FitStats,
    references_in_view: usize,
    boxes_corrected: u64,
    depths_corrected: u64,
}

impl Scorer for PipelineState {
    fn frame(&mut self, _truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        (self.fit, self.fit_stats, self.references_in_view) = (o.fit, o.fit_stats, o.references_in_view);
        self.boxes_corrected += u64::from(o.estimate.boxes_corrected);
        self.depths_corrected += u64::from(o.estimate.depths_corrected);
        Ok(())
    }

    fn finish(self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        let fits = self.fit_stats;
        report.scale_source = self.fit.source.name();
        report.fit_residual_m = (fits.residuals > 0).then(|| fits.residual_sum_m / fits.residuals as f64);
        report.fit_failures = fits.failures;
        report.references_visible = self.references_in_view;
        report.references_rejected = fits.rejected;
        report.boxes_corrected = self.boxes_corrected;
        report.depths_corrected = self.depths_corrected;
        Ok(())
    }
}
