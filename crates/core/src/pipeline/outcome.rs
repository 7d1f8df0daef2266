//! What the pipeline produced on one frame, as one value: the daemon publishes its sample, the
//! black box and snapshots draw its detections and fish, and `fme eval`'s scorers read the rest.

use super::{ActivitySample, DepthFitState, FitStats, StageHealth};
use crate::infer::{FramePlan, RelDepthMap};
use crate::motion::{Fish, Observation, SwarmEstimate};
use crate::track::Detection;
use crate::units::Seconds;

/// Everything one frame produced (docs/pipeline.md#glossary "frame outcome"). Borrowed from the
/// pipeline until its next frame: nothing is copied or allocated to hand it out.
#[derive(Debug, Clone, Copy)]
pub struct FrameOutcome<'a> {
    /// The frame's timestamp (camera clock).
    pub t: Seconds,
    /// What ran on the frame (detector, depth network), on frame time.
    pub plan: FramePlan,
    /// The detections of the detector's run on this frame (empty when it did not run), after
    /// those on the reference cubes were dropped.
    pub detections: &'a [Detection],
    /// The tracked boxes that entered the motion estimator on this frame.
    pub observations: &'a [Observation],
    /// Every fish the estimator follows after this frame (`last_seen` says which were seen on it).
    pub fish: &'a [Fish],
    /// The motion estimator's result (eq. 5, corrections, latency).
    pub estimate: SwarmEstimate,
    /// The sample the outputs publish (eq. 5 with its flags and scale source); `None` when the
    /// pipeline has none for this frame.
    pub sample: Option<ActivitySample>,
    /// The depth fit in use (eq. 1-2) and what set its scale.
    pub fit: DepthFitState,
    /// Counts of the depth fits so far.
    pub fit_stats: FitStats,
    /// The reference objects inside the image.
    pub references_in_view: usize,
    /// The stages' health after the frame.
    pub health: StageHealth,
    /// The depth network's map when it ran on this frame (`None` on other frames and when a
    /// substitute replaces the network).
    pub depth_map: Option<&'a RelDepthMap>,
}

impl FrameOutcome<'static> {
    /// The outcome of a pipeline that only gives a sample and its health (test doubles, replays).
    pub fn sample_only(sample: Option<ActivitySample>, health: StageHealth) -> Self {
        Self {
            t: sample.map_or(Seconds(f64::NAN), |s| s.timestamp),
            plan: FramePlan::default(),
            detections: &[],
            observations: &[],
            fish: &[],
            estimate: SwarmEstimate::default(),
            sample,
            fit: DepthFitState::default(),
            fit_stats: FitStats::default(),
            references_in_view: 0,
            health,
            depth_map: None,
        }
    }
}

impl FrameOutcome<'_> {
    /// The fish seen on this frame (the others are still followed but were not observed on it).
    pub fn fish_seen(&self) -> impl Iterator<Item = &Fish> + Clone + '_ {
        let t = self.t;
        self.fish.iter().filter(move |f| f.last_seen == t)
    }
}
