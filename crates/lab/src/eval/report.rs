//! The scores of one evaluation and its per-frame rows.

use super::live::DetectionScore;
use super::options::DepthChoice;
use crate::mot::MotMetrics;
use fme_core::geometry::Pixel;
use fme_core::metric::{DepthSample, FitMethod};
use fme_edge::sequence::SeriesRow;

/// One frame of the scored series (`--series`): the pipeline's sample and the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoredRow {
    /// The frame and the sample the pipeline computed on it (what `fme run --series` writes).
    pub row: SeriesRow,
    /// Ground-truth swarm speed (mean |v| over visible fish) at the time the estimate refers to
    /// (`t - latency`, interpolated between frames), m/s.
    pub true_mps: Option<f64>,
    /// Ground-truth swarm speed at the frame itself, m/s (what a PLC reading the value now compares to).
    pub true_now_mps: Option<f64>,
}

impl ScoredRow {
    /// The estimate, when there is one.
    pub fn est_mps(&self) -> Option<f64> {
        let m = self.row.sample.mean.0;
        m.is_finite().then_some(m)
    }
    /// Timestamp, s.
    pub fn t(&self) -> f64 {
        self.row.sample.timestamp.0
    }
}

/// One tracked fish in one frame, as the estimator saw it (`--tracks`): what separates the speed
/// error into its lateral part (box motion at the fitted depth) and its along-ray part (depth change).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FishRow {
    /// 1-based frame number.
    pub frame: u32,
    /// Timestamp, seconds.
    pub t: f64,
    /// Track id (ground-truth id with `--boxes gt`).
    pub id: u32,
    /// Centre of the box after eq. 3, pixels.
    pub centre: Pixel,
    /// Width and height of that box, pixels.
    pub size: (f64, f64),
    /// Depth as sampled and fitted, before eq. 4 and the depth smoothing, metres.
    pub depth_raw_m: Option<f64>,
    /// Depth the speed used (after eq. 4 and the smoothing), metres.
    pub depth_m: Option<f64>,
    /// The fish's speed at this frame, m/s.
    pub speed_mps: Option<f64>,
}

/// The scores of one evaluation (`--json` prints this).
#[derive(Debug, Clone, serde::Serialize)]
pub struct EvalReport {
    /// Sequence folder.
    pub sequence: String,
    /// Box source.
    pub boxes: String,
    /// Depth source.
    pub depth: DepthChoice,
    /// Metric fit (`depth.fit`; meaningful with estimated depth).
    pub fit: Option<FitMethod>,
    /// Post-processing (eq. 3 or eq. 4) on.
    pub postprocess: bool,
    /// How fish depth was sampled (`depth.sample`).
    pub depth_sample: DepthSample,
    /// Detector and depth-network rates, Hz (0 = every frame).
    pub rates_hz: [f64; 2],
    /// Speed span, seconds (0 = frame to frame).
    pub speed_span_s: f64,
    /// Frames with both a true and an estimated swarm speed (the scored frames).
    pub frames: usize,
    /// RMSE of the estimated swarm speed against the truth at the time it refers to (`t - latency`), m/s.
    pub speed_rmse_mps: f64,
    /// RMSE against the truth at the frame itself (what the PLC compares with when it reads now), m/s.
    pub speed_rmse_now_mps: f64,
    /// Distance correlation of estimated and true swarm speed.
    pub speed_distcorr: f64,
    /// RMSE of the published body lengths/s against the truth (each fish's speed over its own length,
    /// `gt/world.csv`), at the time the estimate refers to; `None` without lengths in the truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bls_rmse: Option<f64>,
    /// Distance correlation of estimated and true body lengths/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bls_distcorr: Option<f64>,
    /// Mean error of body lengths/s (estimated - true).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bls_bias: Option<f64>,
    /// What set the metric scale at the end (`depth.scale`): "references", "fish" or "none".
    pub scale_source: &'static str,
    /// 2.5% and 97.5% quantiles of the per-frame error (estimated - true), m/s.
    pub error_ci95_mps: [f64; 2],
    /// Mean error (estimated - true), m/s.
    pub speed_bias_mps: f64,
    /// Mean true swarm speed over the scored frames, m/s.
    pub mean_true_mps: f64,
    /// Mean estimated swarm speed over the scored frames, m/s.
    pub mean_est_mps: f64,
    /// Mean number of fish in the estimated mean.
    pub mean_fish: f64,
    /// Mean latency of the estimate (the speeds refer to `t - latency`), seconds.
    pub latency_s: f64,
    /// Pipeline CPU time per frame (process-wide, around `FishPipeline::process`), ms.
    pub cpu_ms_per_frame: f64,
    /// Depth RMSE at fish (estimated depth only, ground truth read the same way), metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_rmse_m: Option<f64>,
    /// Share of the output updates (at `output.rate_hz` on frame time) with the "detections look
    /// unlike fish" flag raised (`[familiarity]`, status bit 10).
    pub unlike_fish_share: f64,
    /// The least and greatest value of each familiarity statistic over the judged windows.
    pub familiarity: fme_core::familiarity::StatRanges,
    /// Fraction of fish with max(est/true, true/est) < 1.25.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_delta_1_25: Option<f64>,
    /// Same with 1.25^2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_delta_1_25_2: Option<f64>,
    /// With ground-truth boxes: depth RMSE against the camera z of each fish's body centre
    /// (`gt/world.csv`), whatever `depth.sample` reads. Metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_rmse_m: Option<f64>,
    /// Same pairs: fraction with max(est/true, true/est) < 1.25.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_delta_1_25: Option<f64>,
    /// Fraction of the ground-truth boxes (with a `world.csv` row) that got a depth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_coverage: Option<f64>,
    /// Mean RMS residual of the metric fits at the references, metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_residual_m: Option<f64>,
    /// Depth frames whose fit failed (the previous fit was kept).
    pub fit_failures: u64,
    /// References visible in the image (used by the fits).
    pub references_visible: usize,
    /// Total reference rejections by the robust fit over all fits.
    pub references_rejected: u64,
    /// Box corrections by eq. 3.
    pub boxes_corrected: u64,
    /// Depth corrections by eq. 4.
    pub depths_corrected: u64,
    /// Frames with an activity estimate (whether or not there is truth to score it against).
    pub activity_frames: usize,
    /// Mean published activity over [`Self::activity_frames`], m/s.
    pub mean_activity_mps: f64,
    /// Mean published activity over [`Self::activity_frames`], body lengths per second.
    pub mean_activity_bls: f64,
    /// Mean per-frame Spearman correlation between the depth network's relative inverse depth at each
    /// true box (3x3 median of the map at its centre) and the box's long side, over boxes inside the
    /// frame: a nearer fish looks longer, so +1 is a depth map that orders the fish as their sizes
    /// do. With `--depth model` and `gt/gt.txt`, on the frames where the depth network ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_consistency: Option<f64>,
    /// Frames averaged in [`Self::depth_consistency`] (frames with at least 3 boxes and no full tie).
    pub depth_consistency_frames: usize,
    /// Each score this run cannot give, and why (no truth for it, or a stage it replaced).
    pub absent: Vec<String>,
    /// Tracking quality of the pipeline's tracks against gt/gt.txt (IoU 0.5); its fields appear at
    /// the top level of the JSON (`idf1`, `mota`, `motp`, `id_switches`, ...).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub mot: Option<MotSummary>,
    /// Detection quality of the pipeline's detector (IoU 0.5; fish under 50% visible are don't-care).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detection: Option<DetectionScore>,
    /// Per-frame series (written by `--series`, not part of the JSON).
    #[serde(skip)]
    pub series: Vec<ScoredRow>,
    /// Per-fish rows (collected with [`EvalOptions::track_rows`], written by `--tracks`).
    #[serde(skip)]
    pub tracks: Vec<FishRow>,
}

/// MOT metrics of the tracked boxes (MOTChallenge conventions, IoU 0.5).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MotSummary {
    /// IDF1.
    pub idf1: f64,
    /// MOTA.
    pub mota: f64,
    /// MOTP (mean IoU distance of matches, as py-motmetrics).
    pub motp: f64,
    /// HOTA.
    pub hota: f64,
    /// Identity switches.
    pub id_switches: u64,
    /// False positives.
    pub false_positives: u64,
    /// Misses.
    pub misses: u64,
}

impl From<&MotMetrics> for MotSummary {
    fn from(m: &MotMetrics) -> Self {
        Self {
            idf1: m.idf1,
            mota: m.mota,
            motp: m.motp,
            hota: m.hota,
            id_switches: m.num_switches,
            false_positives: m.num_false_positives,
            misses: m.num_misses,
        }
    }
}

impl EvalReport {
    /// A report of the run on `sequence` with boxes from `boxes` and depth from `depth`, and every
    /// score still to come (each scorer fills its own); the caller sets what the run is (`fit`,
    /// `postprocess`, `depth_sample`, `rates_hz`, `speed_span_s`, `absent`).
    pub fn blank(sequence: String, boxes: String, depth: DepthChoice) -> Self {
        let nan = f64::NAN;
        Self {
            sequence,
            boxes,
            depth,
            fit: None,
            postprocess: false,
            depth_sample: DepthSample::Centre,
            rates_hz: [nan; 2],
            speed_span_s: nan,
            frames: 0,
            speed_rmse_mps: nan,
            speed_rmse_now_mps: nan,
            speed_distcorr: nan,
            bls_rmse: None,
            bls_distcorr: None,
            bls_bias: None,
            scale_source: "none",
            error_ci95_mps: [nan; 2],
            speed_bias_mps: nan,
            mean_true_mps: nan,
            mean_est_mps: nan,
            mean_fish: nan,
            latency_s: nan,
            cpu_ms_per_frame: nan,
            depth_rmse_m: None,
            unlike_fish_share: 0.0,
            familiarity: Default::default(),
            depth_delta_1_25: None,
            depth_delta_1_25_2: None,
            depth_body_rmse_m: None,
            depth_body_delta_1_25: None,
            depth_body_coverage: None,
            fit_residual_m: None,
            fit_failures: 0,
            references_visible: 0,
            references_rejected: 0,
            boxes_corrected: 0,
            depths_corrected: 0,
            activity_frames: 0,
            mean_activity_mps: nan,
            mean_activity_bls: nan,
            depth_consistency: None,
            depth_consistency_frames: 0,
            absent: Vec::new(),
            mot: None,
            detection: None,
            series: Vec::new(),
            tracks: Vec::new(),
        }
    }
}
