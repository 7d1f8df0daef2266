//! The fish pipeline: detector + tracker + depth network + metric fit + post-processing + motion
//! (paper eq. 1-5), on one thread, with all per-frame state owned here and reused.
//!
//! Per frame at time `t` (the frame's own timestamp, never an assumed period):
//! 1. `tracker.predict(t)`: every frame, so tracks move between detector runs;
//! 2. the schedule says whether this frame gets the detector (`detector.rate_hz`) and/or the depth
//!    network (`depth.rate_hz`); only then is the frame decoded to RGB;
//! 3. detections -> `tracker.update(t)`; depth map -> relative values at the reference objects'
//!    pixels -> metric fit (eq. 1-2), kept until the next depth run;
//! 4. the confirmed tracks' boxes -> [`ActivityEstimator`] (eq. 3-4 corrections, world positions from
//!    the corrected centre and the metric depth sampled there, per-fish speed, swarm mean eq. 5).
//!
//! A [`Substitute`] may replace the detector, detector + tracker, or the depth network with ground
//! truth (`fme eval`); everything else, schedule included, runs as in `fme run`.

use super::PipelineConfig;
use super::rate::RateMeter;
use super::substitute::Substitute;
use super::{
    ActivitySample, Calibration, Frame, FrameOutcome, Network, Networks, Pipeline, PipelineError, QualityFlags,
    StageHealth,
};
use crate::familiarity::FamiliarityMonitor;
use crate::geometry::{Camera, PixelBox};
use crate::infer::{self, DepthNet, Detector, FramePlan, InferSchedule, RgbFrame};
use crate::metric::{
    DepthGrid, MapKind, ReferenceFootprints, ReferencePoints, ScaleConfig, ScalePolicy, ScaleSource, sample_fish,
};
use crate::motion::{ActivityEstimator, Fish, Observation, SwarmEstimate};
use crate::track::{self, Tracker};
use crate::units::{Metres, MetresPerSecond, Seconds};

/// Detector + tracker + depth + metric fit + post-processing + motion.
pub struct FishPipeline {
    cfg: PipelineConfig,
    schedule: InferSchedule,
    detector: Option<Detector>,
    depth: Option<DepthNet>,
    substitute: Option<Box<dyn Substitute>>,
    tracker: Tracker,
    /// "Detections look unlike fish" (`[familiarity]`).
    familiarity: FamiliarityMonitor,
    estimator: ActivityEstimator,
    refs: ReferencePoints,
    footprints: ReferenceFootprints,
    /// The depth fit and what sets its scale (`depth.scale`, eq. 1-2).
    scale: ScalePolicy,
    rgb: Vec<u8>,
    dets: Vec<track::Detection>,
    given: Vec<(u32, PixelBox)>,
    obs: Vec<Observation>,
    /// The estimator's fish after the last frame, for its outcome (allocated once).
    fish: Vec<Fish>,
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
            .field("substitute", &self.substitute.is_some())
            .field("references", &self.refs.len())
            .finish_non_exhaustive()
    }
}

impl FishPipeline {
    /// The pipeline of `fme run`. `calibration`: the camera and reference objects (`None`:
    /// uncalibrated: the fish are the ruler when `depth.scale` and a fish length allow it, else no
    /// speed is reported). Errors name the config key and the
    /// file (missing ONNX Runtime, missing or mismatched model).
    pub fn new(cfg: &PipelineConfig, calibration: Option<Calibration>) -> Result<Self, String> {
        Self::build(cfg, calibration, None, infer::Backend::DEFAULT)
    }

    /// As [`Self::new`], with the networks run by `backend` (a build with both backends: the
    /// parity test and the backend benchmark).
    pub fn with_backend(
        cfg: &PipelineConfig,
        calibration: Option<Calibration>,
        backend: infer::Backend,
    ) -> Result<Self, String> {
        Self::build(cfg, calibration, None, backend)
    }

    /// The same pipeline with stages replaced by `substitute` (`fme eval`); networks it replaces
    /// are not loaded.
    pub fn with_substitute(
        cfg: &PipelineConfig,
        calibration: Option<Calibration>,
        substitute: Box<dyn Substitute>,
    ) -> Result<Self, String> {
        Self::build(cfg, calibration, Some(substitute), infer::Backend::DEFAULT)
    }

    fn build(
        cfg: &PipelineConfig,
        calibration: Option<Calibration>,
        sub: Option<Box<dyn Substitute>>,
        backend: infer::Backend,
    ) -> Result<Self, String> {
        cfg.validate()?;
        let needs_detector = !sub.as_ref().is_some_and(|s| s.replaces_tracks() || s.replaces_detector());
        let needs_depth = !sub.as_ref().is_some_and(|s| s.replaces_depth());
        if needs_detector || needs_depth {
            backend.prepare().map_err(|e| format!("{}: {e}", backend.name()))?;
        }
        let detector = if needs_detector {
            let c = infer::DetectorConfig {
                model: infer::runtime::resolve_model(&cfg.detector.model),
                ..cfg.detector.clone()
            };
            Some(Detector::open_with(&c, c.session(), backend).map_err(|e| format!("detector.model: {e}"))?)
        } else {
            None
        };
        let depth = if needs_depth {
            let c = infer::DepthConfig { model: infer::runtime::resolve_model(&cfg.depth.model), ..cfg.depth.clone() };
            Some(DepthNet::open_with(&c, c.session(), backend).map_err(|e| format!("depth.model: {e}"))?)
        } else {
            None
        };
        let (camera, refs, footprints) = calibrated_parts(cfg, calibration.as_ref());
        Ok(Self {
            schedule: InferSchedule::new(cfg.detector.rate_hz, cfg.depth.rate_hz),
            detector,
            depth,
            substitute: sub,
            tracker: Tracker::new(cfg.tracker),
            familiarity: FamiliarityMonitor::new(cfg.familiarity),
            estimator: ActivityEstimator::new(camera, cfg.motion, cfg.postprocess),
            scale: ScalePolicy::new(scale_config(cfg), crate::motion::MAX_FISH, refs.len()),
            refs,
            footprints,
            rgb: Vec::with_capacity(cfg.frame_width as usize * cfg.frame_height as usize * 3),
            dets: Vec::with_capacity(track::MAX_DETS),
            given: Vec::with_capacity(track::MAX_TRACKS),
            obs: Vec::with_capacity(track::MAX_TRACKS),
            fish: Vec::with_capacity(crate::motion::MAX_FISH),
            last_t: None,
            health: StageHealth::default(),
            det_rate: RateMeter::default(),
            depth_rate: RateMeter::default(),
            cfg: cfg.clone(),
        })
    }

    /// A new calibration while running (a reload), built as at start: the camera, the reference
    /// objects' pixels and footprints, the metric fit (started over: its scale belonged to the old
    /// references) and the speed estimator (its fish were placed with the old camera); tracks stay.
    fn recalibrate(&mut self, calibration: Option<&Calibration>) {
        let (camera, refs, footprints) = calibrated_parts(&self.cfg, calibration);
        self.estimator = ActivityEstimator::new(camera, self.cfg.motion, self.cfg.postprocess);
        self.scale = ScalePolicy::new(scale_config(&self.cfg), crate::motion::MAX_FISH, refs.len());
        self.refs = refs;
        self.footprints = footprints;
    }

    /// Takes the first `n` reference objects out of the fit from now on, as if fouled over or out of
    /// sight (`fme eval --hide-refs`; the tests of `depth.scale = "auto"`).
    pub fn hide_references(&mut self, n: usize) {
        self.refs.drop_first(n);
    }

    /// Makes the recorded positions of the first `n` reference objects wrong from now on (moved with
    /// the net, or fouled: `fme eval --move-refs`): each one's depth off by its own factor, 0.7-1.3.
    pub fn misplace_references(&mut self, n: usize) {
        self.refs.misplace_first(n);
    }

    /// The depth map the pipeline samples now: the network's last map, or the substitute's.
    fn sampled_map(&self) -> Option<&dyn DepthGrid> {
        sampled_map(&self.depth, &self.substitute)
    }

    /// Starts over after time went backwards (camera restarted): tracks, speeds and schedules are
    /// reset; the metric fit is kept (the camera has not moved).
    fn restart(&mut self) {
        self.tracker = Tracker::new(self.cfg.tracker);
        self.estimator = ActivityEstimator::new(*self.estimator.camera(), self.cfg.motion, self.cfg.postprocess);
        self.schedule = InferSchedule::new(self.cfg.detector.rate_hz, self.cfg.depth.rate_hz);
        self.scale.restart();
        self.familiarity.reset();
    }

    /// Runs the networks `plan` asks for (the detector unless tracks are given), decoding the frame
    /// once and only when one of them runs.
    fn run_networks(&mut self, frame: &Frame, plan: FramePlan, tracks_given: bool) -> Result<(), PipelineError> {
        let net_runs = (plan.detect && self.detector.is_some()) || (plan.depth && self.depth.is_some());
        let mut rgb_buf = std::mem::take(&mut self.rgb);
        let result = (|| {
            let rgb = if net_runs {
                let (w, h) = frame
                    .to_rgb_into(&mut rgb_buf)
                    .map_err(|message| PipelineError::Decode { seq: frame.seq, message })?;
                Some(
                    RgbFrame::new(w, h, &rgb_buf)
                        .map_err(|e| PipelineError::Decode { seq: frame.seq, message: e.to_string() })?,
                )
            } else {
                None
            };
            if plan.detect && !tracks_given {
                self.detect(frame, rgb.as_ref())?;
            }
            if plan.depth {
                self.depth_frame(frame, rgb.as_ref())?;
            }
            Ok::<(), PipelineError>(())
        })();
        self.rgb = rgb_buf;
        result
    }

    /// The tracked boxes that enter the estimator: the tracker's confirmed tracks, or the given ones.
    fn observe(&mut self, frame: &Frame, tracks_given: bool) -> Result<(), PipelineError> {
        self.obs.clear();
        if tracks_given {
            if let Some(s) = self.substitute.as_mut() {
                self.given.clear();
                s.tracks(frame, &mut self.given)
                    .map_err(|message| PipelineError::Stage { stage: "tracks", message })?;
                self.obs.extend(self.given.iter().map(|&(id, bbox)| Observation { id, bbox, depth: None }));
            }
        } else {
            self.obs.extend(self.tracker.confirmed().map(|o| Observation { id: o.id, bbox: o.bbox, depth: None }));
        }
        self.health.tracks = self.obs.len() as u32;
        self.health.detector_hz = self.det_rate.hz();
        self.health.depth_hz = self.depth_rate.hz();
        Ok(())
    }

    /// Eq. 5 on this frame's observations, with each fish's depth read at its corrected box, and the
    /// sample the outputs publish.
    fn estimate(&mut self, t: Seconds) -> (SwarmEstimate, ActivitySample) {
        // On the fish's scale with the configured length, every fish is as long as the ruler
        // (`ActivityEstimator::set_ruler_length`). With a length measured under the references the
        // fit carries their scale on, and the lengths measured under it with it.
        let state = self.scale.state();
        let ruler =
            (state.source == ScaleSource::Fish && !state.ruler_length_learned).then_some(Metres(state.ruler_length_m));
        self.estimator.set_ruler_length(ruler);
        // Field by field, so the estimator can be borrowed mutably beside it.
        let map = sampled_map(&self.depth, &self.substitute);
        let (fit, how, obs) = (self.scale.fit(), self.cfg.depth.sample, &self.obs);
        let s = self.estimator.update_with(t, obs, |o, px| {
            let map = map?;
            let b = PixelBox::from_center(px, o.bbox.w, o.bbox.h);
            let others = obs.iter().filter(|x| x.id != o.id).map(|x| &x.bbox);
            let r = sample_fish(how, map.kind(), &b, others, || map.point(px), |p| map.grid(p))?;
            match map.kind() {
                MapKind::Depth => Some(Metres(r)),
                MapKind::InverseDepth => fit?.depth(r),
            }
        });
        let metric = self.scale.fit().is_some() || map.is_some_and(|v| v.kind() == MapKind::Depth);
        let mean = s.mean.map_or(f64::NAN, |m| m.0);
        let bls = match self.cfg.motion.body_length() {
            Some(l) => mean / l.0,
            None => s.mean_bls.unwrap_or(f64::NAN),
        };
        let sample = ActivitySample {
            timestamp: t,
            mean: MetresPerSecond(mean),
            mean_body_lengths: bls,
            smoothed: MetresPerSecond(s.smoothed.map_or(f64::NAN, |m| m.0)),
            ci95_half: MetresPerSecond(s.ci95.map_or(f64::NAN, |(lo, hi)| 0.5 * (hi.0 - lo.0))),
            fish: s.n_fish as u32,
            latency: s.latency,
            flags: QualityFlags {
                too_few_fish: (s.n_fish as u32) < self.cfg.motion.min_fish,
                unfitted: !metric,
                stale: false,
                unlike_fish: self.familiarity.unlike_fish(),
            },
            scale: state.source,
        };
        (s, sample)
    }

    /// Runs the detector, or takes the substitute's detections, and updates the tracker.
    fn detect(&mut self, frame: &Frame, rgb: Option<&RgbFrame<'_>>) -> Result<(), PipelineError> {
        let t = frame.timestamp;
        self.dets.clear();
        match (&mut self.detector, rgb) {
            (Some(det), Some(rgb)) => match det.detect(rgb, t) {
                Ok(d) => {
                    let footprints = &self.footprints;
                    self.dets.extend(
                        d.items
                            .iter()
                            .filter(|x| !footprints.covers(&x.bbox))
                            .map(|x| track::Detection::new(x.bbox, x.score)),
                    );
                }
                Err(e) => {
                    self.health.detector_ok = false;
                    return Err(PipelineError::Stage { stage: "detector", message: e.to_string() });
                }
            },
            _ => {
                if let Some(s) = self.substitute.as_mut() {
                    s.detections(frame, &mut self.dets)
                        .map_err(|message| PipelineError::Stage { stage: "detections", message })?;
                }
            }
        }
        self.health.detector_ok = true;
        self.det_rate.record(t.0);
        self.health.detector_runs += 1;
        let matched = self
            .tracker
            .update(t, &self.dets)
            .map_err(|e| PipelineError::Stage { stage: "tracker", message: e.to_string() })?;
        self.familiarity.observe(t.0, self.dets.iter().map(|d| (d.bbox, d.score)), matched.iter().map(|o| o.id));
        self.health.familiarity = self.familiarity.state();
        Ok(())
    }

    /// Runs the depth network, or loads the substitute's map, then refits.
    fn depth_frame(&mut self, frame: &Frame, rgb: Option<&RgbFrame<'_>>) -> Result<(), PipelineError> {
        match (&mut self.depth, rgb) {
            (Some(net), Some(rgb)) => {
                if let Err(e) = net.estimate(rgb, frame.timestamp) {
                    self.health.depth_ok = false;
                    return Err(PipelineError::Stage { stage: "depth", message: e.to_string() });
                }
            }
            _ => {
                if let Some(s) = self.substitute.as_mut() {
                    s.load_depth(frame).map_err(|message| PipelineError::Stage { stage: "depth", message })?;
                }
            }
        }
        self.health.depth_ok = true;
        self.depth_rate.record(frame.timestamp.0);
        self.health.depth_runs += 1;
        // Field by field: the policy reads the map, the references and the estimator's fish.
        if let Some(map) = sampled_map(&self.depth, &self.substitute) {
            let fish = self.estimator.tracks().map(|f| (f.id, f.bbox, f.last_seen.0));
            let intrinsics = self.estimator.camera().intrinsics;
            self.scale.refit(frame.timestamp.0, map, &self.refs, &intrinsics, fish);
        }
        Ok(())
    }
}

/// The depth map sampled now: the network's last map, or the substitute's.
fn sampled_map<'a>(net: &'a Option<DepthNet>, sub: &'a Option<Box<dyn Substitute>>) -> Option<&'a dyn DepthGrid> {
    match (net, sub) {
        (Some(net), _) => net.last_map().map(|m| m as &dyn DepthGrid),
        (None, Some(s)) => s.depth(),
        (None, None) => None,
    }
}

/// What the scale policy reads of the config.
fn scale_config(cfg: &PipelineConfig) -> ScaleConfig {
    ScaleConfig {
        scale: cfg.depth.scale,
        method: cfg.depth.fit,
        sample: cfg.depth.sample,
        learn_length: cfg.depth.learn_fish_length,
        body_length: cfg.motion.body_length(),
        body_length_cv: cfg.motion.body_length_cv,
    }
}

/// A camera for an uncalibrated box (no speeds are reported without a fit, so only the image size
/// matters): 90 degrees horizontal field of view, identity pose.
fn fallback_camera(cfg: &PipelineConfig) -> Camera {
    let (w, h) = (cfg.frame_width.max(1), cfg.frame_height.max(1));
    let intrinsics = crate::geometry::Intrinsics::from_hfov(w, h, 90.0).unwrap_or(crate::geometry::Intrinsics {
        fx: 1.0,
        fy: 1.0,
        cx: 0.0,
        cy: 0.0,
        distortion: [0.0; 5],
    });
    Camera { intrinsics, pose: crate::geometry::Pose::identity() }
}

/// What a calibration sets up (at start and on a reload): the camera (the assumed lens without
/// one), the reference objects' pixels and, with `detector.ignore_references`, their footprints.
fn calibrated_parts(
    cfg: &PipelineConfig,
    calibration: Option<&Calibration>,
) -> (Camera, ReferencePoints, ReferenceFootprints) {
    let camera = calibration.map_or_else(|| fallback_camera(cfg), |c| c.camera);
    // References are kept if they fall inside the calibrated image (principal point at its centre);
    // sampling outside the actual frame returns nothing anyway.
    let (w, h) = ((2.0 * camera.intrinsics.cx).ceil() as u32, (2.0 * camera.intrinsics.cy).ceil() as u32);
    let refs =
        calibration.map(|c| ReferencePoints::project(&camera, c.references.iter().copied(), w, h)).unwrap_or_default();
    let footprints = match (calibration, cfg.detector.ignore_references) {
        (Some(c), true) => ReferenceFootprints::project(&camera, c.cubes.iter().copied()),
        _ => ReferenceFootprints::default(),
    };
    (camera, refs, footprints)
}

impl Pipeline for FishPipeline {
    fn process(&mut self, frame: &Frame) -> Result<FrameOutcome<'_>, PipelineError> {
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
        let tracks_given = self.substitute.as_ref().is_some_and(|s| s.replaces_tracks());
        if !tracks_given {
            self.tracker.predict(t).map_err(|e| PipelineError::Stage { stage: "tracker", message: e.to_string() })?;
        }
        self.run_networks(frame, plan, tracks_given)?;
        self.observe(frame, tracks_given)?;
        let (estimate, sample) = self.estimate(t);
        self.fish.clear();
        self.fish.extend(self.estimator.tracks());
        Ok(FrameOutcome {
            t,
            plan,
            detections: if plan.detect { &self.dets } else { &[] },
            observations: &self.obs,
            fish: &self.fish,
            estimate,
            sample: Some(sample),
            fit: self.scale.state(),
            fit_stats: self.scale.stats(),
            references_in_view: self.refs.len(),
            health: self.health,
            depth_map: if plan.depth { self.depth.as_ref().and_then(DepthNet::last_map) } else { None },
        })
    }

    fn health(&self) -> StageHealth {
        self.health
    }

    fn set_calibration(&mut self, calibration: Option<&Calibration>) -> Result<(), String> {
        if let Some(c) = calibration {
            c.camera.intrinsics.validate().map_err(|e| format!("{}: camera: {e}", c.path.display()))?;
        }
        self.recalibrate(calibration);
        Ok(())
    }

    fn networks(&self) -> Networks {
        let det =
            self.detector.as_ref().map(|d| Network { path: d.path().into(), form: d.form(), backend: d.backend() });
        let depth =
            self.depth.as_ref().map(|d| Network { path: d.path().into(), form: d.form(), backend: d.backend() });
        Networks { detector: det, depth }
    }

    fn reference_residuals(&self, out: &mut Vec<(crate::geometry::Pixel, f64)>) {
        out.clear();
        // Each reference with the fit's residual there (eq. 1-2): which one was measured wrong or
        // is fouled shows at a glance.
        let (map, fit) = (self.sampled_map(), self.scale.fit());
        out.extend(self.refs.iter().map(|(px, depth)| {
            let fitted = match map {
                Some(v) if v.kind() == MapKind::Depth => v.point(px).map(Metres),
                Some(v) => v.point(px).and_then(|r| fit?.depth(r)),
                None => None,
            };
            (px, fitted.map_or(f64::NAN, |d| d.0 - depth.0))
        }));
    }

    fn depth_grid(&self, size: (u32, u32), grid: (u32, u32), out: &mut Vec<f32>) -> bool {
        let Some(map) = self.sampled_map() else { return false };
        let fit = self.scale.fit();
        if map.kind() == MapKind::InverseDepth && fit.is_none() {
            return false;
        }
        out.clear();
        let (cw, ch) = (f64::from(size.0) / f64::from(grid.0.max(1)), f64::from(size.1) / f64::from(grid.1.max(1)));
        for r in 0..grid.1 {
            for c in 0..grid.0 {
                let px = crate::geometry::Pixel { u: (f64::from(c) + 0.5) * cw, v: (f64::from(r) + 0.5) * ch };
                let d = map.grid(px).and_then(|x| match map.kind() {
                    MapKind::Depth => Some(x),
                    MapKind::InverseDepth => fit.and_then(|f| f.depth(x)).map(|m| m.0),
                });
                out.push(d.map_or(f32::NAN, |d| d as f32));
            }
        }
        true
    }
}
