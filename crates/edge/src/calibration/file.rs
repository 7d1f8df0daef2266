//! Writing the calibration file from a solve: what `fme calibrate` writes and what the web page's
//! "apply" writes, one format (a sequence's `meta.json`: the `camera` block, `reference_objects`
//! and a `calibrate` block saying how it was made), read back by [`super::load`].

use crate::sequence::{CameraMeta, ReferenceObject};
use fme_core::calib::{Options, Reference, Solution};
use std::io::Write as _;
use std::path::Path;

/// How a calibration was made (the `calibrate` block; the loader ignores it).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CalibrateInfo {
    /// The frame the references were marked on (a file, or `web page` for the page's frozen frame).
    pub frame: String,
    /// Where the points came from (the CSV, or `web page`).
    pub points: String,
    /// The references' names, in order.
    pub names: Vec<String>,
    /// RMS reprojection error, pixels.
    pub rms_px: f64,
    /// The limit it was checked against, pixels.
    pub max_rms_px: f64,
    /// The stated click noise, pixels per axis.
    pub click_px: f64,
    /// The stated tape noise, metres per axis.
    pub tape_m: f64,
    /// Each reference's reprojection error, pixels.
    pub error_px: Vec<f64>,
    /// Whether fx = fy, cx, cy were estimated.
    pub estimated_intrinsics: bool,
}

/// The whole file.
#[derive(Debug, serde::Serialize)]
pub struct CalibrationFile {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Intrinsics and pose.
    pub camera: CameraMeta,
    /// The references as reference objects (the metric depth fit's, paper eq. 1-2).
    pub reference_objects: Vec<ReferenceObject>,
    /// How it was made.
    pub calibrate: CalibrateInfo,
}

impl CalibrationFile {
    /// The file for a solution: the references as reference objects (a cube's centre half an edge,
    /// `ref_size_m / 2`, behind its measured face, away from the camera; 0: points).
    pub fn new(refs: &[Reference], sol: &Solution, opts: &Options, ref_size_m: f64, from: (String, String)) -> Self {
        let cam = &sol.camera;
        let centre = cam.pose.camera_center();
        let reference_objects = refs
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let away = (r.world.0 - centre.0).try_normalize(1e-9).unwrap_or_default();
                let c = r.world.0 + away * (0.5 * ref_size_m);
                ReferenceObject {
                    id: i as u32 + 1,
                    size_m: ref_size_m,
                    center_w: c.into(),
                    front_face_center_w: r.world.0.into(),
                }
            })
            .collect();
        Self {
            width: opts.width,
            height: opts.height,
            camera: CameraMeta::from_camera(cam),
            reference_objects,
            calibrate: CalibrateInfo {
                frame: from.0,
                points: from.1,
                names: refs.iter().map(|r| r.name.clone()).collect(),
                rms_px: sol.rms_px,
                max_rms_px: opts.max_rms_px,
                click_px: opts.click_px,
                tape_m: opts.tape_m,
                error_px: sol.residuals.iter().map(|r| r.error_px).collect(),
                estimated_intrinsics: sol.estimated_intrinsics,
            },
        }
    }

    /// The file's text (pretty JSON, a final newline).
    pub fn to_text(&self) -> Result<String, String> {
        let mut text = serde_json::to_string_pretty(self).map_err(|e| format!("encoding the calibration: {e}"))?;
        text.push('\n');
        Ok(text)
    }

    /// Writes it to `path` atomically, so the daemon (a reload, a restart) never reads half a file:
    /// a temporary file beside it, synced, checked by the daemon's loader, then renamed over
    /// `path`. Errors name the file; on any error `path` is untouched.
    pub fn write_atomic(&self, path: &Path) -> Result<(), String> {
        let text = self.to_text()?;
        let name = path.file_name().ok_or_else(|| format!("{}: not a file name", path.display()))?;
        let tmp = path.with_file_name(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
        let written = (|| {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(text.as_bytes())?;
            f.sync_all()
        })();
        let checked = written.map_err(|e| format!("{}: {e}", tmp.display())).and_then(|()| {
            super::load(&tmp).map(|_| ()).map_err(|e| format!("the written calibration does not load: {e}"))
        });
        let renamed = checked.and_then(|()| {
            std::fs::rename(&tmp, path).map_err(|e| format!("renaming {} to {}: {e}", tmp.display(), path.display()))
        });
        match &renamed {
            // The rename itself reaches the disk with the folder (a power cut after the answer
            // keeps the new file).
            Ok(()) => {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    let _ = std::fs::File::open(dir).and_then(|d| d.sync_all());
                }
            }
            Err(_) => {
                let _ = std::fs::remove_file(&tmp);
            }
        }
        renamed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fme_core::calib;

    #[test]
    fn written_atomically_and_read_back_by_the_loader() {
        let truth = super::super::load(&Path::new(fme_core::REPO_DIR).join("tests/data/swarm20/meta.json"))
            .expect("the bundled calibration");
        let refs: Vec<Reference> = truth
            .references
            .iter()
            .enumerate()
            .map(|(i, w)| Reference {
                name: format!("c{i}"),
                line: 0,
                world: *w,
                pixel: truth.camera.world_to_pixel(w).expect("in view"),
            })
            .collect();
        let opts = Options { max_rms_px: 3.0, click_px: 1.5, tape_m: 0.01, width: 640, height: 384 };
        let sol = calib::calibrate(&refs, Some(&truth.camera.intrinsics), &opts).expect("solves");
        let file = CalibrationFile::new(&refs, &sol, &opts, 0.1, ("f".into(), "p".into()));
        let dir = std::env::temp_dir().join(format!("fme-calib-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("calib.json");
        file.write_atomic(&path).expect("written");
        let back = super::super::load(&path).expect("loads");
        assert_eq!(back.references.len(), 10);
        assert!(back.camera.pose.camera_center().distance(&truth.camera.pose.camera_center()).get() < 1e-6);
        // A folder that does not exist: an error naming it, nothing left behind.
        let e = file.write_atomic(&dir.join("missing/calib.json")).unwrap_err();
        assert!(e.contains("missing"), "{e}");
        let left: Vec<_> = std::fs::read_dir(&dir).expect("list").flatten().map(|e| e.file_name()).collect();
        assert_eq!(left, vec![std::ffi::OsString::from("calib.json")], "no temporary file left");
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
