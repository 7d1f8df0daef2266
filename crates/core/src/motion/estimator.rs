//! The per-frame activity estimator (paper section 3.3, eq. 5).

use super::heading::{
    AlongRay, LengthHistogram, SWARM_LENGTH_MEMORY_S, fish_length, foreshortening, ruler_foreshortening,
    speed_from_heading, swarm_floor,
};
use super::stats::mean_ci95;
use crate::geometry::{Camera, CameraPoint, Pixel, PixelBox, WorldPoint, angle_between, apparent_length};
use crate::postprocess::{PostprocessConfig, TrackFilter};
use crate::units::{Metres, MetresPerSecond, Seconds};
use heapless::Deque;

/// Positions kept per track for the speed span.
const POSITIONS: usize = 32;

/// How a fish's speed is computed from its recent world positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SpeedMethod {
    /// `|P_t - P_ref| / (t - t_ref)` with `P_ref` the oldest position within `speed_span` (at least
    /// the previous one): with span 0 this is the paper's frame-to-frame speed.
    #[default]
    Chord,
    /// Norm of the least-squares slope of position against time over the positions within
    /// `speed_span` (at least 3 of them, else the chord): per-fish velocity noise falls with the
    /// number of positions, and so does the upward bias that noise gives `|v|`.
    Regression,
}

impl crate::choice::Choice for SpeedMethod {
    const ALL: &'static [Self] = &[Self::Chord, Self::Regression];
}

/// One stored observation of a track.
#[derive(Debug, Clone, Copy)]
struct Position {
    /// Frame time, s.
    t: f64,
    /// Box centre lifted with the corrected depth, camera frame, m (speed norms are the same as in
    /// the world frame; the camera frame separates motion across and along the line of sight).
    p: [f64; 3],
    /// Distance from the camera, m.
    range: f64,
    /// Apparent body length ([`apparent_length`]), m; NaN when unknown.
    apparent: f64,
}

impl Position {
    /// Unit line of sight: what the box motion measures without depth.
    fn unit(&self) -> [f64; 3] {
        [self.p[0] / self.range, self.p[1] / self.range, self.p[2] / self.range]
    }
}

/// Within `span` of `t` (the same tolerance everywhere).
fn within(sample: &Position, t: f64, span: f64) -> bool {
    t - sample.t <= span * (1.0 + 1e-6) + 1e-9
}

/// Least-squares velocity of `coords(sample)` over the samples within `span` of `t`; `None` for
/// fewer than 3. Returns the velocity's norm and the time it refers to (the window's mean time).
fn regression_speed(
    samples: &Deque<Position, POSITIONS>,
    t: f64,
    span: f64,
    coords: impl Fn(&Position) -> [f64; 3],
) -> Option<(f64, f64)> {
    let inside = || samples.iter().filter(|p| within(p, t, span));
    let n = inside().count();
    if n < 3 {
        return None;
    }
    let tm = inside().map(|p| p.t).sum::<f64>() / n as f64;
    let mut pm = [0.0; 3];
    for p in inside() {
        for (m, x) in pm.iter_mut().zip(coords(p)) {
            *m += x / n as f64;
        }
    }
    let (mut stt, mut stp) = (0.0, [0.0; 3]);
    for p in inside() {
        let dt = p.t - tm;
        stt += dt * dt;
        for ((s, x), m) in stp.iter_mut().zip(coords(p)).zip(pm) {
            *s += dt * (x - m);
        }
    }
    (stt > 0.0).then(|| ((stp[0] * stp[0] + stp[1] * stp[1] + stp[2] * stp[2]).sqrt() / stt, tm))
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Most fish the estimator holds at once; its table is allocated once with this size.
pub const MAX_FISH: usize = 256;

/// Motion settings: the `[motion]` section of the config (paper eq. 5 and the activity sample).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Mean fish body length for body lengths/s, m; 0 = estimated per fish
    /// ([`super::heading::fish_length`]).
    pub body_length_m: Metres,
    /// Spread of the cohort's lengths: standard deviation over the mean (a graded cohort about 0.1).
    /// The fish fit (`depth.scale`) accepts a fish as a ruler within twice this of the others.
    pub body_length_cv: f64,
    /// Fewer fish in the mean than this raises the "too few fish" status bit.
    pub min_fish: u32,
    /// Time constant of the exponential smoothing of the activity index, s.
    pub smoothing_s: Seconds,
    /// Speed is taken over the oldest stored position at most this long ago (at least the previous
    /// one), s: 0 = frame to frame, as the paper. Longer spans trade latency for less noise (at most
    /// 32 positions are kept, so spans beyond 32 frames use the oldest of those).
    pub speed_span_s: Seconds,
    /// A fish enters the mean only once it has been tracked this long, s: a young track's speed is a
    /// chord over its first few frames, noisy and biased. 0 = every fish with two positions, as the
    /// paper.
    pub min_age_s: Seconds,
    /// Chord (the paper) or least-squares regression over the span.
    pub speed_method: SpeedMethod,
    /// Where the speed along the line of sight comes from: the fish's heading
    /// ([`super::heading`]) or the change of its depth (the paper).
    pub along_ray: AlongRay,
    /// A fish's width over its length, as seen head-on (salmon about 0.1): the heading method's
    /// foreshortening model.
    pub body_width_ratio: f64,
    /// A track not seen for this long is forgotten (its slot is reused), s.
    pub track_timeout_s: Seconds,
    /// Per-fish speeds above this are treated as glitches and left out of the mean, m/s.
    pub max_speed_mps: MetresPerSecond,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            body_length_m: Metres(0.35),
            body_length_cv: 0.1,
            min_fish: 3,
            smoothing_s: Seconds(60.0),
            // 1 s chords instead of the paper's frame-to-frame speed (docs/accuracy.md, ablations);
            // the estimate then refers to t - 0.5 s (`SwarmEstimate::latency`).
            speed_span_s: Seconds(1.0),
            // A full span before a fish counts (docs/accuracy.md, ablations).
            min_age_s: Seconds(1.0),
            speed_method: SpeedMethod::Chord,
            along_ray: AlongRay::Heading,
            body_width_ratio: 0.1,
            track_timeout_s: Seconds(1.0),
            max_speed_mps: MetresPerSecond(10.0),
        }
    }
}

impl MotionConfig {
    /// The configured body length, or `None` when it is estimated per fish (`body_length_m = 0`).
    pub fn body_length(&self) -> Option<Metres> {
        (self.body_length_m.0 > 0.0).then_some(self.body_length_m)
    }

    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.body_length_m.0.is_finite() && self.body_length_m.0 >= 0.0) {
            return Err("motion.body_length_m must be >= 0 m (0 = estimated per fish)");
        }
        if !(self.body_length_cv.is_finite() && (0.0..=0.5).contains(&self.body_length_cv)) {
            return Err("motion.body_length_cv must be within 0..=0.5");
        }
        if !(self.speed_span_s.0.is_finite() && self.speed_span_s.0 >= 0.0) {
            return Err("motion.speed_span_s must be zero or a positive number of seconds");
        }
        if !(self.min_age_s.0.is_finite() && self.min_age_s.0 >= 0.0) {
            return Err("motion.min_age_s must be zero or a positive number of seconds");
        }
        if !(self.body_width_ratio.is_finite() && (0.0..=0.5).contains(&self.body_width_ratio)) {
            return Err("motion.body_width_ratio must be within 0..=0.5");
        }
        if !(self.smoothing_s.0.is_finite() && self.smoothing_s.0 > 0.0) {
            return Err("motion.smoothing_s must be a positive number of seconds");
        }
        if !(self.track_timeout_s.0.is_finite() && self.track_timeout_s.0 > 0.0) {
            return Err("motion.track_timeout_s must be a positive number of seconds");
        }
        if !(self.max_speed_mps.0.is_finite() && self.max_speed_mps.0 > 0.0) {
            return Err("motion.max_speed_mps must be a positive speed in m/s");
        }
        Ok(())
    }
}

/// One tracked fish in one frame, as the tracker (or ground truth) gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Track identity, stable across frames.
    pub id: u32,
    /// The box in pixels.
    pub bbox: PixelBox,
    /// Metric depth (camera z) at the box centre, when known. Used by [`ActivityEstimator::update`];
    /// [`ActivityEstimator::update_with`] samples depth itself at the corrected centre.
    pub depth: Option<Metres>,
}

/// The activity index at one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct SwarmEstimate {
    /// Frame timestamp.
    pub t: Seconds,
    /// Number of fish whose speed entered the mean.
    pub n_fish: usize,
    /// Eq. 5: mean 3D speed over those fish; `None` when no fish has a speed yet.
    pub mean: Option<MetresPerSecond>,
    /// 95% t-interval of the mean (low, high).
    pub ci95: Option<(MetresPerSecond, MetresPerSecond)>,
    /// Mean of each fish's speed in its own body lengths per second.
    pub mean_bls: Option<f64>,
    /// The mean smoothed by an EWMA with time constant `motion.smoothing_s` (holds its last value
    /// through frames without fish).
    pub smoothed: Option<MetresPerSecond>,
    /// Observations whose box was corrected by eq. 3 this frame.
    pub boxes_corrected: u32,
    /// Observations whose depth was corrected by eq. 4 this frame.
    pub depths_corrected: u32,
    /// Observations left out: invalid box, no depth, time not increasing, table full.
    pub skipped: u32,
    /// How far back the speeds refer to: a speed over the span `[t_ref, t]` is the speed at its
    /// middle, so the mean refers to `t - latency` (half a frame for frame-to-frame speeds).
    pub latency: Seconds,
}

/// A track's state after the last update, for evaluation and diagnostics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fish {
    /// Track identity.
    pub id: u32,
    /// Time of its last observation.
    pub last_seen: Seconds,
    /// Corrected box of its last observation.
    pub bbox: PixelBox,
    /// Depth of its last observation as `depth_at` returned it (before eq. 4 and the smoothing).
    pub depth_measured: Option<Metres>,
    /// Corrected depth of its last observation.
    pub depth: Option<Metres>,
    /// World position of its last observation.
    pub position: Option<WorldPoint>,
    /// Speed at its last observation.
    pub speed: Option<MetresPerSecond>,
    /// Body length used for body lengths/s: the configured one, else the estimate of
    /// [`super::heading::fish_length`].
    pub length: Option<Metres>,
}

#[derive(Debug, Clone)]
struct FishMotion {
    id: u32,
    /// Time of its first observation.
    first_seen: f64,
    last_seen: f64,
    filter: TrackFilter,
    positions: Deque<Position, POSITIONS>,
    bbox: PixelBox,
    depth_measured: Option<Metres>,
    depth: Option<Metres>,
    speed: Option<f64>,
    lengths: LengthHistogram,
}

impl FishMotion {
    fn new(id: u32, first_seen: f64) -> Self {
        Self {
            id,
            first_seen,
            last_seen: f64::NEG_INFINITY,
            filter: TrackFilter::new(),
            positions: Deque::new(),
            bbox: PixelBox::default(),
            depth_measured: None,
            depth: None,
            speed: None,
            lengths: LengthHistogram::default(),
        }
    }
}

/// Turns per-frame tracked boxes into the activity index. See the module documentation.
#[derive(Debug, Clone)]
pub struct ActivityEstimator {
    capacity: usize,
    camera: Camera,
    motion: MotionConfig,
    post: PostprocessConfig,
    tracks: Vec<FishMotion>,
    smoothed: Option<(f64, f64)>,
    /// Apparent lengths of all fish, decaying with [`SWARM_LENGTH_MEMORY_S`], and when last decayed.
    swarm_lengths: LengthHistogram,
    swarm_lengths_t: f64,
    /// [`swarm_floor`] of `swarm_lengths` at the start of the frame.
    swarm_floor: Option<Metres>,
    /// The fish's length while the fish set the depth scale ([`Self::set_ruler_length`]).
    ruler_length: Option<Metres>,
}

impl ActivityEstimator {
    /// An estimator for a calibrated camera. Allocates the track table ([`MAX_FISH`]) once.
    pub fn new(camera: Camera, motion: MotionConfig, post: PostprocessConfig) -> Self {
        Self::with_capacity(MAX_FISH, camera, motion, post)
    }

    /// An estimator holding at most `capacity` fish (1..=[`MAX_FISH`]); allocates its table once.
    pub fn with_capacity(capacity: usize, camera: Camera, motion: MotionConfig, post: PostprocessConfig) -> Self {
        Self {
            capacity: capacity.clamp(1, MAX_FISH),
            camera,
            motion,
            post,
            tracks: Vec::with_capacity(capacity.clamp(1, MAX_FISH)),
            smoothed: None,
            swarm_lengths: LengthHistogram::default(),
            swarm_lengths_t: f64::NAN,
            swarm_floor: None,
            ruler_length: None,
        }
    }

    /// The length every fish is taken to have while the fish themselves set the depth scale (the
    /// fish as the ruler, `crate::metric::Rulers`): that scale makes the fish's broadside lengths
    /// the cohort's length, so measuring each fish's length again through those depths would only
    /// add their noise and the fits' changes, and an upper quantile of noisy lengths reads long (the
    /// speeds with it; docs/accuracy.md). Against the ruler's length the foreshortening is not capped
    /// ([`ruler_foreshortening`]). `None` (references, ground truth): measured per fish.
    pub fn set_ruler_length(&mut self, length: Option<Metres>) {
        self.ruler_length = length.filter(|l| l.0.is_finite() && l.0 > 0.0);
    }

    /// The camera positions are lifted with.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The motion settings.
    pub fn motion(&self) -> MotionConfig {
        self.motion
    }

    /// The post-processing settings.
    pub fn postprocess(&self) -> PostprocessConfig {
        self.post
    }

    /// Tracks currently held (seen within `motion.track_timeout_s`).
    pub fn tracks(&self) -> impl Iterator<Item = Fish> + '_ {
        self.tracks.iter().map(|s| Fish {
            id: s.id,
            last_seen: Seconds(s.last_seen),
            bbox: s.bbox,
            depth_measured: s.depth_measured,
            depth: s.depth,
            position: s.positions.back().map(|p| self.camera.pose.to_world(&CameraPoint::new(p.p[0], p.p[1], p.p[2]))),
            speed: s.speed.map(MetresPerSecond),
            length: self.length_of(s),
        })
    }

    fn length_of(&self, s: &FishMotion) -> Option<Metres> {
        self.motion.body_length().or_else(|| fish_length(&s.lengths, self.swarm_floor))
    }

    /// One frame, with the depth carried by each observation (sampled at the raw box centre).
    pub fn update(&mut self, t: Seconds, observations: &[Observation]) -> SwarmEstimate {
        self.update_with(t, observations, |o, _| o.depth)
    }

    /// One frame; `depth_at(observation, corrected_centre)` returns the metric depth there (e.g. a
    /// median window of the metric depth map), so depth follows the eq. 3 correction.
    pub fn update_with(
        &mut self,
        t: Seconds,
        observations: &[Observation],
        mut depth_at: impl FnMut(&Observation, Pixel) -> Option<Metres>,
    ) -> SwarmEstimate {
        let mut out = SwarmEstimate { t, ..Default::default() };
        let (mut n, mut sum, mut sum_sq, mut lag) = (0usize, 0.0, 0.0, 0.0);
        let (mut n_bl, mut sum_bl) = (0usize, 0.0);
        // The swarm's lengths fade with time, so they follow the fish in view.
        if t.0.is_finite() {
            if self.swarm_lengths_t.is_finite() && t.0 > self.swarm_lengths_t {
                self.swarm_lengths.decay((-(t.0 - self.swarm_lengths_t) / SWARM_LENGTH_MEMORY_S).exp() as f32);
            }
            if self.swarm_lengths_t.is_nan() || t.0 > self.swarm_lengths_t {
                self.swarm_lengths_t = t.0;
            }
        }
        // Lengths are only needed by the heading method and for an estimated body length: with the
        // depth chord and a configured length, none of this runs per fish.
        let wants_lengths = self.motion.along_ray == AlongRay::Heading || self.motion.body_length().is_none();
        self.swarm_floor = if wants_lengths { swarm_floor(&self.swarm_lengths) } else { None };
        // Forget tracks not seen for too long, so their slots can be reused.
        let timeout = self.motion.track_timeout_s.0;
        self.tracks.retain(|s| t.0 - s.last_seen <= timeout || !t.0.is_finite());
        for obs in observations {
            if !obs.bbox.is_valid() || !t.0.is_finite() {
                out.skipped += 1;
                continue;
            }
            let idx = match self.tracks.iter().position(|s| s.id == obs.id) {
                Some(i) => i,
                None if self.tracks.len() < self.capacity => {
                    self.tracks.push(FishMotion::new(obs.id, t.0));
                    self.tracks.len() - 1
                }
                None => {
                    out.skipped += 1;
                    continue;
                }
            };
            let s = &mut self.tracks[idx];
            if t.0 <= s.last_seen {
                out.skipped += 1;
                continue;
            }
            s.last_seen = t.0;
            let corr = s.filter.correct_box(&self.post, t, obs.bbox);
            out.boxes_corrected += (corr.width_corrected || corr.height_corrected) as u32;
            s.bbox = corr.bbox;
            let centre = corr.bbox.center();
            s.depth_measured = depth_at(obs, centre);
            let (depth, jumped) = s.filter.correct_depth(&self.post, t, s.depth_measured);
            out.depths_corrected += jumped as u32;
            s.depth = depth;
            s.speed = None;
            let Some(point) = depth.and_then(|d| self.camera.intrinsics.unproject(centre, d).ok()) else {
                out.skipped += 1;
                continue;
            };
            let range = point.range().0;
            let apparent = if wants_lengths {
                apparent_length(&self.camera.intrinsics, &corr.bbox, Metres(range)).0
            } else {
                f64::NAN
            };
            if apparent.is_finite() && apparent > 0.0 {
                s.lengths.add(Metres(apparent));
                self.swarm_lengths.add(Metres(apparent));
            }
            // Reference position: the oldest within the speed span, at least the previous one.
            while s.positions.front().is_some_and(|p| t.0 - p.t > timeout) || s.positions.is_full() {
                s.positions.pop_front();
            }
            let span = self.motion.speed_span_s.0;
            let reference = s.positions.iter().find(|p| within(p, t.0, span)).or(s.positions.back()).copied();
            let now = Position { t: t.0, p: [point.0.x, point.0.y, point.0.z], range, apparent };
            let _ = s.positions.push_back(now);
            let Some(reference) = reference else { continue };
            let regression = |coords: fn(&Position) -> [f64; 3]| match self.motion.speed_method {
                SpeedMethod::Regression => regression_speed(&s.positions, t.0, span, coords),
                SpeedMethod::Chord => None,
            };
            let chord_time = 0.5 * (t.0 + reference.t);
            let estimated_length = || self.ruler_length.or_else(|| fish_length(&s.lengths, self.swarm_floor));
            let (v, t_ref) = match self.motion.along_ray {
                AlongRay::Depth => regression(|p| p.p)
                    .unwrap_or_else(|| (distance(now.p, reference.p) / (t.0 - reference.t), chord_time)),
                AlongRay::Heading => {
                    // Speed across the line of sight (its angular speed times the mean range of the
                    // span), over the foreshortening averaged over the same span: one pass for the
                    // mean range and the mean apparent length where known.
                    let (mut n_in, mut range_sum, mut n_seen, mut seen_sum) = (0usize, 0.0, 0usize, 0.0);
                    for p in s.positions.iter().filter(|p| p.t >= reference.t) {
                        n_in += 1;
                        range_sum += p.range;
                        if p.apparent.is_finite() && p.apparent > 0.0 {
                            n_seen += 1;
                            seen_sum += p.apparent;
                        }
                    }
                    let range = range_sum / n_in as f64;
                    let (across, t_ref) =
                        regression(Position::unit).map(|(w, tm)| (w * range, tm)).unwrap_or_else(|| {
                            (range * angle_between(now.p, reference.p) / (t.0 - reference.t), chord_time)
                        });
                    let depth_chord = regression(|p| p.p)
                        .map_or_else(|| distance(now.p, reference.p) / (t.0 - reference.t), |(v, _)| v);
                    let apparent = (n_seen > 0).then(|| Metres(seen_sum / n_seen as f64));
                    let cos = apparent.zip(estimated_length()).and_then(|(a, l)| match self.ruler_length {
                        Some(_) => ruler_foreshortening(a, l, self.motion.body_width_ratio),
                        None => foreshortening(a, l, self.motion.body_width_ratio),
                    });
                    (cos.map_or(f64::NAN, |c| speed_from_heading(across, c, depth_chord)), t_ref)
                }
            };
            if !v.is_finite() || v > self.motion.max_speed_mps.0 {
                out.skipped += 1;
                continue;
            }
            s.speed = Some(v);
            if t.0 - s.first_seen < self.motion.min_age_s.0 * (1.0 - 1e-6) {
                continue;
            }
            n += 1;
            sum += v;
            sum_sq += v * v;
            lag += t.0 - t_ref;
            if let Some(l) = self.motion.body_length().or_else(estimated_length) {
                n_bl += 1;
                sum_bl += v / l.0;
            }
        }
        if let Some((mean, lo, hi)) = mean_ci95(n, sum, sum_sq) {
            out.n_fish = n;
            out.latency = Seconds(lag / n as f64);
            out.mean = Some(MetresPerSecond(mean));
            out.ci95 = Some((MetresPerSecond(lo.max(0.0)), MetresPerSecond(hi)));
            self.smoothed = Some(match self.smoothed {
                Some((t_prev, s)) if t.0 > t_prev => {
                    let a = 1.0 - (-(t.0 - t_prev) / self.motion.smoothing_s.0).exp();
                    (t.0, s + a * (mean - s))
                }
                Some((t_prev, s)) => (t_prev, s),
                None => (t.0, mean),
            });
        }
        out.mean_bls = (n_bl > 0).then(|| sum_bl / n_bl as f64);
        out.smoothed = self.smoothed.map(|s| MetresPerSecond(s.1));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use nalgebra::Vector3;

    fn camera() -> Camera {
        let k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        let pose =
            Pose::look_at(WorldPoint::new(0.0, -3.0, 1.5), WorldPoint::new(0.0, 0.0, 1.5), Vector3::z()).unwrap();
        Camera { intrinsics: k, pose }
    }

    /// Observation of a fish whose box centre is at world point `p`, box 40 x 16 px.
    fn observe(cam: &Camera, id: u32, p: WorldPoint) -> Observation {
        let px = cam.world_to_pixel(&p).unwrap();
        let depth = cam.pose.to_camera(&p).depth();
        Observation { id, bbox: PixelBox::from_center(px, 40.0, 16.0), depth: Some(depth) }
    }

    #[test]
    fn speed_of_known_trajectories_with_irregular_timestamps() {
        let cam = camera();
        // Every fish in the mean from its second position (`min_age` 0, as the paper); lengths estimated.
        let cfg = MotionConfig {
            along_ray: AlongRay::Depth,
            min_age_s: Seconds(0.0),
            body_length_m: Metres(0.0),
            ..Default::default()
        };
        let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::off());
        // Fish 1 at 0.5 m/s along world x; fish 2 at 0.3 m/s along world y (depth direction).
        let times = [0.0, 0.033, 0.07, 0.1, 0.15, 0.2, 0.26];
        let mut last = SwarmEstimate::default();
        for (i, &t) in times.iter().enumerate() {
            let obs = [
                observe(&cam, 1, WorldPoint::new(-1.0 + 0.5 * t, 1.0, 1.2)),
                observe(&cam, 2, WorldPoint::new(0.5, 0.5 + 0.3 * t, 1.8)),
            ];
            last = est.update(Seconds(t), &obs);
            if i == 0 {
                assert_eq!(last.n_fish, 0);
                assert!(last.mean.is_none());
            } else {
                assert_eq!(last.n_fish, 2);
                assert!((last.mean.unwrap().0 - 0.4).abs() < 1e-9, "{last:?}");
            }
        }
        let (lo, hi) = last.ci95.unwrap();
        // Two fish, 0.5 and 0.3: sd = 0.1414, half-width 12.706 * 0.1 = 1.2706, clamped at 0.
        assert_eq!(lo.0, 0.0);
        assert!((hi.0 - (0.4 + 12.706 * 0.1)).abs() < 1e-6);
        assert!((last.smoothed.unwrap().0 - 0.4).abs() < 1e-9);
        let v: Vec<_> = est.tracks().collect();
        assert_eq!(v.len(), 2);
        // Estimated length: 40 px / 320 px * depth, to the length histogram's resolution.
        let d1 = cam.pose.to_camera(&WorldPoint::new(-1.0 + 0.5 * 0.26, 1.0, 1.2)).depth().0;
        assert!((v[0].length.unwrap().0 / (40.0 / 320.0 * d1) - 1.0).abs() < 0.045, "{:?}", v[0].length);
        assert!(last.mean_bls.unwrap() > 0.0);
    }

    #[test]
    fn body_lengths_from_config_span_and_timeout() {
        let cam = camera();
        let cfg = MotionConfig {
            body_length_m: Metres(0.5),
            speed_span_s: Seconds(0.1),
            min_age_s: Seconds(0.0),
            along_ray: AlongRay::Depth,
            track_timeout_s: Seconds(0.5),
            ..Default::default()
        };
        let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::default());
        let mut s = SwarmEstimate::default();
        for i in 0..20 {
            let t = i as f64 / 30.0;
            s = est.update(Seconds(t), &[observe(&cam, 7, WorldPoint::new(0.2 * t, 1.0, 1.5))]);
        }
        assert!((s.mean.unwrap().0 - 0.2).abs() < 1e-9);
        assert!((s.mean_bls.unwrap() - 0.4).abs() < 1e-9);
        // Smoothed converges from the first value (0.2) and stays there.
        assert!((s.smoothed.unwrap().0 - 0.2).abs() < 1e-9);
        // A frame without fish keeps the smoothed value; a later frame forgets the stale track.
        let empty = est.update(Seconds(1.0), &[]);
        assert_eq!((empty.n_fish, empty.mean), (0, None));
        assert!(empty.smoothed.is_some());
        assert_eq!(est.tracks().count(), 1);
        est.update(Seconds(2.0), &[]);
        assert_eq!(est.tracks().count(), 0);
    }

    #[test]
    fn chord_and_regression_over_a_span_report_their_latency() {
        let cam = camera();
        for method in [SpeedMethod::Chord, SpeedMethod::Regression] {
            let cfg = MotionConfig {
                speed_span_s: Seconds(0.5),
                speed_method: method,
                along_ray: AlongRay::Depth,
                ..Default::default()
            };
            let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::off());
            let mut s = SwarmEstimate::default();
            for i in 0..40 {
                let t = i as f64 / 30.0;
                // Accelerating along x: v(t) = 0.2 + 0.6 t.
                let x = 0.2 * t + 0.3 * t * t;
                s = est.update(Seconds(t), &[observe(&cam, 1, WorldPoint::new(x, 1.0, 1.5))]);
            }
            let t = 39.0 / 30.0;
            // Both estimate the speed at the window's middle, t - 0.25 s.
            assert!((s.latency.0 - 0.25).abs() < 1e-9, "{method:?} {s:?}");
            let v_mid = 0.2 + 0.6 * (t - 0.25);
            assert!((s.mean.unwrap().0 - v_mid).abs() < 1e-6, "{method:?}: {} vs {v_mid}", s.mean.unwrap().0);
        }
    }

    #[test]
    fn a_fish_enters_the_mean_once_it_is_old_enough() {
        let cam = camera();
        let cfg = MotionConfig { min_age_s: Seconds(0.5), along_ray: AlongRay::Depth, ..Default::default() };
        let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::off());
        // Fish 1 from t = 0 at 0.3 m/s; fish 2 appears at t = 1 s at 0.6 m/s.
        for i in 0..60 {
            let t = i as f64 / 30.0;
            let mut obs = vec![observe(&cam, 1, WorldPoint::new(0.3 * t, 1.0, 1.5))];
            if t >= 1.0 - 1e-9 {
                obs.push(observe(&cam, 2, WorldPoint::new(-0.5 + 0.6 * (t - 1.0), 1.2, 1.4)));
            }
            let s = est.update(Seconds(t), &obs);
            // At frame i fish 1 is i / 30 s old (15 frames = 0.5 s), fish 2 (i - 30) / 30 s.
            let expected = usize::from(i >= 15) + usize::from(i >= 45);
            assert_eq!(s.n_fish, expected, "frame {i}: {s:?}");
            if i < 15 {
                assert!(s.mean.is_none());
            } else if i < 45 {
                assert!((s.mean.unwrap().0 - 0.3).abs() < 1e-9, "frame {i}: {s:?}");
            } else {
                assert!((s.mean.unwrap().0 - 0.45).abs() < 1e-9, "frame {i}: {s:?}");
            }
            // A young fish still has its own speed for diagnostics.
            if (31..45).contains(&i) {
                let young = est.tracks().find(|v| v.id == 2).unwrap();
                assert!((young.speed.unwrap().0 - 0.6).abs() < 1e-9);
            }
        }
        assert!(MotionConfig { min_age_s: Seconds(f64::NAN), ..Default::default() }.validate().is_err());
    }

    /// Fish 0.4 m long (0.04 m wide, 0.08 m high) swimming at 0.5 m/s, first across the image, then
    /// turned 0-60 degrees out of the image plane; their boxes are drawn as their bodies project, and
    /// their depth readings scatter by up to 0.1 m from frame to frame. `heading` recovers each fish's
    /// speed from box motion and foreshortening, the turned fish from their own length, one that
    /// appears already turned from the swarm's median: within 15 % (the foreshortening model is within
    /// 0.05 up to 60 degrees, the length histogram within 4.4 %); the depth change is off by half as
    /// much again in all.
    #[test]
    fn heading_recovers_speed_out_of_the_image_plane() {
        let cam = camera();
        let (fx, fy) = (cam.intrinsics.fx, cam.intrinsics.fy);
        let (len, v, dt) = (0.4, 0.5, 1.0 / 30.0);
        let angles = [0.0f64, 30.0, 45.0, 60.0, 60.0];
        let run = |along_ray, speed_method| {
            let cfg = MotionConfig { along_ray, speed_method, ..Default::default() };
            let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::off());
            // Turned fish start on the left, where turning away from the camera still shows their length.
            let mut pos: Vec<[f64; 3]> = [0.0, -0.4, -0.8, -1.5, -1.0]
                .iter()
                .enumerate()
                .map(|(i, &x)| [x, 0.4 + 0.2 * i as f64, 1.5])
                .collect();
            for k in 0..90 {
                let t = k as f64 * dt;
                let mut obs = Vec::new();
                for (i, p) in pos.iter_mut().enumerate() {
                    // Fish 4 is only seen in the last half second, already turned.
                    if i == 4 && k < 75 {
                        continue;
                    }
                    let a = if t < 1.5 && i < 4 { 0.0 } else { angles[i].to_radians() };
                    if k > 0 {
                        p[0] += v * dt * a.cos();
                        p[1] += v * dt * a.sin();
                    }
                    let w = WorldPoint::new(p[0], p[1], p[2]);
                    let z = cam.pose.to_camera(&w).depth().0;
                    // Snout and tail as the camera sees them, plus the body's width seen end-on.
                    let end = |k: f64| {
                        let e = WorldPoint::new(p[0] + k * len * a.cos(), p[1] + k * len * a.sin(), p[2]);
                        cam.world_to_pixel(&e).unwrap().u
                    };
                    let bbox = PixelBox::from_center(
                        cam.world_to_pixel(&w).unwrap(),
                        (end(0.5) - end(-0.5)).abs() + 0.1 * len * a.sin() * fx / z,
                        0.08 * fy / z,
                    );
                    let scatter = 0.1 * (k as f64 * 2.399 + i as f64).sin();
                    obs.push(Observation { id: i as u32, bbox, depth: Some(Metres(z + scatter)) });
                }
                est.update(Seconds(t), &obs);
            }
            let mut speeds = [0.0; 5];
            for tv in est.tracks() {
                speeds[tv.id as usize] = tv.speed.unwrap().0;
            }
            speeds
        };
        for method in [SpeedMethod::Chord, SpeedMethod::Regression] {
            for (i, s) in run(AlongRay::Heading, method).iter().enumerate() {
                assert!((s / v - 1.0).abs() < 0.15, "heading, {method:?}, fish {i} at {} degrees: {s} m/s", angles[i]);
            }
        }
        let heading = run(AlongRay::Heading, SpeedMethod::Chord);
        let depth = run(AlongRay::Depth, SpeedMethod::Chord);
        let err = |s: &[f64; 5]| s.iter().map(|x| (x - v).abs()).sum::<f64>();
        assert!(err(&depth) > 1.5 * err(&heading), "depth {depth:?}, heading {heading:?}");
    }

    /// With a ruler length (the fish as the ruler), every fish is taken at that length, without the
    /// cap at 1: a long fish reads slow, a short one fast, the mean near right. Measured lengths
    /// give each its own speed.
    #[test]
    fn a_ruler_length_sets_every_fish_length() {
        let cam = camera();
        let (v, dt) = (0.4, 1.0 / 30.0);
        let lengths = [0.3, 0.4];
        let run = |ruler: Option<Metres>| {
            let cfg = MotionConfig { body_length_m: Metres(0.35), ..Default::default() };
            let mut est = ActivityEstimator::new(cam, cfg, PostprocessConfig::off());
            est.set_ruler_length(ruler);
            for k in 0..60 {
                let t = k as f64 * dt;
                let obs: Vec<_> = lengths
                    .iter()
                    .enumerate()
                    .map(|(i, &len)| {
                        // Broadside, swimming across the image at `v`.
                        let w = WorldPoint::new(-0.6 + v * t, 0.5 + 0.3 * i as f64, 1.5);
                        let z = cam.pose.to_camera(&w).depth();
                        let end =
                            |e: f64| cam.world_to_pixel(&WorldPoint::new(w.0.x + e * len, w.0.y, w.0.z)).unwrap().u;
                        let bbox = PixelBox::from_center(
                            cam.world_to_pixel(&w).unwrap(),
                            end(0.5) - end(-0.5),
                            0.2 * len * cam.intrinsics.fy / z.0,
                        );
                        Observation { id: i as u32, bbox, depth: Some(z) }
                    })
                    .collect();
                est.update(Seconds(t), &obs);
            }
            let mut speeds = [0.0; 2];
            for tv in est.tracks() {
                speeds[tv.id as usize] = tv.speed.unwrap().0;
            }
            speeds
        };
        for (i, s) in run(None).iter().enumerate() {
            assert!((s / v - 1.0).abs() < 0.05, "measured, fish {i}: {s}");
        }
        let ruled = run(Some(Metres(0.35)));
        for (i, s) in ruled.iter().enumerate() {
            let want = v * 0.35 / lengths[i];
            assert!((s / want - 1.0).abs() < 0.05, "ruler, fish {i}: {s} m/s, want {want}");
        }
        // Not a length: measured again.
        assert_eq!(run(Some(Metres(f64::NAN))), run(None));
    }

    #[test]
    fn bad_observations_are_skipped_not_propagated() {
        let cam = camera();
        let cfg = MotionConfig { min_age_s: Seconds(0.0), ..Default::default() };
        let mut est = ActivityEstimator::with_capacity(1, cam, cfg, PostprocessConfig::off());
        let good = observe(&cam, 1, WorldPoint::new(0.0, 1.0, 1.5));
        let nan_box = Observation { id: 2, bbox: PixelBox::new(f64::NAN, 0.0, 1.0, 1.0), depth: Some(Metres(1.0)) };
        let no_depth = Observation { depth: None, ..good };
        let s = est.update(Seconds(0.0), &[good, nan_box]);
        assert_eq!(s.skipped, 1);
        let s = est.update(Seconds(0.1), &[no_depth, Observation { id: 3, ..good }]);
        assert_eq!(s.skipped, 2, "no depth, and the table (1 track) is full");
        let s = est.update(Seconds(0.1), &[good]);
        assert_eq!(s.skipped, 1, "time did not increase for track 1");
        let s = est.update(Seconds(0.2), &[good]);
        assert_eq!((s.n_fish, s.mean), (1, Some(MetresPerSecond(0.0))));
        assert!(MotionConfig { speed_span_s: Seconds(-1.0), ..Default::default() }.validate().is_err());
    }
}
