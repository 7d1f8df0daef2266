//! `fme calibrate`: the camera's pose (and intrinsics, when not given) from reference objects the
//! divers measured, written as the calibration file `camera.calibration` reads; `--check` tells
//! whether the camera has moved since. See docs/calibration.md.

use super::{UsageError, write_stdout};
use crate::calib::{self, Options, Reference, Residual};
use crate::calibration::file::CalibrationFile;
use crate::geometry::Intrinsics;
use anyhow::Context;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod overlay;
use overlay::overlay;

/// Arguments of `fme calibrate`.
#[derive(Debug, clap::Args)]
#[command(after_help = "Underwater behind a flat port the focal length is about 1.33x the in-air value (the \
                        refractive index of water): multiply in-air fx and fy by 1.33, or give no intrinsics \
                        and let ten or more non-coplanar references (six at the least) estimate them. See \
                        docs/calibration.md.")]
pub struct CalibrateArgs {
    /// The frame the references were marked on (PNG or JPEG); gives the image size and the overlay's
    /// background. With --source: where the grabbed frame is written.
    #[arg(long, value_name = "IMG")]
    pub frame: PathBuf,
    /// Grab the frame from this V4L2 camera (at `source.width` x `source.height` and
    /// `source.format` of the configuration: --config, --set), or from a recorded sequence
    /// directory, and write it to --frame. Without --points, stop there: mark the references on
    /// that image, then run again with --frame.
    #[arg(long, value_name = "/dev/videoN|DIR")]
    pub source: Option<PathBuf>,
    /// The configuration (only the `source` section is used, with --source).
    #[command(flatten)]
    pub config: super::ConfigArgs,
    /// The references: CSV with header `name,x,y,z,u,v` (face centre in world metres, z up; the pixel
    /// where it appears, u right, v down).
    #[arg(long, value_name = "CSV", required_unless_present = "source")]
    pub points: Option<PathBuf>,
    /// Intrinsics from any JSON file with a `camera` block (fx, fy, cx, cy, distortion): a calibration
    /// file or a sequence's meta.json. Without it and without --fx.., fx = fy, cx and cy are estimated
    /// (measure ten or more non-coplanar references; six at the least).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["fx", "fy", "cx", "cy"])]
    pub intrinsics: Option<PathBuf>,
    /// Focal length along u, pixels (with --fy --cx --cy; no distortion). Underwater behind a flat
    /// port: about 1.33x the in-air value.
    #[arg(long, requires_all = ["fy", "cx", "cy"])]
    pub fx: Option<f64>,
    /// Focal length along v, pixels.
    #[arg(long, requires_all = ["fx", "cx", "cy"])]
    pub fy: Option<f64>,
    /// Principal point u, pixels.
    #[arg(long, requires_all = ["fx", "fy", "cy"])]
    pub cx: Option<f64>,
    /// Principal point v, pixels.
    #[arg(long, requires_all = ["fx", "fy", "cx"])]
    pub cy: Option<f64>,
    /// Where to write the calibration (JSON, the format of a sequence's meta.json).
    #[arg(long, value_name = "CALIB.json", required_unless_present_any = ["check", "source"], conflicts_with = "check")]
    pub out: Option<PathBuf>,
    /// Also draw the frame with marked (green crosses) and reprojected (red circles) references and
    /// the world axes (x red, y green, z blue, 1 m from the origin and from the references' centroid) to this PNG.
    #[arg(long, value_name = "PNG")]
    pub overlay: Option<PathBuf>,
    /// Check an existing calibration against freshly marked points instead of solving: exit 0 when
    /// their reprojection error is within --max-rms, exit 1 when the camera (or a reference) moved.
    #[arg(long, value_name = "CALIB", conflicts_with_all = ["intrinsics", "fx"])]
    pub check: Option<PathBuf>,
    /// Largest acceptable RMS reprojection error, pixels. A fit over it is still accepted when the
    /// stated measurement noise (--click-px, --tape-m) explains it.
    #[arg(long, default_value_t = 3.0, value_name = "PX")]
    pub max_rms: f64,
    /// Expected error of a marked pixel, pixels per axis (one standard deviation): how carefully
    /// the references were clicked. With --tape-m it sets how far a reference may miss the camera
    /// solved from the others before it is named as mis-measured.
    #[arg(long, default_value_t = 1.5, value_name = "PX")]
    pub click_px: f64,
    /// Expected error of a measured face centre, metres per axis (one standard deviation): how
    /// carefully the references were measured.
    #[arg(long, default_value_t = 0.01, value_name = "M")]
    pub tape_m: f64,
    /// Edge length of the reference cubes, metres, written as `size_m` (their centre is put half an
    /// edge behind the measured face, away from the camera). 0: points, not cubes.
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pub ref_size: f64,
}

/// The intrinsics part of any file's `camera` block (other keys ignored).
#[derive(Debug, serde::Deserialize)]
struct IntrinsicsBlock {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    #[serde(default)]
    distortion: [f64; 5],
}

#[derive(Debug, serde::Deserialize)]
struct IntrinsicsFile {
    camera: IntrinsicsBlock,
}

fn usage(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(UsageError(msg.into()))
}

fn read_intrinsics(path: &Path) -> anyhow::Result<Intrinsics> {
    let text = std::fs::read_to_string(path).map_err(|e| usage(format!("--intrinsics {}: {e}", path.display())))?;
    let f: IntrinsicsFile = serde_json::from_str(&text)
        .map_err(|e| usage(format!("--intrinsics {}: no `camera` block with fx, fy, cx, cy: {e}", path.display())))?;
    let c = f.camera;
    let k = Intrinsics { fx: c.fx, fy: c.fy, cx: c.cx, cy: c.cy, distortion: c.distortion };
    k.validate().map_err(|e| usage(format!("--intrinsics {}: camera: {e}", path.display())))?;
    Ok(k)
}

fn read_points(path: &Path) -> anyhow::Result<Vec<Reference>> {
    let text = std::fs::read_to_string(path).map_err(|e| usage(format!("--points {}: {e}", path.display())))?;
    calib::parse_points(&text).map_err(|e| usage(format!("--points {}: {e}", path.display())))
}

fn read_frame(path: &Path) -> anyhow::Result<image::RgbImage> {
    let img = image::open(path).map_err(|e| usage(format!("--frame {}: {e}", path.display())))?;
    Ok(img.to_rgb8())
}

/// Runs `fme calibrate`.
pub fn run(args: CalibrateArgs) -> anyhow::Result<()> {
    check_numbers(&args)?;
    let frame = match &args.source {
        Some(dev) => grab(dev, &args.config, &args.frame)?,
        None => read_frame(&args.frame)?,
    };
    let Some(points) = &args.points else {
        return write_stdout(&format!(
            "wrote {} ({}x{}); mark the references on it and run fme calibrate --frame {} --points CSV ...\n",
            args.frame.display(),
            frame.width(),
            frame.height(),
            args.frame.display()
        ));
    };
    let refs = read_points(points)?;
    let opts = Options {
        max_rms_px: args.max_rms,
        click_px: args.click_px,
        tape_m: args.tape_m,
        width: frame.width(),
        height: frame.height(),
    };
    if let Some(calib_path) = &args.check {
        return check(calib_path, &refs, &opts, &frame, args.overlay.as_deref());
    }
    let intrinsics = given_intrinsics(&args)?;
    let sol =
        calib::calibrate(&refs, intrinsics.as_ref(), &opts).map_err(|e| usage(format!("{}: {e}", points.display())))?;
    let out = args.out.as_deref().ok_or_else(|| usage("--out is required"))?;
    write_calibration(out, &calibration_file(&args, points, &refs, &sol, &opts))?;
    if let Some(p) = &args.overlay {
        overlay(frame, &sol.camera, &refs, &sol.residuals, p)?;
    }
    write_stdout(&summary(&args, &refs, &sol, out))
}

/// The numeric flags, each checked before anything is read.
fn check_numbers(args: &CalibrateArgs) -> anyhow::Result<()> {
    if !(args.max_rms.is_finite() && args.max_rms > 0.0) {
        return Err(usage(format!("--max-rms must be a positive number of pixels, got {}", args.max_rms)));
    }
    if !(args.click_px.is_finite() && args.click_px > 0.0) {
        return Err(usage(format!("--click-px must be a positive number of pixels, got {}", args.click_px)));
    }
    if !(args.tape_m.is_finite() && args.tape_m > 0.0) {
        return Err(usage(format!("--tape-m must be a positive length in metres, got {}", args.tape_m)));
    }
    if !(args.ref_size.is_finite() && args.ref_size >= 0.0) {
        return Err(usage(format!("--ref-size must be 0 or a positive length in metres, got {}", args.ref_size)));
    }
    Ok(())
}

/// The intrinsics from --intrinsics or --fx --fy --cx --cy; `None`: estimate them.
fn given_intrinsics(args: &CalibrateArgs) -> anyhow::Result<Option<Intrinsics>> {
    Ok(match (&args.intrinsics, args.fx, args.fy, args.cx, args.cy) {
        (Some(p), ..) => Some(read_intrinsics(p)?),
        (None, Some(fx), Some(fy), Some(cx), Some(cy)) => {
            let k = Intrinsics { fx, fy, cx, cy, distortion: [0.0; 5] };
            k.validate().map_err(|e| usage(format!("--fx/--fy/--cx/--cy: {e}")))?;
            Some(k)
        }
        _ => None,
    })
}

/// The calibration file: the solved camera, the references as reference objects (a cube's centre
/// half an edge behind its measured face, away from the camera) and how it was made.
fn calibration_file(
    args: &CalibrateArgs,
    points: &Path,
    refs: &[Reference],
    sol: &calib::Solution,
    opts: &Options,
) -> CalibrationFile {
    let from = (args.frame.display().to_string(), points.display().to_string());
    CalibrationFile::new(refs, sol, opts, args.ref_size, from)
}

/// Writes the calibration to `out` and reads it back through the loader the daemon uses, so a
/// file that it would reject is caught here.
fn write_calibration(out: &Path, file: &CalibrationFile) -> anyhow::Result<()> {
    let text = file.to_text().map_err(|e| anyhow::anyhow!(e))?;
    // The path is what the user gave: a missing folder or no permission is a usage error (exit 2).
    std::fs::write(out, text).map_err(|e| usage(format!("--out {}: {e}", out.display())))?;
    crate::calibration::load(out).map_err(|e| anyhow::anyhow!("the written calibration does not load: {e}"))?;
    Ok(())
}

/// What is printed: the per-reference table, the RMS and the camera.
fn summary(args: &CalibrateArgs, refs: &[Reference], sol: &calib::Solution, out: &Path) -> String {
    let mut s = table(refs, &sol.residuals);
    let k = &sol.camera.intrinsics;
    let centre = sol.camera.pose.camera_center();
    let _ = writeln!(
        s,
        "RMS {:.2} px over {} references (limit {} px); start: {}",
        sol.rms_px,
        refs.len(),
        args.max_rms,
        sol.start
    );
    let _ = writeln!(
        s,
        "camera centre ({:.3}, {:.3}, {:.3}) m; fx {:.1} fy {:.1} cx {:.1} cy {:.1} px{}",
        centre.0.x,
        centre.0.y,
        centre.0.z,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        if sol.estimated_intrinsics { " (estimated)" } else { "" }
    );
    let _ = writeln!(s, "wrote {}", out.display());
    s
}

/// Grabs the sixth frame (after exposure settles) from a V4L2 camera or a recorded sequence
/// (`SourceConfig::is_camera`, as for `fme run --source`), and writes it to `out`.
fn grab(src: &Path, config: &super::ConfigArgs, out: &Path) -> anyhow::Result<image::RgbImage> {
    use crate::capture::{CaptureError, FrameSource, RecordedSource};
    let (cfg, _) = config.load(&super::source_sets(src))?;
    let open_err = |e: CaptureError| match e {
        e @ (CaptureError::NotFound { .. } | CaptureError::Open { .. }) => usage(format!("--source: {e}")),
        e => anyhow::Error::new(e).context("--source"),
    };
    let mut source: Box<dyn FrameSource> = if cfg.source.is_camera() {
        let mut cam = crate::capture::camera(&cfg.source).map_err(open_err)?;
        cam.reopen().map_err(open_err)?;
        cam
    } else {
        Box::new(RecordedSource::open(src, false, false).map_err(open_err)?)
    };
    let mut f = source.next_frame(Vec::new()).context("--source: grabbing a frame")?;
    for _ in 0..5 {
        match source.next_frame(Vec::new()) {
            Ok(next) => f = next,
            // A recording shorter than six frames: its last one.
            Err(CaptureError::End) => break,
            Err(e) => return Err(anyhow::Error::new(e).context("--source: grabbing a frame")),
        }
    }
    let mut rgb = Vec::new();
    let (w, h) = f.to_rgb_into(&mut rgb).map_err(|e| anyhow::anyhow!("--source: decoding the frame: {e}"))?;
    let img = image::RgbImage::from_raw(w, h, rgb).ok_or_else(|| anyhow::anyhow!("--source: frame size mismatch"))?;
    img.save(out).map_err(|e| usage(format!("--frame {}: writing the grabbed frame: {e}", out.display())))?;
    Ok(img)
}

/// The per-reference table: reprojection error in pixels and in metres at the reference's depth.
fn table(refs: &[Reference], res: &[Residual]) -> String {
    // Names are at most `calib::MAX_NAME_CHARS` long; the cap keeps any width a format width.
    let w = refs.iter().map(|r| r.name.chars().count()).max().unwrap_or(4).clamp(9, calib::MAX_NAME_CHARS);
    let mut s = format!(
        "{:<w$} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9}\n",
        "reference", "x_m", "y_m", "z_m", "u_px", "v_px", "depth_m", "error_px", "error_m"
    );
    for (r, e) in refs.iter().zip(res) {
        let p = r.world.0;
        let _ = writeln!(
            s,
            "{:<w$} {:>8.3} {:>8.3} {:>8.3} {:>8.1} {:>8.1} {:>8.2} {:>9.2} {:>9.4}",
            r.name, p.x, p.y, p.z, r.pixel.u, r.pixel.v, e.depth_m, e.error_px, e.error_m
        );
    }
    s
}

/// `--check`: the stored calibration against freshly marked points.
fn check(
    calib_path: &Path,
    refs: &[Reference],
    opts: &Options,
    frame: &image::RgbImage,
    overlay_path: Option<&Path>,
) -> anyhow::Result<()> {
    let stored = crate::calibration::load(calib_path).map_err(|e| usage(format!("--check {e}")))?;
    if refs.is_empty() {
        return Err(usage("--points: no references"));
    }
    for r in refs {
        let (u, v) = (r.pixel.u, r.pixel.v);
        if !(0.0..=f64::from(opts.width)).contains(&u) || !(0.0..=f64::from(opts.height)).contains(&v) {
            return Err(usage(format!(
                "{}: pixel ({u}, {v}) is outside the {}x{} image",
                r.label(),
                opts.width,
                opts.height
            )));
        }
    }
    let (res, rms) = calib::residuals(&stored.camera, refs);
    if let Some(p) = overlay_path {
        overlay(frame.clone(), &stored.camera, refs, &res, p)?;
    }
    let mut s = table(refs, &res);
    // How far the camera moved, when the points determine a pose on their own.
    let moved =
        calib::calibrate(refs, Some(&stored.camera.intrinsics), &Options { max_rms_px: f64::INFINITY, ..*opts })
            .ok()
            .map(|sol| {
                let d = sol.camera.pose.camera_center().distance(&stored.camera.pose.camera_center()).get();
                let a = calib::rotation_angle_deg(&sol.camera.pose.rotation, &stored.camera.pose.rotation);
                format!("; the pose from these points is {d:.3} m and {a:.2} degrees from the stored one")
            })
            .unwrap_or_default();
    if rms <= opts.max_rms_px {
        let _ = writeln!(
            s,
            "camera has not moved: RMS {rms:.2} px under {} is within the limit of {} px (--max-rms){moved}",
            calib_path.display(),
            opts.max_rms_px
        );
        write_stdout(&s)
    } else {
        write_stdout(&s)?;
        anyhow::bail!(
            "camera has moved (or a reference has): RMS {rms:.2} px under {} is over the limit of {} px \
             (--max-rms){moved}; recalibrate with fme calibrate (docs/calibration.md)",
            calib_path.display(),
            opts.max_rms_px
        )
    }
}
