//! The real pipeline of `fme run`: detector + tracker + depth network + metric fit + post-processing
//! + motion (paper eq. 1-5), on one thread, with all per-frame state owned here and reused.
//!
//! Per frame at time `t` (the frame's own timestamp, never an assumed period):
//! 1. `tracker.predict(t)`: every frame, so tracks move between detector runs;
//! 2. the schedule says whether this frame gets the detector (`detector.rate_hz`) and/or the depth
//!    network (`depth.rate_hz`); only then is the frame decoded to RGB;
//! 3. detections -> `tracker.update(t)`; depth map -> relative values at the reference objects'
//!    pixels -> scale/shift fit (eq. 1-2), kept until the next depth run;
//! 4. the confirmed tracks' boxes -> [`ActivityEstimator`] (eq. 3-4 corrections, world positions from
//!    the corrected centre and the metric depth sampled there, per-fish speed, swarm mean eq. 5).

use super::calibration::Calibration;
use super::pipeline::{ActivitySample, CalibInfo, Pipeline, PipelineError, QualityFlags, StageHealth};
use crate::capture::Frame;
use crate::config::Config;
use crate::geometry::{Camera, PixelBox};
use crate::infer::{self, DepthNet, Detector, InferSchedule, RgbFrame, ScheduleConfig, SessionOptions};
use crate::metric::{
    DepthSample, FitMethod, MapKind, ROBUST_INLIER, ReferenceFootprints, ReferencePoints, ScaleShift, sample_fish,
};
use crate::motion::{ActivityEstimator, TrackObservation};
use crate::track::{self, Tracker};
use crate::units::{Metres, MetresPerSecond, Seconds};

/// Achieved run rate of a stage over the last few seconds of frame time (fixed size).
#[derive(Debug, Clone, Copy, Default)]
struct RateMeter {
    times: [f64; 16],
    n: usize,
    next: usize,
}

impl RateMeter {
    fn record(&mut self, t: f64) {
        self.times[self.next] = t;
        self.next = (self.next + 1) % self.times.len();
        self.n = (self.n + 1).min(self.times.len());
    }
    fn hz(&self) -> f64 {
        if self.n < 2 {
            return 0.0;
        }
        let newest = self.times[(self.next + self.times.len() - 1) % self.times.len()];
        let oldest = self.times[(self.next + self.times.len() - self.n) % self.times.len()];
        if newest > oldest { (self.n - 1) as f64 / (newest - oldest) } else { 0.0 }
    }
}

/// Detector + tracker + depth + metric fit + post-processing + motion.
pub struct FishPipeline {
    schedule: InferSchedule,
    schedule_cfg: ScheduleConfig,
    detector: Detector,
    depth: DepthNet,
    tracker_cfg: track::TrackerConfig,
    tracker: Tracker,
    estimator: ActivityEstimator,
    refs: ReferencePoints,
    footprints: ReferenceFootprints,
    fit_method: FitMethod,
    fit: Option<ScaleShift>,
    calib: CalibInfo,
    min_fish: u32,
    body_length: Option<f64>,
    depth_sample: DepthSample,
    rgb: Vec<u8>,
    dets: Vec<track::Detection>,
    obs: Vec<TrackObservation>,
    last_t: Option<f64>,
    health: StageHealth,
    det_rate: RateMeter,
    depth_rate: RateMeter,
}

impl std::fmt::Debug for FishPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FishPipeline")
            .field("detector", &self.detector)
            .field("depth", &self.depth)
            .field("references", &self.refs.len())
            .finish_non_exhaustive()
    }
}

impl FishPipeline {
    /// Builds the pipeline from the configuration. `calibration`: the camera and reference objects
    /// (`None`: uncalibrated; fish are tracked but no speed is reported). Errors name the config key
    /// and the file (missing ONNX Runtime, missing or mismatched model).
    pub fn new(cfg: &Config, calibration: Option<Calibration>) -> Result<Self, String> {
        infer::runtime::environment().map_err(|e| format!("ONNX Runtime: {e}"))?;
        let det_cfg = infer::DetectorConfig {
            model: infer::runtime::resolve_model(&cfg.detector.model),
            conf_threshold: cfg.detector.confidence as f32,
            iou_threshold: cfg.detector.nms_iou as f32,
            class_agnostic: true,
            max_detections: track::MAX_DETS,
            max_candidates: 3000,
            ..infer::DetectorConfig::default()
        };
        let opts = |threads: usize, spin: bool| SessionOptions { intra_threads: threads, spin };
        let detector = Detector::open(&det_cfg, opts(cfg.detector.threads, cfg.detector.spin))
            .map_err(|e| format!("detector.model: {e}"))?;
        let depth_cfg = infer::DepthConfig {
            model: infer::runtime::resolve_model(&cfg.depth.model),
            mean: cfg.depth.mean,
            std: cfg.depth.std,
            flip: cfg.depth.flip,
            ..infer::DepthConfig::default()
        };
        let depth = DepthNet::open(&depth_cfg, opts(cfg.depth.threads, cfg.depth.spin))
            .map_err(|e| format!("depth.model: {e}"))?;
        let tracker_cfg = tracker_config(cfg)?;
        let camera = calibration.as_ref().map_or_else(|| fallback_camera(cfg), |c| c.camera);
        // References are kept if they fall inside the calibrated image (principal point at its centre);
        // sampling outside the actual frame returns nothing anyway.
        let (w, h) = ((2.0 * camera.intrinsics.cx).ceil() as u32, (2.0 * camera.intrinsics.cy).ceil() as u32);
        let refs = calibration
            .as_ref()
            .map(|c| ReferencePoints::project(&camera, c.references.iter().copied(), w, h))
            .unwrap_or_default();
        let footprints = match (&calibration, cfg.detector.ignore_references) {
            (Some(c), true) => ReferenceFootprints::project(&camera, c.cubes.iter().copied()),
            _ => ReferenceFootprints::default(),
        };
        let schedule_cfg = ScheduleConfig { detect_hz: cfg.detector.rate_hz, depth_hz: cfg.depth.rate_hz };
        let motion = motion_config(cfg);
        let post = postprocess_config(cfg);
        motion.validate().map_err(str::to_string)?;
        post.validate().map_err(str::to_string)?;
        Ok(Self {
            schedule: InferSchedule::new(&schedule_cfg),
            schedule_cfg,
            detector,
            depth,
            tracker: Tracker::new(tracker_cfg),
            tracker_cfg,
            estimator: ActivityEstimator::new(camera, motion, post),
            calib: CalibInfo { references_visible: refs.len() as u32, ..CalibInfo::default() },
            refs,
            footprints,
            fit_method: cfg.depth.fit,
            fit: None,
            min_fish: cfg.motion.min_fish,
            depth_sample: cfg.depth.sample,
            body_length: (cfg.motion.body_length_m > 0.0).then_some(cfg.motion.body_length_m),
            rgb: Vec::with_capacity(cfg.source.width as usize * cfg.source.height as usize * 3),
            dets: Vec::with_capacity(track::MAX_DETS),
            obs: Vec::with_capacity(track::MAX_TRACKS),
            last_t: None,
            health: StageHealth::default(),
            det_rate: RateMeter::default(),
            depth_rate: RateMeter::default(),
        })
    }

    /// Starts over after time went backwards (camera restarted): tracks, speeds and schedules are
    /// reset; the metric fit is kept (the camera has not moved).
    fn restart(&mut self) {
        self.tracker = Tracker::new(self.tracker_cfg);
        let (camera, motion, post) = (*self.estimator.camera(), self.estimator.motion(), self.estimator.postprocess());
        self.estimator = ActivityEstimator::new(camera, motion, post);
        self.schedule = InferSchedule::new(&self.schedule_cfg);
    }

    /// Refits scale and shift on the current depth map (eq. 1-2); a failed fit keeps the previous one.
    fn refit(&mut self) {
        let Some(map) = self.depth.last_map() else { return };
        let refs = self.refs.pairs(|px| map.sample(px).map(f64::from));
        self.calib.references_visible = refs.len() as u32;
        match self.fit_method.fit(&refs, ROBUST_INLIER) {
            Ok(f) => {
                self.fit = Some(f);
                self.calib = CalibInfo {
                    scale: f.s,
                    shift: f.t,
                    residual_m: f.residual_rms.0,
                    references_visible: refs.len() as u32,
                    calibrated: true,
                };
            }
            Err(e) => tracing::debug!("metric fit failed ({e}); keeping the previous fit"),
        }
    }
}

/// The tracker settings for `[tracker]`.
fn tracker_config(cfg: &Config) -> Result<track::TrackerConfig, String> {
    let c = &cfg.tracker;
    let mut t = track::TrackerConfig::preset(&c.preset).ok_or_else(|| format!("tracker.preset: {:?}", c.preset))?;
    t.max_tracks = c.max_tracks;
    t.min_hits = c.min_hits;
    t.iou_thresh = c.iou_threshold;
    t.max_lost_s = c.max_age_s;
    t.validate().map_err(|e| format!("tracker: {e}"))?;
    Ok(t)
}

/// The post-processing settings for `[postprocess]`.
fn postprocess_config(cfg: &Config) -> crate::postprocess::PostprocessConfig {
    let p = &cfg.postprocess;
    crate::postprocess::PostprocessConfig {
        box_fluctuation: p.box_fluctuation,
        fluctuation_window: Seconds(p.box_window_s),
        box_ewma_window: Seconds(p.box_ewma_s),
        depth_jump: p.depth_jump,
        depth_jump_threshold: Metres(p.depth_jump_m),
        depth_ewma_window: Seconds(p.depth_window_s),
        depth_smoothing: Seconds(p.depth_smoothing_s),
        ..crate::postprocess::PostprocessConfig::default()
    }
}

/// The motion settings for `[motion]`.
fn motion_config(cfg: &Config) -> crate::motion::MotionConfig {
    let m = &cfg.motion;
    crate::motion::MotionConfig {
        max_tracks: track::MAX_TRACKS,
        body_length: (m.body_length_m > 0.0).then_some(Metres(m.body_length_m)),
        speed_span: Seconds(m.speed_span_s),
        min_age: Seconds(m.min_age_s),
        along_ray: m.along_ray,
        body_width_ratio: m.body_width_ratio,
        smoothing: Seconds(m.smoothing_s),
        max_speed: MetresPerSecond(m.max_speed_mps),
        ..crate::motion::MotionConfig::default()
    }
}

/// A camera for an uncalibrated box (no speeds are reported without a fit, so only the image size
/// matters): 90 degrees horizontal field of view, identity pose.
fn fallback_camera(cfg: &Config) -> Camera {
    let (w, h) = (cfg.source.width.max(1), cfg.source.height.max(1));
    let intrinsics = crate::geometry::Intrinsics::from_hfov(w, h, 90.0).unwrap_or(crate::geometry::Intrinsics {
        fx: 1.0,
        fy: 1.0,
        cx: 0.0,
        cy: 0.0,
        distortion: [0.0; 5],
    });
    let pose = crate::geometry::Pose::new(nalgebra::Matrix3::identity(), nalgebra::Vector3::zeros())
        .expect("the identity is a rotation");
    Camera { intrinsics, pose }
}

impl Pipeline for FishPipeline {
    fn process(&mut self, frame: &Frame) -> Result<Option<ActivitySample>, PipelineError> {
        let t = frame.timestamp;
        if !t.0.is_finite() {
            return Err(PipelineError::Decode { seq: frame.seq, message: format!("timestamp {} is not finite", t.0) });
        }
        if self.last_t.is_some_and(|last| t.0 <= last) {
            tracing::warn!(t = t.0, "frame time went backwards (camera restart?): tracks reset");
            self.restart();
        }
        self.last_t = Some(t.0);
        let plan = self.schedule.plan(t);
        self.tracker.predict(t).map_err(|e| PipelineError::Stage { stage: "tracker", message: e.to_string() })?;
        if plan.detect || plan.depth {
            let (w, h) = frame
                .to_rgb_into(&mut self.rgb)
                .map_err(|message| PipelineError::Decode { seq: frame.seq, message })?;
            let rgb = RgbFrame::new(w, h, &self.rgb)
                .map_err(|e| PipelineError::Decode { seq: frame.seq, message: e.to_string() })?;
            if plan.detect {
                match self.detector.detect(&rgb, t) {
                    Ok(d) => {
                        self.dets.clear();
                        let footprints = &self.footprints;
                        self.dets.extend(
                            d.items
                                .iter()
                                .filter(|x| !footprints.covers(&x.bbox))
                                .map(|x| track::Detection::new(x.bbox, x.score)),
                        );
                        self.health.detector_ok = true;
                        self.det_rate.record(t.0);
                    }
                    Err(e) => {
                        self.health.detector_ok = false;
                        return Err(PipelineError::Stage { stage: "detector", message: e.to_string() });
                    }
                }
                self.tracker
                    .update(t, &self.dets)
                    .map_err(|e| PipelineError::Stage { stage: "tracker", message: e.to_string() })?;
            }
            if plan.depth {
                match self.depth.estimate(&rgb, t) {
                    Ok(_) => {
                        self.health.depth_ok = true;
                        self.depth_rate.record(t.0);
                        if !self.refs.is_empty() {
                            self.refit();
                        }
                    }
                    Err(e) => {
                        self.health.depth_ok = false;
                        return Err(PipelineError::Stage { stage: "depth", message: e.to_string() });
                    }
                }
            }
        }
        self.obs.clear();
        self.obs.extend(self.tracker.confirmed().map(|o| TrackObservation { id: o.id, bbox: o.bbox, depth: None }));
        self.health.tracks = self.obs.len() as u32;
        self.health.detector_hz = self.det_rate.hz();
        self.health.depth_hz = self.depth_rate.hz();
        let (fit, map, how, obs) = (self.fit, self.depth.last_map(), self.depth_sample, &self.obs);
        let s = self.estimator.update_with(t, obs, |o, px| {
            let (fit, map) = (fit?, map?);
            let b = PixelBox::from_center(px, o.bbox.w, o.bbox.h);
            let others = obs.iter().filter(|x| x.id != o.id).map(|x| &x.bbox);
            let r = sample_fish(
                how,
                MapKind::InverseDepth,
                &b,
                others,
                || map.sample(px).map(f64::from),
                |p| map.sample_with_radius(p, 0).map(f64::from),
            )?;
            fit.depth(r)
        });
        let mean = s.mean.map_or(f64::NAN, |m| m.0);
        let ci95_half = s.ci95.map_or(f64::NAN, |(lo, hi)| 0.5 * (hi.0 - lo.0));
        let bls = match self.body_length {
            Some(l) => mean / l,
            None => s.mean_bls.unwrap_or(f64::NAN),
        };
        Ok(Some(ActivitySample {
            timestamp: t,
            mean: MetresPerSecond(mean),
            mean_body_lengths: bls,
            smoothed: MetresPerSecond(s.smoothed.map_or(f64::NAN, |m| m.0)),
            ci95_half: MetresPerSecond(ci95_half),
            fish: s.n_fish as u32,
            flags: QualityFlags {
                too_few_fish: (s.n_fish as u32) < self.min_fish,
                depth_uncalibrated: self.fit.is_none(),
                stale: false,
            },
        }))
    }

    fn health(&self) -> StageHealth {
        self.health
    }

    fn calib(&self) -> CalibInfo {
        self.calib
    }

    fn describe_tracks(&self, out: &mut dyn std::fmt::Write, max: usize) -> std::fmt::Result {
        for v in self.estimator.tracks().take(max) {
            let c = v.bbox.center();
            write!(
                out,
                "id {:>4} t {:.2} s box ({:.0},{:.0}) {:.0}x{:.0} px",
                v.id, v.last_seen.0, c.u, c.v, v.bbox.w, v.bbox.h
            )?;
            match v.depth {
                Some(d) => write!(out, " depth {:.2} m", d.0)?,
                None => write!(out, " depth -")?,
            }
            match v.speed {
                Some(s) => writeln!(out, " speed {:.3} m/s", s.0)?,
                None => writeln!(out, " speed -")?,
            }
        }
        Ok(())
    }
}
