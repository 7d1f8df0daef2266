//! Commissioning a camera: its pose (and, without known intrinsics, its focal length and principal
//! point) from reference objects whose face centres the divers measured in the world frame and whose
//! pixels were marked on one frame. The result is the calibration file that `camera.calibration`
//! reads (docs/calibration.md), with the reference objects the metric depth fit uses (paper eq. 1-2).
//!
//! Method (see [`pnp`]): a linear start (normalised DLT for six or more non-coplanar references, a
//! plane homography otherwise, with sampled rotations as a fallback; without intrinsics also the
//! DLT pose at a few sampled focal lengths), Levenberg-Marquardt on the reprojection error weighted
//! by each reference's pixel covariance under the stated noise (the maximum-likelihood camera,
//! [`pnp::refine_ml`]), then a leave-one-out consensus step ([`consensus`]): each
//! reference is predicted by the camera solved from all the others, and one whose miss is more
//! sigmas off than the stated measurement noise (`--click-px`, `--tape-m`) allows, carried through
//! that camera's uncertainty, is named as mis-measured while the others fit. This is the
//! single-outlier case of RANSAC's consensus test (Fischler & Bolles, CACM 1981) with every
//! leave-one-out set as a candidate and a chi-square test in place of a fixed pixel threshold.

pub mod consensus;
pub mod pnp;

pub use consensus::consensus;

use crate::geometry::{Camera, Intrinsics, Pixel, WorldPoint};
use nalgebra::Vector3;

/// Longest reference name accepted in a points CSV, characters (names label tables and overlays).
pub const MAX_NAME_CHARS: usize = 64;
/// One measured reference: the world position of its camera-facing face centre and its pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Name from the CSV (`name` column).
    pub name: String,
    /// 1-based line of the CSV it came from (0 when not from a file).
    pub line: usize,
    /// Face centre, world frame, metres (z up).
    pub world: WorldPoint,
    /// Where it appears, pixels (u right, v down).
    pub pixel: Pixel,
}

impl Reference {
    /// `'name' (line N)` for messages.
    pub fn label(&self) -> String {
        if self.line > 0 {
            format!("reference '{}' (line {})", self.name, self.line)
        } else {
            format!("reference '{}'", self.name)
        }
    }
}

/// Why a calibration could not be made; every message names the reference or line at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    /// The points CSV is malformed.
    #[error("line {line}: {msg}")]
    Csv {
        /// 1-based line.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// Fewer references than the solve needs.
    #[error("{have} reference(s); the pose needs at least {need}{why}")]
    TooFew {
        /// References given.
        have: usize,
        /// References needed.
        need: usize,
        /// Why that many (empty or a clause).
        why: String,
    },
    /// Degenerate geometry (coincident or collinear references, a pixel outside the image).
    #[error("{0}")]
    Degenerate(String),
    /// One reference does not fit the others.
    #[error(
        "{label} does not fit the others: the camera solved from the other references puts it {error_px:.1} px \
         from where it was marked, {sigmas:.1} sigma of the stated measurement noise (1 sigma = {sigma_px:.2} px \
         in that direction; the others fit to {others_rms_px:.2} px RMS); re-measure its position and pixel, or \
         drop it"
    )]
    Outlier {
        /// The reference (`reference 'name' (line N)`).
        label: String,
        /// Its leave-one-out prediction error, pixels.
        error_px: f64,
        /// That error in standard deviations (Mahalanobis distance) of its predicted position under
        /// the stated noise.
        sigmas: f64,
        /// One standard deviation of the prediction along the miss, pixels.
        sigma_px: f64,
        /// RMS error of the others under their own solution, pixels.
        others_rms_px: f64,
    },
    /// The fit is worse than the limit (and no single reference explains it).
    #[error(
        "reprojection error {rms_px:.2} px RMS is over the limit of {limit_px} px (--max-rms) and more than the \
         stated measurement noise explains (--click-px {click_px}, --tape-m {tape_m}); worst: {worst} at \
         {worst_px:.1} px. Check the intrinsics (underwater behind a flat port the focal length is about 1.33x \
         the in-air value) and the measurements"
    )]
    OverLimit {
        /// RMS reprojection error, pixels.
        rms_px: f64,
        /// The limit, pixels.
        limit_px: f64,
        /// The stated click noise, pixels per axis.
        click_px: f64,
        /// The stated tape noise, metres per axis.
        tape_m: f64,
        /// The reference with the largest error.
        worst: String,
        /// Its error, pixels.
        worst_px: f64,
    },
    /// The solver found no pose (numerically degenerate input).
    #[error("no camera pose fits these references: {0}")]
    NoSolution(String),
}

/// Parses the points CSV: header `name,x,y,z,u,v` (world metres, z up; pixel u right, v down).
/// Blank lines and lines starting with `#` are skipped. Errors name the line.
pub fn parse_points(text: &str) -> Result<Vec<Reference>, CalibError> {
    let mut refs: Vec<Reference> = Vec::new();
    let mut header = false;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if !header {
            let want = ["name", "x", "y", "z", "u", "v"];
            if fields.len() != 6 || !fields.iter().zip(want).all(|(f, w)| f.eq_ignore_ascii_case(w)) {
                return Err(CalibError::Csv { line, msg: format!("expected the header `name,x,y,z,u,v`, got `{l}`") });
            }
            header = true;
            continue;
        }
        if fields.len() != 6 {
            return Err(CalibError::Csv {
                line,
                msg: format!("expected 6 fields (name,x,y,z,u,v), got {}", fields.len()),
            });
        }
        let name = fields[0].to_string();
        if name.is_empty() {
            return Err(CalibError::Csv { line, msg: "empty name".into() });
        }
        if name.chars().count() > MAX_NAME_CHARS {
            return Err(CalibError::Csv {
                line,
                msg: format!("name of {} characters; at most {MAX_NAME_CHARS}", name.chars().count()),
            });
        }
        let mut v = [0.0; 5];
        for (k, col) in ["x", "y", "z", "u", "v"].iter().enumerate() {
            v[k] = fields[k + 1].parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| CalibError::Csv {
                line,
                msg: format!("{col} of '{name}' is not a number: `{}`", fields[k + 1]),
            })?;
        }
        if let Some(other) = refs.iter().find(|r| r.name == name) {
            return Err(CalibError::Csv { line, msg: format!("name '{name}' already used on line {}", other.line) });
        }
        refs.push(Reference { name, line, world: WorldPoint::new(v[0], v[1], v[2]), pixel: Pixel::new(v[3], v[4]) });
    }
    if !header {
        return Err(CalibError::Csv { line: 1, msg: "empty file: expected the header `name,x,y,z,u,v`".into() });
    }
    Ok(refs)
}

/// Settings of a solve.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Largest acceptable RMS reprojection error, pixels, unless the stated noise explains it.
    pub max_rms_px: f64,
    /// Expected error of a marked pixel, pixels per axis (standard deviation).
    pub click_px: f64,
    /// Expected error of a measured face centre, metres per axis (standard deviation).
    pub tape_m: f64,
    /// Image size in pixels (pixels outside it are rejected; the principal point starts at its centre).
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl Options {
    /// The stated measurement noise.
    pub fn noise(&self) -> pnp::Noise {
        pnp::Noise { click_px: self.click_px, tape_m: self.tape_m }
    }
}

/// Horizontal fields of view, degrees, whose focal lengths (principal point at the image centre)
/// also start the refinement without intrinsics: the pixel DLT's focal length and principal point
/// absorb the noise of few references and can start it in a worse basin than a guessed camera.
const SAMPLED_HFOV_DEG: [f64; 5] = [40.0, 60.0, 80.0, 100.0, 120.0];

/// One reference under a camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Residual {
    /// Where the camera projects the reference (None: behind the camera).
    pub projected: Option<Pixel>,
    /// Distance from marked to projected pixel, pixels.
    pub error_px: f64,
    /// The reference's depth (camera z), metres.
    pub depth_m: f64,
    /// `error_px` as a lateral distance at that depth, metres (`error_px * depth / f`).
    pub error_m: f64,
}

/// A solved calibration.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Intrinsics and pose.
    pub camera: Camera,
    /// Per reference, in input order.
    pub residuals: Vec<Residual>,
    /// RMS reprojection error over the references, pixels.
    pub rms_px: f64,
    /// True when fx = fy, cx, cy were estimated (no intrinsics given).
    pub estimated_intrinsics: bool,
    /// Which start the solution came from (`dlt`, `plane homography` or `sampled rotations`).
    pub start: &'static str,
}

/// Each reference's error under `camera`, and the RMS.
pub fn residuals(camera: &Camera, refs: &[Reference]) -> (Vec<Residual>, f64) {
    let f = 0.5 * (camera.intrinsics.fx + camera.intrinsics.fy);
    let rows: Vec<Residual> = refs
        .iter()
        .map(|r| {
            let depth = camera.pose.to_camera(&r.world).0.z;
            match camera.world_to_pixel(&r.world) {
                Ok(p) => {
                    let e = ((p.u - r.pixel.u).powi(2) + (p.v - r.pixel.v).powi(2)).sqrt();
                    Residual { projected: Some(p), error_px: e, depth_m: depth, error_m: e * depth / f }
                }
                Err(_) => Residual { projected: None, error_px: f64::INFINITY, depth_m: depth, error_m: f64::INFINITY },
            }
        })
        .collect();
    let rms = (rows.iter().map(|r| r.error_px * r.error_px).sum::<f64>() / rows.len().max(1) as f64).sqrt();
    (rows, rms)
}

/// Checks the references can determine a pose: enough of them, inside the image, no two at one
/// place, not all on a line.
pub fn check_geometry(refs: &[Reference], opts: &Options) -> Result<(), CalibError> {
    if refs.len() < 4 {
        return Err(CalibError::TooFew { have: refs.len(), need: 4, why: String::new() });
    }
    for r in refs {
        let (u, v) = (r.pixel.u, r.pixel.v);
        if !(0.0..=f64::from(opts.width)).contains(&u) || !(0.0..=f64::from(opts.height)).contains(&v) {
            return Err(CalibError::Degenerate(format!(
                "{}: pixel ({u}, {v}) is outside the {}x{} image",
                r.label(),
                opts.width,
                opts.height
            )));
        }
    }
    for (i, a) in refs.iter().enumerate() {
        for b in &refs[i + 1..] {
            if a.world.distance(&b.world).get() < 0.01 {
                return Err(CalibError::Degenerate(format!(
                    "{} and {} are at the same world position (within 1 cm)",
                    a.label(),
                    b.label()
                )));
            }
            if (a.pixel.u - b.pixel.u).hypot(a.pixel.v - b.pixel.v) < 1.0 {
                return Err(CalibError::Degenerate(format!(
                    "{} and {} are marked on the same pixel (within 1 px)",
                    a.label(),
                    b.label()
                )));
            }
        }
    }
    let w: Vec<Vector3<f64>> = refs.iter().map(|r| r.world.0).collect();
    let (_, _, sv) = pnp::plane_fit(&w);
    if sv[1] < 1e-3 * sv[0].max(1e-12) || sv[1] < 0.01 {
        return Err(CalibError::Degenerate(
            "the references lie on one straight line in the world; a pose needs them spread over a plane or a volume"
                .into(),
        ));
    }
    Ok(())
}

/// Non-coplanarity of the references: the smallest over the largest spread of their best-fit
/// plane (0: exactly coplanar).
fn non_coplanarity(w: &[Vector3<f64>]) -> f64 {
    let (_, _, sv) = pnp::plane_fit(w);
    sv[2] / sv[0].max(1e-12)
}

/// Solves without the consensus step and the error limit: linear start(s), then the
/// maximum-likelihood refinement; of several starts the one with the smallest weighted residual
/// sum is kept. [`calibrate`] checks it; the web page also shows each reference's error under it
/// when the check refuses the solve.
pub fn solve_once(refs: &[Reference], intrinsics: Option<&Intrinsics>, opts: &Options) -> Result<Solution, CalibError> {
    let w: Vec<Vector3<f64>> = refs.iter().map(|r| r.world.0).collect();
    let px: Vec<Pixel> = refs.iter().map(|r| r.pixel).collect();
    let noise = opts.noise();
    let spread = non_coplanarity(&w);
    let (start_cam, start, estimate_k) = match intrinsics {
        Some(k) => {
            let norm: Vec<(f64, f64)> =
                px.iter().map(|p| k.undistort((p.u - k.cx) / k.fx, (p.v - k.cy) / k.fy)).collect();
            let (pose, start) = match (refs.len() >= 6 && spread > 0.05).then(|| pnp::dlt(&w, &norm)).flatten() {
                Some(p) => (pnp::pose_from_normalised_dlt(&p), "dlt"),
                None => (pnp::planar(&w, &norm), "plane homography"),
            };
            let pose = pose.ok_or_else(|| CalibError::NoSolution("the linear start failed".into()))?;
            (Camera { intrinsics: *k, pose }, start, false)
        }
        None => {
            if refs.len() < 6 || spread < 0.05 {
                return Err(CalibError::TooFew {
                    have: refs.len(),
                    need: 6,
                    why: format!(
                        " non-coplanar references (out of plane spread {:.0}% of the in-plane spread, 5% needed) to \
                         estimate the focal length and principal point; give the intrinsics (--intrinsics FILE or \
                         --fx --fy --cx --cy)",
                        spread * 100.0
                    ),
                });
            }
            let pix: Vec<(f64, f64)> = px.iter().map(|p| (p.u, p.v)).collect();
            let cam = pnp::dlt(&w, &pix)
                .and_then(|p| pnp::camera_from_pixel_dlt(&p))
                .ok_or_else(|| CalibError::NoSolution("the DLT start failed".into()))?;
            (cam, "dlt", true)
        }
    };
    // A first unweighted pass brings the start near the data, where the weights mean something.
    let mut camera = pnp::refine_ml(&pnp::refine(&start_cam, &w, &px, estimate_k), &w, &px, estimate_k, &noise);
    let mut cost = noise.chi2(&camera, &w, &px);
    let mut start = start;
    if estimate_k {
        let (cx, cy) = (0.5 * f64::from(opts.width), 0.5 * f64::from(opts.height));
        for hfov in SAMPLED_HFOV_DEG {
            let f = 0.5 * f64::from(opts.width) / (0.5 * hfov.to_radians()).tan();
            let k = Intrinsics { fx: f, fy: f, cx, cy, distortion: [0.0; 5] };
            let norm: Vec<(f64, f64)> = px.iter().map(|p| ((p.u - cx) / f, (p.v - cy) / f)).collect();
            let Some(pose) = pnp::dlt(&w, &norm).and_then(|p| pnp::pose_from_normalised_dlt(&p)) else { continue };
            let c0 = pnp::refine(&Camera { intrinsics: k, pose }, &w, &px, false);
            let c = pnp::refine_ml(&pnp::refine(&c0, &w, &px, true), &w, &px, true, &noise);
            let r = noise.chi2(&c, &w, &px);
            if r < cost && c.intrinsics.validate().is_ok() {
                camera = c;
                cost = r;
                start = "dlt at a sampled focal length";
            }
        }
    }
    let (_, rms_px) = residuals(&camera, refs);
    // Few references off a plane (no exact linear start), or a start that did not reach the data:
    // also refine from sampled rotations and keep the best (an outlier makes this run; it is cheap).
    if let (Some(k), true) = (intrinsics, start != "dlt" || rms_px > 1.0) {
        let norm: Vec<(f64, f64)> = px.iter().map(|p| k.undistort((p.u - k.cx) / k.fx, (p.v - k.cy) / k.fy)).collect();
        for pose in pnp::sampled_starts(&w, &norm, 2000, 8) {
            let c = pnp::refine(&Camera { intrinsics: *k, pose }, &w, &px, false);
            let c = pnp::refine_ml(&c, &w, &px, false, &noise);
            let r = noise.chi2(&c, &w, &px);
            if r < cost {
                camera = c;
                cost = r;
                start = "sampled rotations";
            }
        }
    }
    camera.intrinsics.validate().map_err(|e| CalibError::NoSolution(e.to_string()))?;
    let (residuals, rms_px) = residuals(&camera, refs);
    Ok(Solution { camera, residuals, rms_px, estimated_intrinsics: estimate_k, start })
}

/// Solves the calibration: checks the geometry, solves, runs the consensus step and checks the
/// error limit (a fit over `max_rms_px` is refused only when the stated noise does not explain it:
/// its weighted residual sum is over [`consensus::fit_limit`]). `intrinsics`: known intrinsics (only the pose is solved), or `None` to estimate
/// `fx = fy`, `cx`, `cy` as well (six or more non-coplanar references).
pub fn calibrate(refs: &[Reference], intrinsics: Option<&Intrinsics>, opts: &Options) -> Result<Solution, CalibError> {
    check_geometry(refs, opts)?;
    let sol = solve_once(refs, intrinsics, opts)?;
    if let Some(e) = consensus(refs, &sol, opts) {
        return Err(e);
    }
    let (chi2, dof) = consensus::fit_chi2(&sol.camera, refs, sol.estimated_intrinsics, opts);
    if sol.rms_px.is_nan() || (sol.rms_px > opts.max_rms_px && (chi2.is_nan() || chi2 > consensus::fit_limit(dof))) {
        let (i, worst) = sol
            .residuals
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.error_px.total_cmp(&b.1.error_px))
            .map(|(i, r)| (i, r.error_px))
            .unwrap_or((0, f64::NAN));
        return Err(CalibError::OverLimit {
            rms_px: sol.rms_px,
            limit_px: opts.max_rms_px,
            click_px: opts.click_px,
            tape_m: opts.tape_m,
            worst: refs.get(i).map(Reference::label).unwrap_or_default(),
            worst_px: worst,
        });
    }
    Ok(sol)
}

/// Angle between two rotations, degrees.
pub fn rotation_angle_deg(a: &nalgebra::Matrix3<f64>, b: &nalgebra::Matrix3<f64>) -> f64 {
    let c = ((a.transpose() * b).trace() - 1.0) * 0.5;
    c.clamp(-1.0, 1.0).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_errors_name_the_line() {
        let ok = parse_points("name,x,y,z,u,v\n# c\na,1,2,3,4,5\n\nb,1,2,3.5,6,7\n").unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[1].line, 5);
        let e = parse_points("name,x,y,z,u,v\na,1,2,3,4,5\nb,1,2,zz,6,7\n").unwrap_err();
        assert!(e.to_string().starts_with("line 3:") && e.to_string().contains("'b'"), "{e}");
        let e = parse_points("n,x,y\n").unwrap_err();
        assert!(e.to_string().contains("header"), "{e}");
        let e = parse_points("name,x,y,z,u,v\na,1,2,3,4,5\na,1,2,3,4,5\n").unwrap_err();
        assert!(e.to_string().contains("line 3") && e.to_string().contains("line 2"), "{e}");
        assert!(parse_points("").is_err());
    }
}
