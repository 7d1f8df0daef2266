//! The run behind `fme eval`: the daemon's own pipeline ([`FishPipeline`]) over a recording, with
//! ground truth swapped in where asked, each frame's outcome handed to the scorers
//! ([`super::score`]).
//!
//! The frames come from the same recorded source `fme run` replays (`capture::RecordedSource`, as
//! fast as possible, no loop) and go through [`FishPipeline`] with the one [`Config`]: the same
//! reduced-rate schedule on frame time, depth sampling, fit, smoothing and `min_age`. The scorers
//! read only the pipeline's outcome, so what is scored is what the PLC receives.

use super::boxes::IndexedBoxes;
use super::inputs::{BoxInput, DepthInput, GroundTruth};
use super::live;
use super::options::{DepthChoice, EvalOptions};
use super::report::EvalReport;
use super::score::{
    ConsistencyScorer, DepthScorer, DetectionScorer, FamiliarityScorer, FishRows, FrameTruth, PipelineState, Scorer,
    SpeedScorer, TrackingScorer,
};
use super::{BoxesChoice, EvalError};
use fme_core::geometry::Pixel;
use fme_core::metric::ReferencePoints;
use fme_core::pipeline::{Calibration, FishPipeline, Pipeline};
use fme_edge::capture::{CaptureError, FrameSource, RecordedSource};
use fme_edge::config::Config;
use fme_edge::sequence::Sequence;

/// Runs the evaluation: the pipeline over every frame of `seq` with `cfg`, scored.
pub fn evaluate(seq: &Sequence, cfg: &Config, opts: &EvalOptions) -> Result<EvalReport, EvalError> {
    check_inputs(seq, opts)?;
    let (cfg, calibration) = run_config(seq, cfg, opts)?;
    let mut report = blank_report(seq, &cfg, opts);
    let mut scorers = scorers(seq, &cfg, opts, &report.boxes);
    let mut pipeline = pipeline(seq, &cfg, calibration, opts)?;
    let mut source = RecordedSource::open(&seq.dir, false, false)
        .map_err(|e| EvalError::Input { path: seq.dir.clone(), msg: e.to_string() })?;
    let truth = live::gt_by_frame(seq);
    let (mut hide, mut misplace) = (opts.hide_refs, opts.move_refs);
    let (mut cpu_s, mut samples, mut buf) = (0.0, 0usize, Vec::new());
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
        let outcome = pipeline
            .process(&frame_data)
            .map_err(|e| EvalError::Input { path: seq.frame_path(frame), msg: e.to_string() })?;
        if let (Some(a), Some(b)) = (cpu0, process_cpu_s()) {
            cpu_s += b - a;
        }
        if outcome.sample.is_some() {
            samples += 1;
            let boxes = truth.get(frame as usize - 1).map_or(&[][..], Vec::as_slice);
            let t = FrameTruth { frame, boxes };
            for s in &mut scorers {
                s.frame(&t, &outcome)?;
            }
        }
        buf = frame_data.data;
    }
    report.cpu_ms_per_frame = 1000.0 * cpu_s / samples.max(1) as f64;
    for s in scorers {
        s.finish(&mut report)?;
    }
    Ok(report)
}

/// A recording labelled with boxes only (no `depth/`, no `gt/world.csv`) is scored for tracking
/// and detection, with the pipeline's own depth; ground-truth depth needs the maps.
fn check_inputs(seq: &Sequence, opts: &EvalOptions) -> Result<(), EvalError> {
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
    Ok(())
}

/// The config as the run uses it: the recording as the source (as fast as possible, no loop, its
/// size), and its calibration unless `--no-calibration` (then the fish are the ruler).
fn run_config(seq: &Sequence, cfg: &Config, opts: &EvalOptions) -> Result<(Config, Option<Calibration>), EvalError> {
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
    Ok((cfg, calibration))
}

/// The report before any score: what the run is.
fn blank_report(seq: &Sequence, cfg: &Config, opts: &EvalOptions) -> EvalReport {
    let boxes = match &opts.boxes {
        BoxesChoice::Gt => "gt".to_string(),
        BoxesChoice::Tracker => "tracker".to_string(),
        BoxesChoice::Model => "model".to_string(),
        BoxesChoice::File(p) => p.display().to_string(),
    };
    let mut r = EvalReport::blank(seq.dir.display().to_string(), boxes, opts.depth);
    r.fit = (opts.depth != DepthChoice::Gt).then_some(cfg.depth.fit);
    r.postprocess = cfg.postprocess.box_fluctuation || cfg.postprocess.depth_jump;
    r.depth_sample = cfg.depth.sample;
    r.rates_hz = [cfg.detector.rate_hz, cfg.depth.rate_hz];
    r.speed_span_s = cfg.motion.speed_span_s.0;
    r.absent = absent_scores(seq, opts, !seq.world.is_empty());
    r
}

/// The scorers this run can feed: each needs its truth and the stage it scores to run.
fn scorers<'a>(seq: &'a Sequence, cfg: &Config, opts: &EvalOptions, boxes: &str) -> Vec<Box<dyn Scorer + 'a>> {
    let estimated = opts.depth != DepthChoice::Gt;
    let given_boxes = opts.boxes == BoxesChoice::Gt || matches!(opts.boxes, BoxesChoice::File(_));
    let mut s: Vec<Box<dyn Scorer + 'a>> = vec![
        Box::new(SpeedScorer::new(seq, boxes)),
        Box::new(PipelineState::default()),
        Box::new(FamiliarityScorer::new(1.0 / cfg.output.rate_hz)),
    ];
    if seq.has_gt && !given_boxes {
        s.push(Box::new(TrackingScorer::default()));
    }
    if seq.has_gt && opts.boxes == BoxesChoice::Model {
        s.push(Box::new(DetectionScorer::default()));
    }
    if seq.has_gt && opts.depth == DepthChoice::Model {
        s.push(Box::new(ConsistencyScorer::new(seq.info.im_width, seq.info.im_height)));
    }
    if estimated {
        s.push(Box::new(DepthScorer::new(seq, cfg.depth.sample, opts.boxes == BoxesChoice::Gt)));
    }
    if opts.track_rows {
        s.push(Box::new(FishRows::default()));
    }
    s
}

/// The pipeline with ground truth swapped in where `opts` asks.
fn pipeline(
    seq: &Sequence,
    cfg: &Config,
    calibration: Option<Calibration>,
    opts: &EvalOptions,
) -> Result<FishPipeline, EvalError> {
    let depth_input = match opts.depth {
        DepthChoice::Gt => DepthInput::Metric,
        DepthChoice::Model => DepthInput::Pipeline,
        DepthChoice::RelativeGt => DepthInput::Relative(opts.relative),
    };
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
    FishPipeline::with_substitute(&cfg.pipeline(), calibration, Box::new(substitute)).map_err(EvalError::Model)
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

/// Process CPU time (user + system) so far, seconds; `None` where /proc is not readable.
fn process_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = s.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
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
