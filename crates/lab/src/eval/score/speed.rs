//! The activity index against the true swarm speed (paper sec. 4.5): RMSE, distance correlation,
//! error interval and bias in m/s and body lengths/s, with the truth taken at the time each
//! estimate refers to (`t - latency`, interpolated between frames); and the published activity.

use super::{FrameTruth, Scorer};
use crate::eval::metrics::{bias, distance_correlation, quantile, rmse};
use crate::eval::report::ScoredRow;
use crate::eval::{EvalError, EvalReport};
use fme_core::pipeline::{ActivitySample, FrameOutcome};
use fme_edge::sequence::{Sequence, SeriesRow};

/// The true swarm speed per frame and the series of samples.
#[derive(Debug)]
pub struct SpeedScorer {
    /// Mean |v| of the fish visible in each frame (index = 1-based frame), m/s.
    true_mps: Vec<Option<f64>>,
    /// Mean |v| / length, where world.csv has the fish's lengths, BL/s.
    true_bls: Vec<Option<f64>>,
    fps: f64,
    has_truth: bool,
    /// For the "nothing to score" message: the sequence, the box source, its box count.
    context: (String, String, usize),
    series: Vec<ScoredRow>,
}

impl SpeedScorer {
    /// Reads the truth of `seq` (`gt/world.csv`); `boxes`: the box source's name, for messages.
    pub fn new(seq: &Sequence, boxes: &str) -> Self {
        let mut sum = vec![(0.0f64, 0usize); seq.len() as usize + 1];
        let mut bls = vec![(0.0f64, 0usize); seq.len() as usize + 1];
        for r in &seq.world {
            if r.visibility > 0.0
                && r.velocity.iter().all(|v| v.is_finite())
                && let Some(s) = sum.get_mut(r.frame as usize)
            {
                s.0 += r.velocity.norm();
                s.1 += 1;
                if r.length.0.is_finite()
                    && r.length.0 > 0.0
                    && let Some(b) = bls.get_mut(r.frame as usize)
                {
                    b.0 += r.velocity.norm() / r.length.0;
                    b.1 += 1;
                }
            }
        }
        let mean = |v: Vec<(f64, usize)>| v.iter().map(|&(s, n)| (n > 0).then(|| s / n as f64)).collect();
        Self {
            true_mps: mean(sum),
            true_bls: mean(bls),
            fps: seq.info.frame_rate,
            has_truth: !seq.world.is_empty(),
            context: (seq.dir.display().to_string(), boxes.to_string(), seq.gt.len()),
            series: Vec::with_capacity(seq.len() as usize),
        }
    }

    /// The truth at time `tq`, interpolated between frames.
    fn truth_at(&self, per_frame: &[Option<f64>], tq: f64) -> Option<f64> {
        let pos = tq * self.fps + 1.0;
        let f0 = pos.floor();
        if f0.is_nan() || f0 < 1.0 {
            return None;
        }
        let w = pos - f0;
        let a = per_frame.get(f0 as usize).copied().flatten();
        let b = per_frame.get(f0 as usize + 1).copied().flatten();
        match (a, b) {
            (Some(a), Some(b)) => Some(a + w * (b - a)),
            (Some(a), None) if w < 0.5 => Some(a),
            (None, Some(b)) if w >= 0.5 => Some(b),
            _ => None,
        }
    }

    /// Each row's truth: at the time its estimate refers to, and at the frame itself.
    fn attach_truth(&mut self) {
        for i in 0..self.series.len() {
            let r = self.series[i];
            let now = self.true_mps.get(r.row.frame as usize).copied().flatten();
            let at =
                if r.est_mps().is_some() { self.truth_at(&self.true_mps, r.t() - r.row.sample.latency.0) } else { now };
            (self.series[i].true_now_mps, self.series[i].true_mps) = (now, at);
        }
    }
}

impl Scorer for SpeedScorer {
    fn frame(&mut self, truth: &FrameTruth<'_>, o: &FrameOutcome<'_>) -> Result<(), EvalError> {
        if let Some(sample) = o.sample {
            let row = SeriesRow { frame: u64::from(truth.frame), sample };
            self.series.push(ScoredRow { row, true_mps: None, true_now_mps: None });
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>, report: &mut EvalReport) -> Result<(), EvalError> {
        self.attach_truth();
        let s = &self.series;
        // Body lengths per second: the published value against the truth at the time it refers to.
        let (bls_e, bls_t): (Vec<f64>, Vec<f64>) = s
            .iter()
            .filter_map(|r| {
                let e = r.row.sample.mean_body_lengths;
                let t = self.truth_at(&self.true_bls, r.t() - r.row.sample.latency.0)?;
                e.is_finite().then_some((e, t))
            })
            .unzip();
        let scored: Vec<&ScoredRow> = s.iter().filter(|r| r.true_mps.is_some() && r.est_mps().is_some()).collect();
        if self.has_truth && scored.len() < 2 {
            let (dir, boxes, n_boxes) = &self.context;
            return Err(EvalError::NothingToScore(format!(
                "{dir}: only {} frame(s) have both a true and an estimated swarm speed (boxes from {boxes}, {n_boxes} boxes in total)",
                scored.len()
            )));
        }
        let truth: Vec<f64> = scored.iter().filter_map(|r| r.true_mps).collect();
        let est: Vec<f64> = scored.iter().filter_map(|r| r.est_mps()).collect();
        let (now_e, now_t): (Vec<f64>, Vec<f64>) =
            s.iter().filter_map(|r| Some((r.est_mps()?, r.true_now_mps?))).unzip();
        let errors: Vec<f64> = est.iter().zip(&truth).map(|(e, t)| e - t).collect();
        let n = scored.len() as f64;
        report.frames = scored.len();
        report.speed_rmse_mps = rmse(&est, &truth).unwrap_or(f64::NAN);
        report.speed_rmse_now_mps = rmse(&now_e, &now_t).unwrap_or(f64::NAN);
        report.speed_distcorr = distance_correlation(&est, &truth).unwrap_or(0.0);
        report.bls_rmse = rmse(&bls_e, &bls_t);
        report.bls_distcorr = distance_correlation(&bls_e, &bls_t);
        report.bls_bias = bias(&bls_e, &bls_t);
        report.error_ci95_mps = [quantile(&errors, 0.025).unwrap_or(0.0), quantile(&errors, 0.975).unwrap_or(0.0)];
        report.speed_bias_mps = bias(&est, &truth).unwrap_or(0.0);
        report.mean_true_mps = truth.iter().sum::<f64>() / n;
        report.mean_est_mps = est.iter().sum::<f64>() / n;
        report.mean_fish = scored.iter().map(|r| f64::from(r.row.sample.fish)).sum::<f64>() / n;
        // Over the frames with an estimate (a frame without one has no latency).
        let with_est: Vec<&ActivitySample> =
            s.iter().filter(|r| r.est_mps().is_some()).map(|r| &r.row.sample).collect();
        report.latency_s = with_est.iter().map(|s| s.latency.0).sum::<f64>() / with_est.len().max(1) as f64;
        published_activity(s, report);
        if !self.has_truth {
            // No world.csv: the speed is not scored (NaN is `null` in the JSON).
            report.speed_distcorr = f64::NAN;
            report.error_ci95_mps = [f64::NAN; 2];
            report.speed_bias_mps = f64::NAN;
        }
        report.series = self.series;
        Ok(())
    }
}

/// The mean published activity, scored or not (a sequence without truth still has one).
fn published_activity(series: &[ScoredRow], report: &mut EvalReport) {
    let activity: Vec<&ActivitySample> =
        series.iter().map(|r| &r.row.sample).filter(|s| s.mean.0.is_finite()).collect();
    let mean_of = |f: fn(&ActivitySample) -> f64| -> f64 {
        let v: Vec<f64> = activity.iter().map(|s| f(s)).filter(|x| x.is_finite()).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    };
    report.activity_frames = activity.len();
    report.mean_activity_mps = mean_of(|s| s.mean.0);
    report.mean_activity_bls = mean_of(|s| s.mean_body_lengths);
}
