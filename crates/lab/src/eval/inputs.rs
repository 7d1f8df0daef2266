//! Ground truth swapped into the pipeline for `fme eval --boxes gt|tracker|FILE` and
//! `--depth gt|relative-gt`: a [`Substitute`] over a sequence, so the daemon's pipeline runs around it
//! on its own schedule.

use super::EvalError;
use super::boxes::IndexedBoxes;
use super::relative::{RelativeGtParams, relative_at, sample_relative};
use fme_core::geometry::{Pixel, PixelBox};
use fme_core::metric::{MapKind, RelativeMap, sample_median};
use fme_core::pipeline::{DepthGrid, Frame, Substitute};
use fme_core::track::Detection;
use fme_edge::sequence::{DepthMap, Sequence};

/// Radius of the median window that reads ground-truth depth at a point (5x5, the paper's).
pub const GT_WINDOW: usize = 2;

/// What replaces the pipeline's boxes.
#[derive(Debug)]
pub enum BoxInput {
    /// The detector and the tracker run.
    Pipeline,
    /// Tracked boxes with ids, every frame (ground truth or a track file).
    Tracks(IndexedBoxes),
    /// Detections per frame (index 0 = frame 1) for the tracker, on the detector's frames.
    Detections(Vec<Vec<Detection>>),
}

/// What replaces the depth network.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthInput {
    /// The depth network runs.
    Pipeline,
    /// Ground-truth depth maps in metres (no fit needed).
    Metric,
    /// Ground truth made relative inverse depth with noise; the metric fit runs on it.
    Relative(RelativeGtParams),
}

/// A depth map read from the sequence: metres, or made relative.
#[derive(Debug)]
struct GtMap {
    frame: u32,
    map: DepthMap,
    metres: Vec<f32>,
    input: DepthInput,
    /// Reference pixels whose relative value reads 50% nearer (fouled references, `--foul-refs`).
    fouled: Vec<Pixel>,
}

impl DepthGrid for GtMap {
    fn kind(&self) -> MapKind {
        match self.input {
            DepthInput::Relative(_) => MapKind::InverseDepth,
            _ => MapKind::Depth,
        }
    }
    fn point(&self, px: Pixel) -> Option<f64> {
        match self.input {
            DepthInput::Relative(p) => {
                let r = sample_relative(&p, &self.map, self.frame, px, GT_WINDOW)?;
                Some(if self.fouled.contains(&px) { 1.5 * r } else { r })
            }
            _ => sample_median(&self.metres_map(), px, GT_WINDOW, |_| true),
        }
    }
    fn grid(&self, px: Pixel) -> Option<f64> {
        match self.input {
            DepthInput::Relative(p) => relative_at(&p, &self.map, self.frame, px),
            _ => self.metres_map().at(px),
        }
    }
}

impl GtMap {
    fn metres_map(&self) -> RelativeMap<'_> {
        RelativeMap { data: &self.metres, width: self.map.width as usize, height: self.map.height as usize }
    }
}

/// Ground truth for the stages `fme eval` replaces.
#[derive(Debug)]
pub struct GroundTruth {
    seq: Sequence,
    boxes: BoxInput,
    depth: DepthInput,
    map: Option<GtMap>,
    fouled: Vec<Pixel>,
}

impl GroundTruth {
    /// Ground truth of `seq` for the given stages; `fouled` lists reference pixels to foul.
    pub fn new(seq: Sequence, boxes: BoxInput, depth: DepthInput, fouled: Vec<Pixel>) -> Self {
        Self { seq, boxes, depth, map: None, fouled }
    }

    /// The sequence frame (1-based) a recorded frame is.
    fn frame_of(f: &Frame) -> u32 {
        u32::try_from(f.seq + 1).unwrap_or(u32::MAX)
    }
}

impl Substitute for GroundTruth {
    fn replaces_tracks(&self) -> bool {
        matches!(self.boxes, BoxInput::Tracks(_))
    }
    fn replaces_detector(&self) -> bool {
        matches!(self.boxes, BoxInput::Detections(_))
    }
    fn replaces_depth(&self) -> bool {
        self.depth != DepthInput::Pipeline
    }
    fn tracks(&mut self, frame: &Frame, out: &mut Vec<(u32, PixelBox)>) -> Result<(), String> {
        if let BoxInput::Tracks(b) = &self.boxes {
            b.frame_boxes(Self::frame_of(frame), out);
        }
        Ok(())
    }
    fn detections(&mut self, frame: &Frame, out: &mut Vec<Detection>) -> Result<(), String> {
        if let BoxInput::Detections(d) = &self.boxes
            && let Some(v) = d.get(Self::frame_of(frame) as usize - 1)
        {
            out.extend_from_slice(v);
        }
        Ok(())
    }
    fn load_depth(&mut self, frame: &Frame) -> Result<(), String> {
        let n = Self::frame_of(frame);
        let map = self.seq.read_depth(n).map_err(|e| e.to_string())?;
        let (w, h) = (self.seq.info.im_width, self.seq.info.im_height);
        if (map.width, map.height) != (w, h) {
            return Err(EvalError::Input {
                path: self.seq.depth_path(n),
                msg: format!("depth map is {}x{}, the sequence is {w}x{h}", map.width, map.height),
            }
            .to_string());
        }
        let mut metres = self.map.take().map(|m| m.metres).unwrap_or_default();
        to_metres(&map, &mut metres);
        self.map = Some(GtMap { frame: n, map, metres, input: self.depth, fouled: self.fouled.clone() });
        Ok(())
    }
    fn depth(&self) -> Option<&dyn DepthGrid> {
        self.map.as_ref().map(|m| m as &dyn DepthGrid)
    }
}

/// Millimetres (0 = none) to metres (NaN = none).
pub fn to_metres(depth: &DepthMap, out: &mut Vec<f32>) {
    out.clear();
    out.extend(depth.mm.iter().map(|&mm| if mm == 0 { f32::NAN } else { f32::from(mm) / 1000.0 }));
}
