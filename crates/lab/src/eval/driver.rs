//! The evaluation driver: the daemon's own pipeline ([`FishPipeline`]) over a recording, with ground
//! truth swapped in where asked, scored against ground truth.
//!
//! The frames come from the same recorded source `fme run` replays (`capture::RecordedSource`, as
//! fast as possible, no loop) and go through [`FishPipeline`] with the one [`Config`]: the same
//! reduced-rate schedule on frame time, depth sampling, fit, smoothing and `min_age`. The scoring
//! taps read the pipeline's outputs after each frame, so what is scored is what the PLC receives.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use super::boxes::IndexedBoxes;
use super::consistency::{DepthConsistency, inside_frame};
use super::inputs::{BoxInput, DepthInput, GT_WINDOW, GroundTruth, to_metres};
use super::live::{self, DetectionScore};
use super::metrics::{DepthAccuracy, bias, distance_correlation, quantile, rmse};
use super::relative::RelativeGtParams;
use super::{BoxesChoice, EvalError};
use crate::mot::{MotAccumulator, MotMetrics};
use fme_core::geometry::Pixel;
use fme_core::metric::{DepthSample, FitMethod, MapKind, ReferencePoints, RelativeMap, sample_fish, sample_median};
use fme_core::pipeline::{ActivitySample, FishPipeline, Pipeline};
use fme_edge::capture::{CaptureError, FrameSource, RecordedSource};
use fme_edge::config::Config;
use fme_edge::sequence::Sequence;
use fme_edge::sequence::SeriesRow;

/// The `--depth` choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthChoice {
    /// Ground-truth depth maps from `depth/` (the paper's GTDepth), on the depth network's schedule.
    Gt,
    /// The pipeline's depth network and metric fit (eq. 1-2).
    Model,
    /// Ground-truth depth turned into noisy relative inverse depth, then the metric fit (eq. 1-2).
    RelativeGt,
}

/// What `fme eval` swaps in and collects; everything else is the [`Config`].
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Box source.
    pub boxes: BoxesChoice,
    /// Depth source.
    pub depth: DepthChoice,
    /// Synthetic relative depth settings for `relative-gt`.
    pub relative: RelativeGtParams,
    /// Number of reference objects to foul in `relative-gt` (their R is made to look 50% nearer).
    pub foul_refs: usize,
    /// Seed of the synthetic detections of `--boxes tracker` (when the sequence has no det/det.txt).
    pub det_seed: u64,
    /// Collect one [`FishRow`] per fish and frame into [`EvalReport::tracks`] (`--tracks`).
    pub track_rows: bool,
    /// Run without the sequence's calibration (`--no-calibration`): the board default camera, the fish
    /// as the ruler.
    pub no_calibration: bool,
    /// Hide the first N reference objects from T seconds on (`--hide-refs N@T`).
    pub hide_refs: Option<(usize, f64)>,
    /// Make the recorded positions of the first N reference objects wrong from T seconds on
    /// (`--move-refs N@T`).
    pub move_refs: Option<(usize, f64)>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            boxes: BoxesChoice::Gt,
            depth: DepthChoice::Gt,
            relative: RelativeGtParams::default(),
            foul_refs: 0,
            det_seed: 1,
            track_rows: false,
            no_calibration: false,
            hide_refs: None,
            move_refs: None,
        }
    }
}

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

/// Process CPU time (user + system) so far, seconds; `None` where /proc is not readable.
fn process_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = s.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// The box input of a run.
fn box_input(seq: &Sequence, opts: &EvalOptions) -> Result<BoxInput, EvalError> {
    Ok(match &opts.boxes {
        BoxesChoice::Gt => BoxInput::Tracks(IndexedBoxes::ground_truth(seq)),
        BoxesChoice::File(p) => BoxInput::Tracks(IndexedBoxes::from_mot_file(p, seq.len())?),
        BoxesChoice::Model => BoxInput::Pipeline,
        BoxesChoice::Tracker => {
            let det_file = seq.dir.join("det").join("det.txt");
            BoxInput::Detections(if det_file.is_file() {
                fme_edge::sequence::mot_text::read_detections(&det_file, seq.len())?
            } else {
                live::synthetic_detections(seq, opts.det_seed)
            })
        }
    })
}

/// Runs the evaluation: the pipeline over every frame of `seq` with `cfg`, scored.
pub fn evaluate(seq: &Sequence, cfg: &Config, opts: &EvalOptions) -> Result<EvalReport, EvalError> {
    // A recording labelled with boxes only (no `depth/`, no `gt/world.csv`) is scored for tracking
    // and detection, with the pipeline's own depth; ground-truth depth needs the maps.
    if !seq.has_depth && opts.depth != DepthChoice::Model {
        return Err(EvalError::Input {
            path: seq.dir.join("depth"),
            msg: "missing: --depth gt and relative-gt need the ground-truth depth maps (use --depth model)".into(),
        });
    }
    if !seq.has_gt && (opts.boxes == BoxesChoice::Gt || opts.boxes == BoxesChoice::Tracker) {
        return Err(EvalError::Input {
            path: seq.dir.join("gt").join("gt.txt"),
            msg: "missing: --boxes gt and tracker need the ground-truth boxes (use --boxes model)".into(),
        });
    }
    let speed_truth = !seq.world.is_empty();
    let mut cfg = cfg.clone();
    cfg.source.path = seq.dir.clone();
    cfg.source.realtime = false;
    cfg.source.looping = false;
    // The recording's size (the uncalibrated camera is a 90 degree view of it).
    (cfg.source.width, cfg.source.height) = (seq.info.im_width, seq.info.im_height);
    let calibration = if opts.no_calibration {
        cfg.camera.calibration = std::path::PathBuf::new();
        if cfg.motion.body_length().is_some() {
            cfg.depth.scale = fme_core::metric::DepthScale::Fish;
        }
        None
    } else {
        cfg.calibration().map_err(EvalError::Model)?
    };
    let boxes_name = match &opts.boxes {
        BoxesChoice::Gt => "gt".to_string(),
        BoxesChoice::Tracker => "tracker".to_string(),
        BoxesChoice::Model => "model".to_string(),
        BoxesChoice::File(p) => p.display().to_string(),
    };
    let depth_input = match opts.depth {
        DepthChoice::Gt => DepthInput::Metric,
        DepthChoice::Model => DepthInput::Pipeline,
        DepthChoice::RelativeGt => DepthInput::Relative(opts.relative),
    };
    let estimated = opts.depth != DepthChoice::Gt;
    // Reference pixels as the pipeline projects them; the first `foul_refs` read 50% nearer.
    let fouled: Vec<Pixel> = match &seq.camera {
        Some(camera) => ReferencePoints::project(
            camera,
            seq.reference_objects().iter().map(|r| r.front_face_center()),
            seq.info.im_width,
            seq.info.im_height,
        )
        .iter()
        .take(opts.foul_refs)
        .map(|(px, _)| px)
        .collect(),
        None => Vec::new(),
    };
    let substitute = GroundTruth::new(seq.clone(), box_input(seq, opts)?, depth_input, fouled);
    let mut pipeline =
        FishPipeline::with_substitute(&cfg.pipeline(), calibration, Box::new(substitute)).map_err(EvalError::Model)?;
    let mut source = RecordedSource::open(&seq.dir, false, false)
        .map_err(|e| EvalError::Input { path: seq.dir.clone(), msg: e.to_string() })?;

    // True swarm speed per frame: mean |v| of the fish visible in it; and mean |v| / length, where
    // world.csv has the fish's lengths.
    let mut true_sum = vec![(0.0f64, 0usize); seq.len() as usize + 1];
    let mut true_bls = vec![(0.0f64, 0usize); seq.len() as usize + 1];
    for r in &seq.world {
        if r.visibility > 0.0
            && r.velocity.iter().all(|v| v.is_finite())
            && let Some(s) = true_sum.get_mut(r.frame as usize)
        {
            s.0 += r.velocity.norm();
            s.1 += 1;
            if r.length.0.is_finite()
                && r.length.0 > 0.0
                && let Some(b) = true_bls.get_mut(r.frame as usize)
            {
                b.0 += r.velocity.norm() / r.length.0;
                b.1 += 1;
            }
        }
    }
    let (mut hide, mut misplace) = (opts.hide_refs, opts.move_refs);
    // Camera z of each fish's body centre by (frame, id): ground-truth boxes carry world.csv's ids.
    let body_z: HashMap<(u32, u32), f64> = match &seq.camera {
        Some(camera) if estimated && opts.boxes == BoxesChoice::Gt => {
            seq.world.iter().map(|r| ((r.frame, r.id), camera.pose.to_camera(&r.position).depth().0)).collect()
        }
        _ => HashMap::new(),
    };
    let gt_boxes = live::gt_by_frame(seq);
    let score_tracks = seq.has_gt && opts.boxes != BoxesChoice::Gt && !matches!(opts.boxes, BoxesChoice::File(_));
    let score_detection = seq.has_gt && opts.boxes == BoxesChoice::Model;
    let score_consistency = seq.has_gt && opts.depth == DepthChoice::Model;
    let (frame_w, frame_h) = (f64::from(seq.info.im_width), f64::from(seq.info.im_height));
    let mut consistency = DepthConsistency::default();
    let mut mot = MotAccumulator::new();
    let mut detection = DetectionScore::default();
    let mut depth_acc = DepthAccuracy::default();
    let (mut body_acc, mut body_boxes) = (DepthAccuracy::default(), 0usize);
    let (mut boxes_corrected, mut depths_corrected) = (0u64, 0u64);
    let mut series = Vec::with_capacity(seq.len() as usize);
    let mut tracks = Vec::new();
    let (mut gt_mm, mut gt_m) = (None, Vec::new());
    let (mut g, mut h, mut frame_gt) = (Vec::new(), Vec::new(), Vec::new());
    let mut cpu_s = 0.0;
    let mut buf = Vec::new();
    // Output updates on frame time, and how many had the familiarity flag raised.
    let (mut next_update, mut updates, mut flagged) = (f64::NEG_INFINITY, 0u64, 0u64);
    let mut familiarity = fme_core::familiarity::StatRanges::default();
    loop {
        let frame_data = match source.next_frame(std::mem::take(&mut buf)) {
            Ok(f) => f,
            Err(CaptureError::End) => break,
            Err(e) => return Err(EvalError::Input { path: seq.dir.clone(), msg: e.to_string() }),
        };
        let frame = u32::try_from(frame_data.seq + 1).unwrap_or(u32::MAX);
        if let Some((n, t_hide)) = hide
            && frame_data.timestamp.0 >= t_hide
        {
            pipeline.hide_references(n);
            hide = None;
        }
        if let Some((n, t_move)) = misplace
            && frame_data.timestamp.0 >= t_move
        {
            pipeline.misplace_references(n);
            misplace = None;
        }
        let cpu0 = process_cpu_s();
        let sample = pipeline
            .process(&frame_data)
            .map_err(|e| EvalError::Input { path: seq.frame_path(frame), msg: e.to_string() })?;
        if let (Some(a), Some(b)) = (cpu0, process_cpu_s()) {
            cpu_s += b - a;
        }
        buf = frame_data.data;
        let Some(sample) = sample else { continue };
        let t = sample.timestamp;
        if pipeline.ran().detect
            && let Some(w) = pipeline.health().familiarity.stats
        {
            familiarity.add(&w);
        }
        if t.0 >= next_update {
            updates += 1;
            flagged += u64::from(sample.flags.unlike_fish);
            next_update = if next_update.is_finite() { next_update } else { t.0 } + 1.0 / cfg.output.rate_hz;
            if next_update <= t.0 {
                next_update = t.0 + 1.0 / cfg.output.rate_hz;
            }
        }
        let est = *pipeline.estimate();
        boxes_corrected += u64::from(est.boxes_corrected);
        depths_corrected += u64::from(est.depths_corrected);
        let fg = gt_boxes.get(frame as usize - 1).map_or(&[][..], Vec::as_slice);
        if score_tracks {
            g.clear();
            g.extend(fg.iter().map(|&(id, b, _)| (i64::from(id), b)));
            h.clear();
            h.extend(pipeline.observations().iter().map(|o| (i64::from(o.id), o.bbox)));
            mot.update(&g, &h);
        }
        if score_consistency
            && pipeline.ran().depth
            && let Some(map) = pipeline.depth_map()
        {
            // Relative inverse depth at each true box's centre, 3x3 median of the map.
            consistency.add_frame(
                fg.iter()
                    .filter(|(_, b, _)| inside_frame(b, frame_w, frame_h))
                    .filter_map(|&(_, b, _)| map.sample_with_radius(b.center(), 1).map(|r| (f64::from(r), b))),
            );
        }
        if score_detection && pipeline.ran().detect {
            frame_gt.clear();
            frame_gt.extend(fg.iter().map(|&(_, b, v)| (b, v)));
            detection.add_frame(pipeline.detections(), &frame_gt);
        }
        if estimated && seq.has_depth {
            let dm = seq.read_depth(frame)?;
            to_metres(&dm, &mut gt_m);
            gt_mm = Some((dm.width as usize, dm.height as usize));
        }
        let views: Vec<_> = pipeline.tracks().filter(|v| v.last_seen == t).collect();
        if let (true, Some((w, hgt))) = (estimated, gt_mm) {
            let gt = RelativeMap { data: &gt_m, width: w, height: hgt };
            for v in &views {
                let Some(e) = v.depth_measured else {
                    if body_z.contains_key(&(frame, v.id)) {
                        body_boxes += 1;
                    }
                    continue;
                };
                // Ground truth read the same way as the estimate (the same pixels).
                let others = views.iter().filter(|x| x.id != v.id).map(|x| &x.bbox);
                let c = v.bbox.center();
                let truth = sample_fish(
                    cfg.depth.sample,
                    MapKind::Depth,
                    &v.bbox,
                    others,
                    || sample_median(&gt, c, GT_WINDOW, |_| true),
                    |p| gt.at(p),
                );
                if let Some(g) = truth {
                    depth_acc.add(e.0, g);
                }
                if let Some(&z) = body_z.get(&(frame, v.id)) {
                    body_boxes += 1;
                    body_acc.add(e.0, z);
                }
            }
        }
        if opts.track_rows {
            tracks.extend(views.iter().map(|v| FishRow {
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
        series.push(ScoredRow {
            row: SeriesRow { frame: u64::from(frame), sample },
            true_mps: None,
            true_now_mps: None,
        });
    }
    // Truth at the time each estimate refers to (`SwarmEstimate::latency`), interpolated between frames.
    let truth_frame: Vec<Option<f64>> = true_sum.iter().map(|&(ts, tn)| (tn > 0).then(|| ts / tn as f64)).collect();
    let bls_frame: Vec<Option<f64>> = true_bls.iter().map(|&(ts, tn)| (tn > 0).then(|| ts / tn as f64)).collect();
    let fps = seq.info.frame_rate;
    let interpolate = |truth_frame: &[Option<f64>], tq: f64| -> Option<f64> {
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
    let truth_at = |tq: f64| interpolate(&truth_frame, tq);
    for r in &mut series {
        let now = truth_frame.get(r.row.frame as usize).copied().flatten();
        r.true_now_mps = now;
        r.true_mps = if r.est_mps().is_some() { truth_at(r.t() - r.row.sample.latency.0) } else { now };
    }
    // Body lengths per second: the published value against the truth at the time it refers to.
    let (bls_e, bls_t): (Vec<f64>, Vec<f64>) = series
        .iter()
        .filter_map(|r| {
            let e = r.row.sample.mean_body_lengths;
            let t = interpolate(&bls_frame, r.t() - r.row.sample.latency.0)?;
            e.is_finite().then_some((e, t))
        })
        .unzip();
    let scored: Vec<&ScoredRow> = series.iter().filter(|r| r.true_mps.is_some() && r.est_mps().is_some()).collect();
    if speed_truth && scored.len() < 2 {
        return Err(EvalError::NothingToScore(format!(
            "{}: only {} frame(s) have both a true and an estimated swarm speed (boxes from {boxes_name}, {} boxes in total)",
            seq.dir.display(),
            scored.len(),
            seq.gt.len()
        )));
    }
    let truth: Vec<f64> = scored.iter().filter_map(|r| r.true_mps).collect();
    let est_v: Vec<f64> = scored.iter().filter_map(|r| r.est_mps()).collect();
    let (now_e, now_t): (Vec<f64>, Vec<f64>) =
        series.iter().filter_map(|r| Some((r.est_mps()?, r.true_now_mps?))).unzip();
    let errors: Vec<f64> = est_v.iter().zip(&truth).map(|(e, t)| e - t).collect();
    let n = scored.len() as f64;
    let with_est: Vec<&ActivitySample> =
        series.iter().filter(|r| r.est_mps().is_some()).map(|r| &r.row.sample).collect();
    let fits = pipeline.fit_stats();
    let mot_summary = score_tracks.then(|| MotSummary::from(&mot.metrics()));
    let activity: Vec<&ActivitySample> =
        series.iter().map(|r| &r.row.sample).filter(|s| s.mean.0.is_finite()).collect();
    let mean_of = |f: fn(&ActivitySample) -> f64| -> f64 {
        let v: Vec<f64> = activity.iter().map(|s| f(s)).filter(|x| x.is_finite()).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    };
    let absent = absent_scores(seq, opts, speed_truth);
    let mut report = EvalReport {
        sequence: seq.dir.display().to_string(),
        boxes: boxes_name,
        depth: opts.depth,
        fit: estimated.then_some(cfg.depth.fit),
        postprocess: cfg.postprocess.box_fluctuation || cfg.postprocess.depth_jump,
        depth_sample: cfg.depth.sample,
        rates_hz: [cfg.detector.rate_hz, cfg.depth.rate_hz],
        speed_span_s: cfg.motion.speed_span_s.0,
        frames: scored.len(),
        speed_rmse_mps: rmse(&est_v, &truth).unwrap_or(f64::NAN),
        speed_rmse_now_mps: rmse(&now_e, &now_t).unwrap_or(f64::NAN),
        speed_distcorr: distance_correlation(&est_v, &truth).unwrap_or(0.0),
        bls_rmse: rmse(&bls_e, &bls_t),
        bls_distcorr: distance_correlation(&bls_e, &bls_t),
        bls_bias: bias(&bls_e, &bls_t),
        scale_source: pipeline.fit_state().source.name(),
        error_ci95_mps: [quantile(&errors, 0.025).unwrap_or(0.0), quantile(&errors, 0.975).unwrap_or(0.0)],
        speed_bias_mps: bias(&est_v, &truth).unwrap_or(0.0),
        mean_true_mps: truth.iter().sum::<f64>() / n,
        mean_est_mps: est_v.iter().sum::<f64>() / n,
        mean_fish: scored.iter().map(|r| f64::from(r.row.sample.fish)).sum::<f64>() / n,
        // Over the frames with an estimate (a frame without one has no latency).
        latency_s: with_est.iter().map(|s| s.latency.0).sum::<f64>() / with_est.len().max(1) as f64,
        cpu_ms_per_frame: 1000.0 * cpu_s / series.len().max(1) as f64,
        unlike_fish_share: flagged as f64 / updates.max(1) as f64,
        familiarity,
        depth_rmse_m: depth_acc.rmse(),
        depth_delta_1_25: depth_acc.delta_1_25(),
        depth_delta_1_25_2: depth_acc.delta_1_25_2(),
        depth_body_rmse_m: body_acc.rmse(),
        depth_body_delta_1_25: body_acc.delta_1_25(),
        depth_body_coverage: (body_boxes > 0).then(|| body_acc.count() as f64 / body_boxes as f64),
        fit_residual_m: (fits.residuals > 0).then(|| fits.residual_sum_m / fits.residuals as f64),
        fit_failures: fits.failures,
        references_visible: pipeline.references_in_view(),
        references_rejected: fits.rejected,
        boxes_corrected,
        depths_corrected,
        mot: mot_summary,
        detection: score_detection.then_some(detection),
        activity_frames: activity.len(),
        mean_activity_mps: mean_of(|s| s.mean.0),
        mean_activity_bls: mean_of(|s| s.mean_body_lengths),
        depth_consistency: consistency.mean(),
        depth_consistency_frames: consistency.frames(),
        absent,
        series,
        tracks,
    };
    if !speed_truth {
        // No world.csv: the speed is not scored (NaN is `null` in the JSON).
        report.speed_distcorr = f64::NAN;
        report.error_ci95_mps = [f64::NAN; 2];
        report.speed_bias_mps = f64::NAN;
    }
    Ok(report)
}

/// The scores a run cannot give, each with its reason (`absent` in the report).
fn absent_scores(seq: &Sequence, opts: &EvalOptions, speed_truth: bool) -> Vec<String> {
    let mut absent = Vec::new();
    if !speed_truth {
        absent
            .push("speed and BL/s errors: no gt/world.csv (no speed truth); the activity is reported unscored".into());
    }
    if opts.depth != DepthChoice::Gt && !seq.has_depth {
        absent.push("depth accuracy: no depth/ (no depth truth)".into());
    }
    if !seq.has_gt {
        absent.push("detection, tracking and depth consistency: no gt/gt.txt (no true boxes)".into());
        return absent;
    }
    match &opts.boxes {
        BoxesChoice::Model => {}
        BoxesChoice::Tracker => absent.push("detection: --boxes tracker (the detector does not run)".into()),
        BoxesChoice::Gt | BoxesChoice::File(_) => {
            absent.push("detection and tracking: the boxes are given (the detector and tracker do not run)".into())
        }
    }
    if opts.depth != DepthChoice::Model {
        absent.push("depth consistency: the depth network does not run (--depth model runs it)".into());
    }
    absent
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
