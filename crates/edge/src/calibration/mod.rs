//! The calibration file: a `meta.json`-format file (the `camera` block and `reference_objects`,
//! written by `fme calibrate` or beside a recording) read into the pipeline's
//! [`Calibration`] (paper eq. 1-2), and which file a configuration asks for; [`file`] writes it,
//! [`live`] reloads it into the running pipeline.

pub mod file;
pub mod live;

use crate::config::Config;
use crate::sequence::{Meta, ReferenceObject};
use fme_core::geometry::{Camera, Pose};
use fme_core::pipeline::Calibration;
use std::path::Path;

/// Reads and checks a calibration file; the error names the file and the problem.
pub fn load(path: &Path) -> Result<Calibration, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    // The `meta.json` format, read by the sequence reader's parser: the `camera` block and
    // `reference_objects` are used; other keys (fps, water, ...) are allowed and ignored.
    let f: Meta = serde_json::from_str(&text)
        .map_err(|e| format!("{}: not a calibration (meta.json) file: {e}", path.display()))?;
    let intrinsics = f.camera.intrinsics();
    intrinsics.validate().map_err(|e| format!("{}: camera: {e}", path.display()))?;
    let w2c = &f.camera.world_to_camera;
    let pose = Pose::from_rows(w2c.rotation, w2c.translation)
        .map_err(|e| format!("{}: camera.world_to_camera: {e}", path.display()))?;
    let references = f.reference_objects.iter().map(ReferenceObject::front_face_center).collect::<Vec<_>>();
    if references.iter().any(|p| !(p.0.x.is_finite() && p.0.y.is_finite() && p.0.z.is_finite())) {
        return Err(format!("{}: reference_objects: a position is not finite", path.display()));
    }
    let cubes = f.reference_objects.iter().map(|r| (r.center(), r.size())).collect();
    Ok(Calibration { path: path.to_path_buf(), camera: Camera { intrinsics, pose }, references, cubes })
}

impl Config {
    /// The calibration this configuration asks for: `camera.calibration` when set, else a recorded
    /// source's own `meta.json`, else none (a camera without calibration runs uncalibrated).
    /// A calibration that cannot give a metric fit (fewer than two reference objects, and no fish
    /// ruler: `depth.scale = "references"` or `motion.body_length_m = 0`) is an error: the box would
    /// track fish forever and never report a speed.
    pub fn calibration(&self) -> Result<Option<Calibration>, String> {
        let configured = &self.camera.calibration;
        let (path, key) = if !configured.as_os_str().is_empty() {
            (configured.clone(), "camera.calibration")
        } else {
            let meta = self.source.path.join("meta.json");
            if self.source.is_camera() || !meta.is_file() {
                return Ok(None);
            }
            (meta, "the recording's calibration")
        };
        let c = load(&path).map_err(|e| format!("{key}: {e}"))?;
        let fish_ruler =
            self.depth.scale != fme_core::metric::DepthScale::References && self.motion.body_length().is_some();
        if c.references.len() < 2 && !fish_ruler {
            return Err(format!(
                "{key}: {}: reference_objects: {} reference object(s); the metric depth fit needs at least 2 (or depth.scale = \"fish\" or \"auto\" with motion.body_length_m > 0)",
                path.display(),
                c.references.len()
            ));
        }
        Ok(Some(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_recordings_meta_json_and_rejects_garbage() {
        let c = load(&Path::new(fme_core::REPO_DIR).join("tests/data/swarm20/meta.json")).expect("meta.json");
        assert!(c.references.len() >= 2);
        assert!((c.camera.intrinsics.cx - 320.0).abs() < 1e-9);
        let dir = std::env::temp_dir().join(format!("fme-calib-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bad = dir.join("bad.json");
        std::fs::write(&bad, "{\"camera\": 3}").unwrap();
        let e = load(&bad).unwrap_err();
        assert!(e.contains("bad.json") && e.contains("calibration"), "{e}");
        let e = load(&dir.join("missing.json")).unwrap_err();
        assert!(e.contains("missing.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
