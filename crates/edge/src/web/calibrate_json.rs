//! The JSON of `/api/calibration`: the request a page sends (clicked pixels, measured positions,
//! optional intrinsics), checked with messages naming the field, and the answers' parts (camera,
//! per-reference errors).

use fme_core::calib::{MAX_NAME_CHARS, Options, Reference, Residual};
use fme_core::geometry::{Camera, Intrinsics, Pixel, WorldPoint};
use serde::Deserialize;
use serde_json::{Value, json};

/// Most references one request may carry (the body limit allows about this many).
pub const MAX_REFERENCES: usize = 40;
/// Largest image side accepted, pixels.
pub const MAX_SIDE: u32 = 8192;

/// `POST /api/calibration`'s body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolveRequest {
    /// Width of the frame the references were clicked on, pixels.
    pub width: u32,
    /// Its height, pixels.
    pub height: u32,
    /// The references, in order.
    pub references: Vec<RefIn>,
    /// Known intrinsics; without them fx = fy, cx, cy are estimated (six or more non-coplanar).
    #[serde(default)]
    pub intrinsics: Option<Intrinsics>,
    /// Write the file and reload it into the pipeline (else: solve only).
    #[serde(default)]
    pub apply: bool,
    /// Edge length of the reference cubes, m (as `fme calibrate --ref-size`).
    #[serde(default)]
    pub ref_size_m: f64,
    /// As `fme calibrate --click-px`.
    #[serde(default = "default_click")]
    pub click_px: f64,
    /// As `fme calibrate --tape-m`.
    #[serde(default = "default_tape")]
    pub tape_m: f64,
    /// As `fme calibrate --max-rms`.
    #[serde(default = "default_rms")]
    pub max_rms_px: f64,
}

fn default_click() -> f64 {
    1.5
}
fn default_tape() -> f64 {
    0.01
}
fn default_rms() -> f64 {
    3.0
}

/// One clicked reference.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RefIn {
    /// Its name (unique, at most [`MAX_NAME_CHARS`] characters).
    pub name: String,
    /// Measured face centre, world metres (z up).
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// See `x`.
    pub z: f64,
    /// Clicked pixel, u right.
    pub u: f64,
    /// Clicked pixel, v down.
    pub v: f64,
}

/// A checked request: what the solver takes.
#[derive(Debug)]
pub struct Checked {
    /// The references.
    pub refs: Vec<Reference>,
    /// The intrinsics, if given.
    pub intrinsics: Option<Intrinsics>,
    /// The solve's settings.
    pub opts: Options,
}

fn positive(v: f64, key: &str) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 { Ok(v) } else { Err(format!("{key} must be a positive number, got {v}")) }
}

impl SolveRequest {
    /// Checks every field; the error names the field (and the reference).
    pub fn check(&self) -> Result<Checked, String> {
        for (key, side) in [("width", self.width), ("height", self.height)] {
            if side == 0 || side > MAX_SIDE {
                return Err(format!("{key} must be 1..={MAX_SIDE} pixels, got {side}"));
            }
        }
        if self.references.len() > MAX_REFERENCES {
            return Err(format!("{} references; at most {MAX_REFERENCES}", self.references.len()));
        }
        if !(self.ref_size_m.is_finite() && self.ref_size_m >= 0.0) {
            return Err(format!("ref_size_m must be 0 or a positive length in metres, got {}", self.ref_size_m));
        }
        let opts = Options {
            max_rms_px: positive(self.max_rms_px, "max_rms_px")?,
            click_px: positive(self.click_px, "click_px")?,
            tape_m: positive(self.tape_m, "tape_m")?,
            width: self.width,
            height: self.height,
        };
        let mut refs: Vec<Reference> = Vec::with_capacity(self.references.len());
        for (i, r) in self.references.iter().enumerate() {
            let name = r.name.trim();
            let at = format!("references[{i}]");
            if name.is_empty() || name.chars().count() > MAX_NAME_CHARS {
                return Err(format!("{at}: a name of 1 to {MAX_NAME_CHARS} characters is needed"));
            }
            if refs.iter().any(|o| o.name == name) {
                return Err(format!("{at}: the name '{name}' is used twice"));
            }
            for (key, v) in [("x", r.x), ("y", r.y), ("z", r.z), ("u", r.u), ("v", r.v)] {
                if !v.is_finite() {
                    return Err(format!("{at} '{name}': {key} is not a number"));
                }
            }
            refs.push(Reference {
                name: name.to_string(),
                line: 0,
                world: WorldPoint::new(r.x, r.y, r.z),
                pixel: Pixel::new(r.u, r.v),
            });
        }
        if let Some(k) = &self.intrinsics {
            k.validate().map_err(|e| format!("intrinsics: {e}"))?;
        }
        let intrinsics = self.intrinsics;
        Ok(Checked { refs, intrinsics, opts })
    }
}

/// The camera as JSON: intrinsics, world-to-camera rotation (rows) and translation, centre.
pub fn camera_json(cam: &Camera) -> Value {
    let k = &cam.intrinsics;
    let r = &cam.pose.rotation;
    let t = &cam.pose.translation;
    let c = cam.pose.camera_center().0;
    json!({
        "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "distortion": k.distortion,
        "rotation": [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]],
        "translation": [t.x, t.y, t.z],
        "center_w": [c.x, c.y, c.z],
    })
}

/// Each reference with its error under a camera (`null` for numbers that are not finite).
pub fn residual_rows(refs: &[Reference], res: &[Residual]) -> Vec<Value> {
    let fin = |v: f64| v.is_finite().then_some(v);
    refs.iter()
        .zip(res)
        .map(|(r, e)| {
            json!({
                "name": r.name,
                "x": r.world.0.x, "y": r.world.0.y, "z": r.world.0.z,
                "u": r.pixel.u, "v": r.pixel.v,
                "projected": e.projected.map(|p| [p.u, p.v]),
                "error_px": fin(e.error_px),
                "error_m": fin(e.error_m),
                "depth_m": fin(e.depth_m),
            })
        })
        .collect()
}

/// The name of the reference a solver message is about (`reference 'NAME'` as its label writes it).
pub fn named_in(refs: &[Reference], label: &str) -> Option<String> {
    refs.iter().find(|r| r.label() == label).map(|r| r.name.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(body: &str) -> Result<Checked, String> {
        serde_json::from_str::<SolveRequest>(body).map_err(|e| e.to_string())?.check()
    }

    #[test]
    fn a_request_is_checked_naming_the_field() {
        let ok = req(r#"{"width":640,"height":384,"references":[{"name":"a","x":1,"y":2,"z":3,"u":4,"v":5}]}"#)
            .expect("a good request");
        assert_eq!(ok.refs.len(), 1);
        assert_eq!(ok.opts.click_px, 1.5);
        assert!(ok.intrinsics.is_none());
        let e = req(r#"{"width":0,"height":384,"references":[]}"#).unwrap_err();
        assert!(e.contains("width"), "{e}");
        let two = r#"{"name":"a","x":1,"y":2,"z":3,"u":4,"v":5}"#;
        let e = req(&format!(r#"{{"width":640,"height":384,"references":[{two},{two}]}}"#)).unwrap_err();
        assert!(e.contains("references[1]") && e.contains("twice"), "{e}");
        let e = req(r#"{"width":640,"height":384,"references":[],"intrinsics":{"fx":-1,"fy":1,"cx":1,"cy":1}}"#)
            .unwrap_err();
        assert!(e.contains("intrinsics"), "{e}");
        let e = req(r#"{"width":640,"height":384,"references":[],"click_px":0}"#).unwrap_err();
        assert!(e.contains("click_px"), "{e}");
        assert!(req(r#"{"width":640,"height":384,"references":[],"bogus":1}"#).is_err());
    }
}
