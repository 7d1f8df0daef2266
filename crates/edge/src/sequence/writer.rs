//! Writing sequences so that nothing half-written ever looks complete: everything goes into a hidden
//! staging folder next to the target, which is renamed into place only when all files are written.

use super::{DepthMap, Error, GtBox, Meta, Result, SeqInfo, WorldRow, frame_file_name, write_depth_png};
use std::path::{Path, PathBuf};

/// Marker files that make a folder recognisable as fme output, so `force` may replace it.
const GENERATED_MARKERS: [&str; 2] = ["seqinfo.ini", "scenes.txt"];

/// A staging folder for one output folder. Dropping it without [`StagedDir::commit`] deletes it.
#[derive(Debug)]
pub struct StagedDir {
    target: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
}

impl StagedDir {
    /// Prepares to write `target`. Fails when `target` exists and is not an empty folder, unless
    /// `force` is set and it is an earlier fme output (it holds `seqinfo.ini` or `scenes.txt`): an
    /// unrelated folder is never deleted.
    pub fn create(target: &Path, force: bool) -> Result<Self> {
        if target.exists() {
            if !target.is_dir() {
                return Err(Error::invalid(target, "output exists and is not a folder"));
            }
            let mut entries = std::fs::read_dir(target).map_err(|e| Error::io(target, e))?;
            if entries.next().is_some() {
                if !force {
                    return Err(Error::invalid(target, "output folder is not empty (use --force to replace it)"));
                }
                if !GENERATED_MARKERS.iter().any(|m| target.join(m).is_file()) {
                    return Err(Error::invalid(
                        target,
                        "output folder is not empty and does not look like an fme sequence (no seqinfo.ini or \
                         scenes.txt); refusing to replace it even with --force",
                    ));
                }
            }
        }
        let name = target
            .file_name()
            .ok_or_else(|| Error::invalid(target, "output path has no final folder name"))?
            .to_string_lossy()
            .into_owned();
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| Error::io(&staging, e))?;
        }
        std::fs::create_dir(&staging).map_err(|e| Error::io(&staging, e))?;
        Ok(Self { target: target.to_path_buf(), staging, force, committed: false })
    }

    /// The staging folder to write into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The final folder.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the staging folder into place (replacing an earlier output when allowed).
    pub fn commit(mut self) -> Result<PathBuf> {
        if self.target.exists() {
            let empty = std::fs::read_dir(&self.target).map_err(|e| Error::io(&self.target, e))?.next().is_none();
            if !empty && !self.force {
                return Err(Error::invalid(&self.target, "output folder appeared while writing; not replacing it"));
            }
            std::fs::remove_dir_all(&self.target).map_err(|e| Error::io(&self.target, e))?;
        }
        std::fs::rename(&self.staging, &self.target).map_err(|e| Error::io(&self.target, e))?;
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: a leftover hidden `.partial-*` folder never looks like a sequence anyway.
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// Writes the files of one sequence into a folder (usually inside a [`StagedDir`]).
#[derive(Debug)]
pub struct SequenceWriter {
    dir: PathBuf,
    im_ext: String,
}

impl SequenceWriter {
    /// Creates `dir` with `img1/`, `gt/` and `depth/`.
    pub fn new(dir: &Path) -> Result<Self> {
        for sub in ["img1", "gt", "depth"] {
            let p = dir.join(sub);
            std::fs::create_dir_all(&p).map_err(|e| Error::io(&p, e))?;
        }
        Ok(Self { dir: dir.to_path_buf(), im_ext: ".jpg".into() })
    }

    /// The sequence folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Path of frame `frame`'s image.
    pub fn frame_path(&self, frame: u32) -> PathBuf {
        self.dir.join("img1").join(frame_file_name(frame, &self.im_ext))
    }

    /// Path of frame `frame`'s depth map.
    pub fn depth_path(&self, frame: u32) -> PathBuf {
        self.dir.join("depth").join(frame_file_name(frame, ".png"))
    }

    /// Writes already-encoded JPEG bytes of a frame.
    pub fn write_frame_bytes(&self, frame: u32, jpeg: &[u8]) -> Result<()> {
        let p = self.frame_path(frame);
        std::fs::write(&p, jpeg).map_err(|e| Error::io(&p, e))
    }

    /// Encodes and writes a frame as JPEG.
    pub fn write_frame(&self, frame: u32, rgb: &image::RgbImage, quality: u8) -> Result<()> {
        let p = self.frame_path(frame);
        let bytes = encode_jpeg(rgb, quality).map_err(|error| Error::Image { path: p.clone(), error })?;
        std::fs::write(&p, bytes).map_err(|e| Error::io(&p, e))
    }

    /// Writes a frame's depth map.
    pub fn write_depth(&self, frame: u32, depth: &DepthMap) -> Result<()> {
        write_depth_png(&self.depth_path(frame), depth)
    }

    /// Writes `seqinfo.ini`, `meta.json`, `gt/gt.txt` and `gt/world.csv`, after checking that every
    /// frame image and depth map was written.
    pub fn finish(self, info: &SeqInfo, meta: &Meta, gt: &[GtBox], world: &[WorldRow]) -> Result<()> {
        for f in 1..=info.seq_length {
            for p in [self.frame_path(f), self.depth_path(f)] {
                if !p.is_file() {
                    return Err(Error::invalid(&p, "was never written"));
                }
            }
        }
        super::write_gt(&self.dir.join("gt").join("gt.txt"), gt)?;
        super::write_world(&self.dir.join("gt").join("world.csv"), world)?;
        meta.write(&self.dir.join("meta.json"))?;
        // seqinfo.ini last: its presence marks a complete sequence.
        info.write(&self.dir.join("seqinfo.ini"))
    }
}

/// Encodes RGB pixels as a baseline JPEG.
pub fn encode_jpeg(rgb: &image::RgbImage, quality: u8) -> std::result::Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::with_capacity(rgb.as_raw().len() / 8);
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality);
    rgb.write_with_encoder(enc)?;
    Ok(out)
}
