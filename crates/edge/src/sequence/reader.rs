//! [`Sequence::open`]: load one sequence folder and check that its parts agree.

use super::{DepthMap, Error, GtBox, Meta, Result, SeqInfo, WorldRow, frame_file_name, read_depth_png};
use fme_core::geometry::Camera;
use fme_core::units::Seconds;
use std::path::{Path, PathBuf};

/// A sequence on disk with its ground truth loaded (frames and depth maps are read on demand).
///
/// Only `seqinfo.ini` and the frames are required: a plain MOTChallenge folder, or a recording the
/// box froze, opens as it is. `meta.json` (the calibration: camera, reference objects), `gt/gt.txt`,
/// `gt/world.csv` and `depth/` are read when present.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The sequence folder.
    pub dir: PathBuf,
    /// `seqinfo.ini`: frame rate, size and length of the sequence.
    pub info: SeqInfo,
    /// `meta.json` when present, with the frame rate, size and length it leaves out taken from
    /// `seqinfo.ini`.
    pub meta: Option<Meta>,
    /// Camera built from `meta.json` (none without one).
    pub camera: Option<Camera>,
    /// `gt/gt.txt` rows, in file order (sorted by frame, then id, for sequences fme writes); empty
    /// without the file ([`Self::has_gt`]).
    pub gt: Vec<GtBox>,
    /// Whether `gt/gt.txt` exists.
    pub has_gt: bool,
    /// `gt/world.csv` rows, in file order.
    pub world: Vec<WorldRow>,
    /// Whether `depth/` exists (then it holds one PNG per frame).
    pub has_depth: bool,
}

impl Sequence {
    /// Opens a sequence folder: reads `seqinfo.ini`, and `meta.json`, `gt/gt.txt`, `gt/world.csv`
    /// when present; checks that what `meta.json` states of size and length agrees with
    /// `seqinfo.ini`, that the first `seqLength` frame images (and depth maps, when `depth/` exists)
    /// are present, and that every row's frame lies in `1..=seqLength`. Frame images beyond
    /// `seqLength` are not part of the sequence.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        if !dir.is_dir() {
            return Err(Error::invalid(&dir, "not a sequence folder (does not exist or is not a directory)"));
        }
        let info_path = dir.join("seqinfo.ini");
        let info = SeqInfo::read(&info_path)?;
        let meta_path = dir.join("meta.json");
        let (meta, camera) = if meta_path.is_file() {
            let mut meta = Meta::read(&meta_path)?;
            let stated = |v: u32, truth: u32| v == 0 || v == truth;
            if !(stated(meta.width, info.im_width)
                && stated(meta.height, info.im_height)
                && stated(meta.frames, info.seq_length))
            {
                return Err(Error::invalid(
                    &meta_path,
                    format!(
                        "width/height/frames {}x{}/{} disagree with seqinfo.ini {}x{}/{}",
                        meta.width, meta.height, meta.frames, info.im_width, info.im_height, info.seq_length
                    ),
                ));
            }
            (meta.width, meta.height, meta.frames) = (info.im_width, info.im_height, info.seq_length);
            if meta.fps == 0.0 {
                meta.fps = info.frame_rate;
            }
            let camera = meta.camera(&meta_path)?;
            (Some(meta), Some(camera))
        } else {
            (None, None)
        };
        let gt_path = dir.join("gt").join("gt.txt");
        let has_gt = gt_path.is_file();
        let gt = if has_gt { super::read_gt(&gt_path)? } else { Vec::new() };
        // `world.csv` is fme's ground-truth extra: a recording labelled with a MOTChallenge tool
        // (boxes only) has none, and is scored for tracking and detection only.
        let world_path = dir.join("gt").join("world.csv");
        let world = if world_path.is_file() { super::read_world(&world_path)? } else { Vec::new() };
        let n = info.seq_length;
        if let Some(r) = gt.iter().find(|r| r.frame > n) {
            return Err(Error::invalid(&gt_path, format!("frame {} is beyond seqLength {n}", r.frame)));
        }
        if let Some(r) = world.iter().find(|r| r.frame > n) {
            return Err(Error::invalid(&world_path, format!("frame {} is beyond seqLength {n}", r.frame)));
        }
        let has_depth = dir.join("depth").is_dir();
        let seq = Self { dir, info, meta, camera, gt, has_gt, world, has_depth };
        for f in 1..=n {
            let p = seq.frame_path(f);
            if !p.is_file() {
                return Err(Error::invalid(&p, format!("frame {f} of {n} is missing")));
            }
            if seq.has_depth {
                let d = seq.depth_path(f);
                if !d.is_file() {
                    return Err(Error::invalid(&d, format!("depth map of frame {f} of {n} is missing")));
                }
            }
        }
        Ok(seq)
    }

    /// Number of frames.
    pub fn len(&self) -> u32 {
        self.info.seq_length
    }

    /// True for a sequence without frames.
    pub fn is_empty(&self) -> bool {
        self.info.seq_length == 0
    }

    /// Path of the image of 1-based frame `frame`.
    pub fn frame_path(&self, frame: u32) -> PathBuf {
        self.dir.join(&self.info.im_dir).join(frame_file_name(frame, &self.info.im_ext))
    }

    /// Paths of all frame images, in order.
    pub fn frame_paths(&self) -> Vec<PathBuf> {
        (1..=self.len()).map(|f| self.frame_path(f)).collect()
    }

    /// Path of the depth map of 1-based frame `frame`.
    pub fn depth_path(&self, frame: u32) -> PathBuf {
        self.dir.join("depth").join(frame_file_name(frame, ".png"))
    }

    /// Paths of all depth maps, in order (empty when the sequence has none).
    pub fn depth_paths(&self) -> Vec<PathBuf> {
        if self.has_depth { (1..=self.len()).map(|f| self.depth_path(f)).collect() } else { Vec::new() }
    }

    /// Reads the depth map of a frame and checks its size.
    pub fn read_depth(&self, frame: u32) -> Result<DepthMap> {
        let p = self.depth_path(frame);
        let d = read_depth_png(&p)?;
        if (d.width, d.height) != (self.info.im_width, self.info.im_height) {
            return Err(Error::invalid(
                &p,
                format!(
                    "depth map is {}x{}, frames are {}x{}",
                    d.width, d.height, self.info.im_width, self.info.im_height
                ),
            ));
        }
        Ok(d)
    }

    /// Timestamp of a 1-based frame, `(frame - 1) / frameRate` (seqinfo.ini).
    pub fn timestamp(&self, frame: u32) -> Seconds {
        Seconds(f64::from(frame.saturating_sub(1)) / self.info.frame_rate)
    }

    /// The reference objects of `meta.json` (none without one).
    pub fn reference_objects(&self) -> &[super::ReferenceObject] {
        self.meta.as_ref().map_or(&[], |m| m.reference_objects.as_slice())
    }

    /// Ground-truth boxes of one frame (a linear scan; index once for hot loops).
    pub fn gt_of_frame(&self, frame: u32) -> impl Iterator<Item = &GtBox> {
        self.gt.iter().filter(move |r| r.frame == frame)
    }
}
