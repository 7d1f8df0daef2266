//! What `fme eval` swaps in for a stage and what it collects; everything else is the one config.

use super::BoxesChoice;
use super::relative::RelativeGtParams;

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
