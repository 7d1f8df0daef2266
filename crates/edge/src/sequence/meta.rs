//! `meta.json`: everything about a sequence that is not per-frame (camera, water, reference objects).

use super::{Error, Result};
use fme_core::geometry::{Camera, Intrinsics, Pose, WorldPoint};
use fme_core::units::{Metres, Seconds};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The contents of `meta.json`. Unknown keys are ignored on reading, so later generator
/// versions may add fields without breaking older readers. Only `camera` is required: a real
/// recording's file is a calibration (`fme calibrate` writes `camera`, `reference_objects`, `width`,
/// `height`), without the synthetic scene's fields; `seqinfo.ini` is the authority for the frame
/// rate, size and length, and [`super::Sequence::open`] fills in what the file leaves out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// Frames per second of the recording; frame `k` (1-based) is at `(k - 1) / fps` seconds.
    /// 0 when the file does not state it.
    #[serde(default)]
    pub fps: f64,
    /// Image width, pixels (0 when not stated).
    #[serde(default)]
    pub width: u32,
    /// Image height, pixels (0 when not stated).
    #[serde(default)]
    pub height: u32,
    /// Number of frames (0 when not stated).
    #[serde(default)]
    pub frames: u32,
    /// Seed of the generator's random number generator.
    #[serde(default)]
    pub seed: u64,
    /// Motion preset (`single`, `swarm`, `postproc-suite/<scene>`, `feeding`), or a free label.
    #[serde(default)]
    pub preset: String,
    /// Program that wrote the sequence (empty when not stated).
    #[serde(default)]
    pub generator: GeneratorMeta,
    /// Pinhole camera and its fixed world-to-camera pose.
    pub camera: CameraMeta,
    /// Water type and optical coefficients (type `unknown` when not stated).
    #[serde(default)]
    pub water: WaterMeta,
    /// Reference cubes of known position (paper sec. 4.3.2, Fig. 7).
    #[serde(default)]
    pub reference_objects: Vec<ReferenceObject>,
    /// Reference-object layout name (`A`..`F`, paper Table 5), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<String>,
    /// Pond (or net-cage section) size in metres along world x, y, z; the pond spans `[0, size]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pond_size_m: Option<[f64; 3]>,
    /// Number of fish in the scene (tracks in `gt/`), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fish: Option<u32>,
}

/// Name and version of the program that wrote a sequence.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GeneratorMeta {
    /// Program name, e.g. `fme synth`.
    pub name: String,
    /// Program version.
    pub version: String,
}

/// The camera block of `meta.json`: intrinsics in pixels and the world-to-camera transform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraMeta {
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u, pixels.
    pub cx: f64,
    /// Principal point v, pixels.
    pub cy: f64,
    /// OpenCV distortion `[k1, k2, p1, p2, k3]`.
    #[serde(default)]
    pub distortion: [f64; 5],
    /// `p_cam = rotation * p_world + translation`.
    pub world_to_camera: WorldToCamera,
}

/// World-to-camera transform as stored: `p_cam = rotation * p_world + translation`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorldToCamera {
    /// 3x3 rotation, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation in metres (camera frame).
    pub translation: [f64; 3],
}

/// Water of the scene: Jerlov type and the image-formation coefficients the renderer used,
/// `I_c = J_c exp(-b_c d) + B_c (1 - exp(-b_c d))` with `d` the ray length.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WaterMeta {
    /// Jerlov water type: `I`, `II`, `III`, `1C`, `3C`, `5C`, `7C` or `9C`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Attenuation `b_c` per metre, (R, G, B).
    #[serde(default)]
    pub attenuation_per_m: [f64; 3],
    /// Veiling light (backscatter at infinity) `B_c` in `[0, 1]`, (R, G, B).
    #[serde(default)]
    pub backscatter: [f64; 3],
}

impl Default for WaterMeta {
    /// Water of a recording that does not describe it.
    fn default() -> Self {
        Self { kind: "unknown".into(), attenuation_per_m: [0.0; 3], backscatter: [0.0; 3] }
    }
}

/// A reference cube of known size and position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceObject {
    /// 1-based id.
    pub id: u32,
    /// Edge length in metres.
    pub size_m: f64,
    /// Cube centre, world frame.
    pub center_w: [f64; 3],
    /// Centre of the face turned towards the camera, world frame (the surface a depth map sees).
    pub front_face_center_w: [f64; 3],
}

impl ReferenceObject {
    /// Cube centre as a world point.
    pub fn center(&self) -> WorldPoint {
        WorldPoint::new(self.center_w[0], self.center_w[1], self.center_w[2])
    }
    /// Centre of the camera-facing face as a world point.
    pub fn front_face_center(&self) -> WorldPoint {
        let p = self.front_face_center_w;
        WorldPoint::new(p[0], p[1], p[2])
    }
    /// Edge length.
    pub fn size(&self) -> Metres {
        Metres(self.size_m)
    }
}

impl CameraMeta {
    /// The block for a camera.
    pub fn from_camera(camera: &Camera) -> Self {
        let k = &camera.intrinsics;
        Self {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            distortion: k.distortion,
            world_to_camera: WorldToCamera {
                rotation: camera.pose.rotation_rows(),
                translation: camera.pose.translation.into(),
            },
        }
    }
    /// Intrinsics of the block.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics { fx: self.fx, fy: self.fy, cx: self.cx, cy: self.cy, distortion: self.distortion }
    }
}

impl Meta {
    /// Reads and checks `meta.json`.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let meta: Meta = serde_json::from_str(&text).map_err(|error| Error::Json { path: path.into(), error })?;
        meta.validate(path)?;
        Ok(meta)
    }

    /// Writes `meta.json` (pretty-printed, stable key order).
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut text = serde_json::to_string_pretty(self).map_err(|error| Error::Json { path: path.into(), error })?;
        text.push('\n');
        std::fs::write(path, text).map_err(|e| Error::io(path, e))
    }

    /// Checks the values can describe a sequence; `path` is only used in the error. A value left
    /// out (0) is not checked: `seqinfo.ini` gives it.
    pub fn validate(&self, path: &Path) -> Result<()> {
        if !self.fps.is_finite() || self.fps < 0.0 {
            return Err(Error::invalid(path, format!("fps must be positive, got {}", self.fps)));
        }
        self.camera(path)?;
        Ok(())
    }

    /// The calibrated camera (intrinsics and pose), checked.
    pub fn camera(&self, path: &Path) -> Result<Camera> {
        let intrinsics = self.camera.intrinsics();
        intrinsics.validate().map_err(|e| Error::invalid(path, format!("camera: {e}")))?;
        let w2c = &self.camera.world_to_camera;
        let pose = Pose::from_rows(w2c.rotation, w2c.translation)
            .map_err(|e| Error::invalid(path, format!("camera.world_to_camera: {e}")))?;
        Ok(Camera { intrinsics, pose })
    }

    /// Timestamp of 1-based frame `frame`: `(frame - 1) / fps`.
    pub fn timestamp(&self, frame: u32) -> Seconds {
        Seconds(f64::from(frame.saturating_sub(1)) / self.fps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `fme calibrate` writes: no fps, frames, generator or water.
    const CALIBRATION: &str = r#"{"width": 640, "height": 384,
        "camera": {"fx": 300, "fy": 300, "cx": 320, "cy": 192,
                   "world_to_camera": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}},
        "reference_objects": [{"id": 1, "size_m": 0, "center_w": [0,0,2], "front_face_center_w": [0,0,2]}],
        "calibrate": {"rms_px": 0.4}}"#;

    #[test]
    fn a_calibration_without_the_synthetic_fields_reads() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("meta.json");
        std::fs::write(&p, CALIBRATION).expect("write");
        let m = Meta::read(&p).expect("a calibration is a meta.json");
        assert_eq!((m.fps, m.frames, m.width), (0.0, 0, 640));
        assert_eq!((m.water.kind.as_str(), m.generator.name.as_str()), ("unknown", ""));
        assert_eq!(m.reference_objects.len(), 1);
        // The camera stays required, and the error names the file and the key.
        std::fs::write(&p, r#"{"fps": 30}"#).expect("write");
        let e = Meta::read(&p).expect_err("no camera").to_string();
        assert!(e.contains("meta.json") && e.contains("camera"), "{e}");
        std::fs::write(&p, CALIBRATION.replace("\"width\": 640", "\"fps\": -1")).expect("write");
        assert!(Meta::read(&p).expect_err("negative fps").to_string().contains("fps"));
    }
}
