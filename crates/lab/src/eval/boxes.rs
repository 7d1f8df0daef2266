//! Tracked boxes `fme eval` swaps in for the detector and tracker: ground truth or a track file.

use super::EvalError;
use fme_core::geometry::PixelBox;
use fme_edge::sequence::Sequence;
use fme_edge::sequence::mot_text::{ReadOptions, read_file};
use std::path::{Path, PathBuf};

/// Boxes indexed by frame, loaded up front.
#[derive(Debug, Clone)]
pub struct IndexedBoxes {
    name: String,
    by_frame: Vec<Vec<(u32, PixelBox)>>,
}

impl IndexedBoxes {
    /// Boxes per frame (index = 1-based frame number; index 0 unused).
    pub fn new(name: String, by_frame: Vec<Vec<(u32, PixelBox)>>) -> Self {
        Self { name, by_frame }
    }

    /// The ground-truth boxes of `gt/gt.txt` with their ids (the paper's GTBBox).
    pub fn ground_truth(seq: &Sequence) -> Self {
        let mut by_frame = vec![Vec::new(); seq.len() as usize + 1];
        for r in &seq.gt {
            if let Some(f) = by_frame.get_mut(r.frame as usize) {
                f.push((r.id, r.bbox));
            }
        }
        Self { name: "gt".into(), by_frame }
    }

    /// MOTChallenge tracks from a file (`frame,id,x,y,w,h,...`); rows with id -1 (untracked
    /// detections) are ignored; a frame beyond the sequence is an error naming the file.
    pub fn from_mot_file(path: &Path, frames: u32) -> Result<Self, EvalError> {
        let rows = read_file(path, ReadOptions::default())?;
        let mut by_frame = vec![Vec::new(); frames as usize + 1];
        for r in rows {
            if r.frame > frames {
                return Err(EvalError::Input {
                    path: path.to_path_buf(),
                    msg: format!("frame {} is beyond the sequence's {frames} frames", r.frame),
                });
            }
            if r.id >= 0 && r.id <= i64::from(u32::MAX) {
                by_frame[r.frame as usize].push((r.id as u32, r.bbox));
            }
        }
        Ok(Self { name: path.display().to_string(), by_frame })
    }
}

impl IndexedBoxes {
    /// Short name for reports (`gt` or the file).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Clears `out` and fills it with `(track id, box)` for `frame` (1-based).
    pub fn frame_boxes(&self, frame: u32, out: &mut Vec<(u32, PixelBox)>) {
        out.clear();
        if let Some(b) = self.by_frame.get(frame as usize) {
            out.extend_from_slice(b);
        }
    }
}

/// The `--boxes` choice.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BoxesChoice {
    /// `gt/gt.txt`.
    Gt,
    /// fme's tracker on the sequence's `det/det.txt`, or on noisy detections made from ground truth.
    Tracker,
    /// The pipeline's own detector and tracker.
    Model,
    /// A MOTChallenge track file.
    File(PathBuf),
}

impl std::str::FromStr for BoxesChoice {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "gt" => Self::Gt,
            "tracker" => Self::Tracker,
            "model" => Self::Model,
            other => Self::File(PathBuf::from(other)),
        })
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    /// `fme eval --boxes FILE` reads a comma-separated and a whitespace-separated file alike.
    #[test]
    fn box_files_may_be_comma_or_whitespace_separated() {
        let dir = tempfile::tempdir().expect("temp dir");
        let comma = dir.path().join("comma.txt");
        let spaces = dir.path().join("spaces.txt");
        std::fs::write(&comma, "1,3,10,20,30,40,1,-1,-1,-1\n2,3,11,20,30,40,1,-1,-1,-1\n2,-1,0,0,5,5,0.4\n")
            .expect("write");
        std::fs::write(&spaces, "1 3 10 20 30 40 1 -1 -1 -1\n2\t3\t11 20 30 40\n2 -1 0 0 5 5 0.4\n").expect("write");
        let mut out = Vec::new();
        for path in [&comma, &spaces] {
            let p = IndexedBoxes::from_mot_file(path, 2).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            p.frame_boxes(2, &mut out);
            assert_eq!(out, [(3, PixelBox::new(11.0, 20.0, 30.0, 40.0))], "{}", path.display());
        }
        std::fs::write(&spaces, "1 3 10 20 30 40\n2 3 11 x 30 40\n").expect("write");
        let e = IndexedBoxes::from_mot_file(&spaces, 2).expect_err("bad row").to_string();
        assert!(e.contains("spaces.txt:2:") && e.contains("y `x` is not a number"), "{e}");
        let e = IndexedBoxes::from_mot_file(&comma, 1).expect_err("beyond").to_string();
        assert!(e.contains("comma.txt") && e.contains("frame 2 is beyond"), "{e}");
    }
}
