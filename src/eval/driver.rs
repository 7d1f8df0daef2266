//! The evaluation driver: run the estimator over a sequence and score it against ground truth.

use std::collections::HashMap;

use super::live::{self, DetectionScore};
use super::metrics::{DepthAccuracy, bias, distance_correlation, quantile, rmse};
use super::relative::{RelativeGtParams, relative_at, sample_relative};
use super::{BoxProvider, BoxesChoice, EvalError};
use crate::geometry::{Pixel, PixelBox};
use crate::infer::{self, DepthNet, Detector, RelDepthMap, RgbFrame, SessionOptions};
pub use crate::metric::DepthSample;
use crate::metric::regressors::{Regressor, RegressorKind};
use crate::metric::{
    FitMethod, MapKind, ROBUST_INLIER, ReferencePair, ReferencePoints, References, RelativeMap, ScaleShift,
    sample_fish, sample_median,
};
use crate::mot::MotMetrics;
use crate::motion::{ActivityEstimator, MotionConfig, TrackObservation};
use crate::postprocess::PostprocessConfig;
use crate::sequence::{DepthMap, Sequence};
use crate::track::TrackerConfig;
use crate::units::Metres;
use std::io::Write;
use std::path::Path;

/// The `--depth` choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthChoice {
    /// Ground-truth depth maps from `depth/` (the paper's GTDepth).
    Gt,
    /// The depth network (`--depth-model`) on every frame, then the metric fit (eq. 1-2).
    Model,
    /// Ground-truth depth turned into noisy relative inverse depth, then the metric fit (eq. 1-2).
    RelativeGt,
}

/// The `--fit` choice (used with estimated depth).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FitChoice {
    /// The paper's eq. 2, `D = s*R + t`.
    Linear,
    /// `1/D = s*R + t`.
    Inverse,
    /// The inverse model fitted by exhaustive-pair RANSAC (survives fouled references).
    Robust,
    /// 2nd-order polynomial in R (Table 4).
    Poly2,
    /// Regression tree (Table 4).
    Tree,
    /// k-nearest neighbours (Table 4).
    Knn,
}

/// Everything `fme eval` can vary.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Box source.
    pub boxes: BoxesChoice,
    /// Depth source.
    pub depth: DepthChoice,
    /// Metric fit for estimated depth.
    pub fit: FitChoice,
    /// Post-processing of the main run (the raw run always has it off).
    pub postprocess: PostprocessConfig,
    /// Motion settings.
    pub motion: MotionConfig,
    /// Synthetic relative depth settings for `relative-gt`.
    pub relative: RelativeGtParams,
    /// Number of reference objects to foul in `relative-gt` (their R is made to look 50% nearer).
    pub foul_refs: usize,
    /// Radius of the median window used to sample depth maps (2 = 5x5).
    pub window_radius: usize,
    /// Inlier tolerance of the robust fit: max(absolute, relative * depth).
    pub robust_inlier: (Metres, f64),
    /// How fish depth is sampled.
    pub depth_sample: DepthSample,
    /// Detector for `--boxes model`.
    pub detector: infer::DetectorConfig,
    /// Depth network for `--depth model`.
    pub depth_model: infer::DepthConfig,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Tracker for `--boxes tracker|model`.
    pub tracker: TrackerConfig,
    /// Seed of the synthetic detections of `--boxes tracker` (when the sequence has no det/det.txt).
    pub det_seed: u64,
    /// Collect one [`TrackRow`] per fish and frame into [`EvalReport::tracks`] (`--tracks`).
    pub track_rows: bool,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            boxes: BoxesChoice::Gt,
            depth: DepthChoice::Gt,
            fit: FitChoice::Linear,
            postprocess: PostprocessConfig::default(),
            motion: MotionConfig::default(),
            relative: RelativeGtParams::default(),
            foul_refs: 0,
            window_radius: 2,
            robust_inlier: ROBUST_INLIER,
            depth_sample: DepthSample::Centre,
            detector: infer::DetectorConfig { class_agnostic: true, ..infer::DetectorConfig::default() },
            depth_model: infer::DepthConfig::default(),
            threads: 2,
            tracker: TrackerConfig::default_preset(),
            det_seed: 1,
            track_rows: false,
        }
    }
}

/// One frame of the series behind the plots (`--series`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SeriesRow {
    /// 1-based frame number.
    pub frame: u32,
    /// Timestamp, seconds.
    pub t: f64,
    /// Ground-truth swarm speed (mean |v| over visible fish) at the time the estimate refers to
    /// (`t - latency`, interpolated between frames), m/s.
    pub true_mps: Option<f64>,
    /// The same for the run without post-processing.
    pub true_raw_mps: Option<f64>,
    /// Estimated swarm speed (eq. 5) with post-processing as configured, m/s.
    pub est_mps: Option<f64>,
    /// Estimated swarm speed with post-processing off, m/s.
    pub est_raw_mps: Option<f64>,
    /// Fish in the estimated mean.
    pub n_fish: usize,
}

/// One tracked fish in one frame, as the estimator saw it (`--tracks`): what separates the speed
/// error into its lateral part (box motion at the fitted depth) and its along-ray part (depth change).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackRow {
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
    /// Metric fit (meaningful with estimated depth).
    pub fit: Option<FitChoice>,
    /// Post-processing on in the main run.
    pub postprocess: bool,
    /// How fish depth was sampled.
    pub depth_sample: DepthSample,
    /// Speed span, seconds (0 = frame to frame).
    pub speed_span_s: f64,
    /// Frames with both a true and an estimated swarm speed (the scored frames).
    pub frames: usize,
    /// RMSE of the estimated swarm speed, m/s.
    pub speed_rmse_mps: f64,
    /// Distance correlation of estimated and true swarm speed.
    pub speed_distcorr: f64,
    /// 2.5% and 97.5% quantiles of the per-frame error (estimated - true), m/s.
    pub error_ci95_mps: [f64; 2],
    /// Mean error (estimated - true), m/s.
    pub speed_bias_mps: f64,
    /// RMSE with post-processing off, m/s.
    pub speed_rmse_raw_mps: f64,
    /// Distance correlation with post-processing off.
    pub speed_distcorr_raw: f64,
    /// Mean true swarm speed over the scored frames, m/s.
    pub mean_true_mps: f64,
    /// Mean estimated swarm speed over the scored frames, m/s.
    pub mean_est_mps: f64,
    /// Mean number of fish in the estimated mean.
    pub mean_fish: f64,
    /// Mean latency of the estimate (the speeds refer to `t - latency`), seconds.
    pub latency_s: f64,
    /// Depth RMSE at fish box centres (estimated depth only), metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_rmse_m: Option<f64>,
    /// Fraction of fish centres with max(est/true, true/est) < 1.25.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_delta_1_25: Option<f64>,
    /// Same with 1.25^2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_delta_1_25_2: Option<f64>,
    /// With ground-truth boxes: depth RMSE against the camera z of each fish's body centre
    /// (`gt/world.csv`), whatever `depth_sample` reads; a surface sample is nearer than the body
    /// centre by about half the fish's thickness. Metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_rmse_m: Option<f64>,
    /// Same pairs: fraction with max(est/true, true/est) < 1.25.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_delta_1_25: Option<f64>,
    /// Fraction of the ground-truth boxes (with a `world.csv` row) that got a depth, i.e. that the
    /// body-centre score covers; `visible` sampling gives hidden fish none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_body_coverage: Option<f64>,
    /// Mean residual of the per-frame metric fits at the references, metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_residual_m: Option<f64>,
    /// Frames whose fit failed (the previous fit was kept).
    pub fit_failures: usize,
    /// References visible in the image (used by the fits).
    pub references_visible: usize,
    /// Total reference rejections by the robust fit over all frames.
    pub references_rejected: u64,
    /// Box corrections by eq. 3 in the main run.
    pub boxes_corrected: u64,
    /// Depth corrections by eq. 4 in the main run.
    pub depths_corrected: u64,
    /// Tracking quality of `--boxes tracker|model` against gt/gt.txt (IoU 0.5); its fields appear at
    /// the top level of the JSON (`idf1`, `mota`, `motp`, `id_switches`, ...).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub mot: Option<MotSummary>,
    /// Detection quality of `--boxes model` (IoU 0.5; fish under 50% visible are don't-care).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detection: Option<DetectionScore>,
    /// Per-frame series (written by `--series`, not part of the JSON).
    #[serde(skip)]
    pub series: Vec<SeriesRow>,
    /// Per-fish rows (collected with [`EvalOptions::track_rows`], written by `--tracks`).
    #[serde(skip)]
    pub tracks: Vec<TrackRow>,
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

/// A box source with its tracking and detection scores where computed here.
type BoxSource = (Box<dyn BoxProvider>, Option<MotSummary>, Option<DetectionScore>);

/// The box source of a run.
fn box_source(seq: &Sequence, opts: &EvalOptions) -> Result<BoxSource, EvalError> {
    match &opts.boxes {
        BoxesChoice::Tracker => {
            let det_file = seq.dir.join("det").join("det.txt");
            let dets = if det_file.is_file() {
                crate::mot::io::read_detections(&det_file, seq.len())?
            } else {
                live::synthetic_detections(seq, opts.det_seed)
            };
            let (b, m) = live::track(seq, opts.tracker, &dets, "tracker");
            Ok((Box::new(b), Some((&m).into()), None))
        }
        BoxesChoice::Model => {
            let model_err = |e: infer::InferError| EvalError::Model(format!("--det-model: {e}"));
            infer::runtime::environment().map_err(model_err)?;
            let so = SessionOptions { intra_threads: opts.threads, ..SessionOptions::default() };
            let mut detector = Detector::open(&opts.detector, so).map_err(model_err)?;
            let (dets, score) = live::model_detections(seq, &mut detector)?;
            let (b, m) = live::track(seq, opts.tracker, &dets, "model");
            Ok((Box::new(b), Some((&m).into()), Some(score)))
        }
        other => Ok((other.provider(seq)?, None, None)),
    }
}

/// Runs the depth network on frame `frame` of `seq`.
fn model_depth<'a>(seq: &Sequence, net: &'a mut DepthNet, frame: u32) -> Result<&'a RelDepthMap, EvalError> {
    let img = live::read_frame_rgb(seq, frame)?;
    net.estimate(&RgbFrame::from(&img), seq.timestamp(frame))
        .map_err(|e| EvalError::Input { path: seq.frame_path(frame), msg: e.to_string() })
}

enum Fitted {
    Ss(ScaleShift),
    Reg(Box<Regressor>),
}

impl Fitted {
    fn depth(&self, r: f64) -> Option<Metres> {
        match self {
            Self::Ss(f) => f.depth(r),
            Self::Reg(g) => g.depth(r),
        }
    }
}

fn fit_frame(opts: &EvalOptions, refs: &References) -> Result<Fitted, crate::metric::FitError> {
    Ok(match opts.fit {
        FitChoice::Linear => Fitted::Ss(FitMethod::Linear.fit(refs, opts.robust_inlier)?),
        FitChoice::Inverse => Fitted::Ss(FitMethod::Inverse.fit(refs, opts.robust_inlier)?),
        FitChoice::Robust => Fitted::Ss(FitMethod::Robust.fit(refs, opts.robust_inlier)?),
        FitChoice::Poly2 => Fitted::Reg(Box::new(Regressor::fit(RegressorKind::Poly2, refs)?)),
        FitChoice::Tree => Fitted::Reg(Box::new(Regressor::fit(RegressorKind::Tree, refs)?)),
        FitChoice::Knn => Fitted::Reg(Box::new(Regressor::fit(RegressorKind::Knn, refs)?)),
    })
}

fn to_metres(depth: &DepthMap, out: &mut Vec<f32>) {
    out.clear();
    out.extend(depth.mm.iter().map(|&mm| if mm == 0 { f32::NAN } else { f32::from(mm) / 1000.0 }));
}

/// Runs the evaluation. Reads frames' depth maps one at a time; memory is O(frames + pixels).
pub fn evaluate(seq: &Sequence, opts: &EvalOptions) -> Result<EvalReport, EvalError> {
    if !seq.has_depth {
        return Err(EvalError::Input {
            path: seq.dir.join("depth"),
            msg: "missing: the ground-truth depth maps are needed to score depth and speed".into(),
        });
    }
    let mut depth_net = match opts.depth {
        DepthChoice::Model => {
            let model_err = |e: infer::InferError| EvalError::Model(format!("--depth-model: {e}"));
            infer::runtime::environment().map_err(model_err)?;
            let so = SessionOptions { intra_threads: opts.threads, ..SessionOptions::default() };
            Some(DepthNet::open(&opts.depth_model, so).map_err(model_err)?)
        }
        _ => None,
    };
    let (mut provider, mot, detection) = box_source(seq, opts)?;
    let estimated = opts.depth != DepthChoice::Gt;
    let (w, h) = (seq.meta.width as usize, seq.meta.height as usize);
    // Reference points: projected once (the camera is fixed); hidden ones are left out.
    let faces = seq.meta.reference_objects.iter().map(|r| r.front_face_center());
    let ref_px = ReferencePoints::project(&seq.camera, faces, seq.meta.width, seq.meta.height);
    // True swarm speed per frame: mean |v| of the fish visible in it.
    let mut true_sum = vec![(0.0f64, 0usize); seq.len() as usize + 1];
    for r in &seq.world {
        if r.visibility > 0.0
            && r.velocity.iter().all(|v| v.is_finite())
            && let Some(s) = true_sum.get_mut(r.frame as usize)
        {
            s.0 += r.velocity.norm();
            s.1 += 1;
        }
    }
    let mut est = ActivityEstimator::new(seq.camera, opts.motion, opts.postprocess);
    let mut est_raw = ActivityEstimator::new(seq.camera, opts.motion, PostprocessConfig::off());
    let mut boxes: Vec<(u32, PixelBox)> = Vec::new();
    let mut obs: Vec<TrackObservation> = Vec::new();
    let mut gt_map = Vec::new();
    let mut depth_acc = DepthAccuracy::default();
    let (mut body_acc, mut body_boxes) = (DepthAccuracy::default(), 0usize);
    // Camera z of each fish's body centre by (frame, id): ground-truth boxes carry world.csv's ids.
    let body_z: HashMap<(u32, u32), f64> = if estimated && opts.boxes == BoxesChoice::Gt {
        seq.world.iter().map(|r| ((r.frame, r.id), seq.camera.pose.to_camera(&r.position).depth().0)).collect()
    } else {
        HashMap::new()
    };
    let mut last_fit: Option<Fitted> = None;
    let (mut fit_failures, mut rejected, mut residual_sum, mut residual_n) = (0usize, 0u64, 0.0, 0usize);
    let (mut boxes_corrected, mut depths_corrected) = (0u64, 0u64);
    let mut series = Vec::with_capacity(seq.len() as usize);
    let mut latencies = Vec::with_capacity(seq.len() as usize);
    let mut tracks = Vec::new();
    let radius = opts.window_radius;
    for frame in 1..=seq.len() {
        let t = seq.timestamp(frame);
        provider.frame_boxes(frame, &mut boxes)?;
        let dm = seq.read_depth(frame)?;
        if (dm.width as usize, dm.height as usize) != (w, h) {
            return Err(EvalError::Input {
                path: seq.depth_path(frame),
                msg: format!("depth map is {}x{}, the sequence is {w}x{h}", dm.width, dm.height),
            });
        }
        to_metres(&dm, &mut gt_map);
        let gt = RelativeMap { data: &gt_map, width: w, height: h };
        let map: Option<&RelDepthMap> = match depth_net.as_mut() {
            Some(net) => Some(model_depth(seq, net, frame)?),
            None => None,
        };
        // Relative inverse depth at a pixel: the network's map, or ground truth made relative.
        // (The network's map is sampled with its own window, `depth.sample_radius` map pixels.)
        let rel = |px: Pixel| -> Option<f64> {
            match map {
                Some(m) => m.sample(px).map(f64::from),
                None => sample_relative(&opts.relative, &dm, frame, px, radius),
            }
        };
        if estimated {
            let mut refs = References::new();
            for (i, (px, depth)) in ref_px.iter().enumerate() {
                if let Some(mut r) = rel(px) {
                    if i < opts.foul_refs {
                        r *= 1.5;
                    }
                    let _ = refs.push(ReferencePair { relative: r, depth });
                }
            }
            match fit_frame(opts, &refs) {
                Ok(f) => {
                    if let Fitted::Ss(s) = &f {
                        residual_sum += s.residual_rms.0;
                        residual_n += 1;
                        rejected += u64::from(s.rejected.count_ones());
                    }
                    last_fit = Some(f);
                }
                Err(_) => fit_failures += 1,
            }
        }
        obs.clear();
        obs.extend(boxes.iter().map(|&(id, bbox)| TrackObservation { id, bbox, depth: None }));
        // The other fish's boxes (what may cover `o` for `DepthSample::Visible`).
        let others = |id: u32| obs.iter().filter(move |x| x.id != id).map(|x| &x.bbox);
        // Ground truth in metres in `bbox`, or at its centre with the paper's window.
        let gt_at = |o: &TrackObservation, bbox: &PixelBox| {
            let c = bbox.center();
            sample_fish(
                opts.depth_sample,
                MapKind::Depth,
                bbox,
                others(o.id),
                || sample_median(&gt, c, radius, |_| true),
                |p| gt.at(p),
            )
        };
        let depth_at = |o: &TrackObservation, px: Pixel| -> Option<Metres> {
            let b = PixelBox::from_center(px, o.bbox.w, o.bbox.h);
            if !estimated {
                return gt_at(o, &b).map(Metres);
            }
            // Relative inverse depth of the network or of ground truth at one grid point.
            let rel_at = |p| match map {
                Some(m) => m.sample_with_radius(p, 0).map(f64::from),
                None => relative_at(&opts.relative, &dm, frame, p),
            };
            let r = sample_fish(opts.depth_sample, MapKind::InverseDepth, &b, others(o.id), || rel(px), rel_at)?;
            last_fit.as_ref()?.depth(r)
        };
        if estimated {
            for o in &obs {
                let c = o.bbox.center();
                // Ground truth read the same way as the estimate (the same pixels).
                let g = gt_at(o, &o.bbox);
                let e = depth_at(o, c);
                if let (Some(e), Some(g)) = (e, g) {
                    depth_acc.add(e.0, g);
                }
                if let Some(&z) = body_z.get(&(frame, o.id)) {
                    body_boxes += 1;
                    if let Some(e) = e {
                        body_acc.add(e.0, z);
                    }
                }
            }
        }
        let s = est.update_with(t, &obs, &depth_at);
        if opts.track_rows {
            tracks.extend(est.tracks().filter(|v| v.last_seen == t).map(|v| TrackRow {
                frame,
                t: t.0,
                id: v.id,
                centre: v.bbox.center(),
                size: (v.bbox.w, v.bbox.h),
                depth_raw_m: v.depth_measured.map(|d| d.0),
                depth_m: v.depth.map(|d| d.0),
                speed_mps: v.speed.map(|s| s.0),
            }));
        }
        let s_raw = est_raw.update_with(t, &obs, &depth_at);
        boxes_corrected += u64::from(s.boxes_corrected);
        depths_corrected += u64::from(s.depths_corrected);
        series.push(SeriesRow {
            frame,
            t: t.0,
            true_mps: None,
            true_raw_mps: None,
            est_mps: s.mean.map(|m| m.0),
            est_raw_mps: s_raw.mean.map(|m| m.0),
            n_fish: s.n_fish,
        });
        latencies.push((s.latency.0, s_raw.latency.0));
    }
    // Truth at the time each estimate refers to (`ActivitySample::latency`), interpolated between frames.
    let truth_frame: Vec<Option<f64>> = true_sum.iter().map(|&(ts, tn)| (tn > 0).then(|| ts / tn as f64)).collect();
    let fps = seq.meta.fps;
    let truth_at = |tq: f64| -> Option<f64> {
        let pos = tq * fps + 1.0;
        let f0 = pos.floor();
        if f0.is_nan() || f0 < 1.0 {
            return None;
        }
        let w = pos - f0;
        let a = truth_frame.get(f0 as usize).copied().flatten();
        let b = truth_frame.get(f0 as usize + 1).copied().flatten();
        match (a, b) {
            (Some(a), Some(b)) => Some(a + w * (b - a)),
            (Some(a), None) if w < 0.5 => Some(a),
            (None, Some(b)) if w >= 0.5 => Some(b),
            _ => None,
        }
    };
    for (r, &(lat, lat_raw)) in series.iter_mut().zip(&latencies) {
        r.true_mps = if r.est_mps.is_some() { truth_at(r.t - lat) } else { truth_frame[r.frame as usize] };
        r.true_raw_mps = if r.est_raw_mps.is_some() { truth_at(r.t - lat_raw) } else { truth_frame[r.frame as usize] };
    }
    let scored: Vec<&SeriesRow> = series.iter().filter(|r| r.true_mps.is_some() && r.est_mps.is_some()).collect();
    if scored.len() < 2 {
        return Err(EvalError::NothingToScore(format!(
            "{}: only {} frame(s) have both a true and an estimated swarm speed (boxes from {}, {} boxes in total)",
            seq.dir.display(),
            scored.len(),
            provider.name(),
            seq.gt.len()
        )));
    }
    let truth: Vec<f64> = scored.iter().filter_map(|r| r.true_mps).collect();
    let est_v: Vec<f64> = scored.iter().filter_map(|r| r.est_mps).collect();
    let raw_pairs: Vec<(f64, f64)> =
        series.iter().filter_map(|r| Some((r.est_raw_mps?, r.true_raw_mps?))).collect::<Vec<_>>();
    let (raw_e, raw_t): (Vec<f64>, Vec<f64>) = raw_pairs.into_iter().unzip();
    let errors: Vec<f64> = est_v.iter().zip(&truth).map(|(e, t)| e - t).collect();
    let n = scored.len() as f64;
    Ok(EvalReport {
        sequence: seq.dir.display().to_string(),
        boxes: provider.name(),
        depth: opts.depth,
        fit: estimated.then_some(opts.fit),
        postprocess: opts.postprocess.box_fluctuation || opts.postprocess.depth_jump,
        depth_sample: opts.depth_sample,
        speed_span_s: opts.motion.speed_span.0,
        frames: scored.len(),
        speed_rmse_mps: rmse(&est_v, &truth).unwrap_or(f64::NAN),
        speed_distcorr: distance_correlation(&est_v, &truth).unwrap_or(0.0),
        error_ci95_mps: [quantile(&errors, 0.025).unwrap_or(0.0), quantile(&errors, 0.975).unwrap_or(0.0)],
        speed_bias_mps: bias(&est_v, &truth).unwrap_or(0.0),
        speed_rmse_raw_mps: rmse(&raw_e, &raw_t).unwrap_or(f64::NAN),
        speed_distcorr_raw: distance_correlation(&raw_e, &raw_t).unwrap_or(0.0),
        mean_true_mps: truth.iter().sum::<f64>() / n,
        mean_est_mps: est_v.iter().sum::<f64>() / n,
        mean_fish: scored.iter().map(|r| r.n_fish as f64).sum::<f64>() / n,
        // Over the frames with an estimate (a frame without one has no latency).
        latency_s: series.iter().zip(&latencies).filter(|(r, _)| r.est_mps.is_some()).map(|(_, l)| l.0).sum::<f64>()
            / series.iter().filter(|r| r.est_mps.is_some()).count().max(1) as f64,
        depth_rmse_m: depth_acc.rmse(),
        depth_delta_1_25: depth_acc.delta_1_25(),
        depth_delta_1_25_2: depth_acc.delta_1_25_2(),
        depth_body_rmse_m: body_acc.rmse(),
        depth_body_delta_1_25: body_acc.delta_1_25(),
        depth_body_coverage: (body_boxes > 0).then(|| body_acc.count() as f64 / body_boxes as f64),
        fit_residual_m: (residual_n > 0).then(|| residual_sum / residual_n as f64),
        fit_failures,
        references_visible: ref_px.len(),
        references_rejected: rejected,
        boxes_corrected,
        depths_corrected,
        mot,
        detection,
        series,
        tracks,
    })
}

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

/// Writes the per-frame series as CSV with header `frame,t,true_mps,est_mps,n_fish` (empty field
/// where a value is missing).
pub fn write_series(path: &Path, series: &[SeriesRow]) -> Result<(), EvalError> {
    write_csv(path, "frame,t,true_mps,est_mps,n_fish", series, |out, r| {
        writeln!(out, "{},{},{},{},{}", r.frame, r.t, csv_opt(r.true_mps), csv_opt(r.est_mps), r.n_fish)
    })
}

/// Writes the per-fish rows as CSV with header `frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps`
/// (empty field where a value is missing).
pub fn write_tracks(path: &Path, rows: &[TrackRow]) -> Result<(), EvalError> {
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
