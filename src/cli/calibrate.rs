//! `fme calibrate`: the camera's pose (and intrinsics, when not given) from reference objects the
//! divers measured, written as the calibration file `camera.calibration` reads; `--check` tells
//! whether the camera has moved since. See docs/calibration.md.

use super::{UsageError, write_stdout};
use crate::calib::{self, Options, Reference, Residual};
use crate::geometry::{Camera, Intrinsics, Pixel, WorldPoint};
use crate::sequence::{CameraMeta, ReferenceObject};
use anyhow::Context;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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

/// What `fme calibrate` writes besides the `camera` block and `reference_objects`.
#[derive(Debug, serde::Serialize)]
struct CalibrateInfo {
    frame: String,
    points: String,
    names: Vec<String>,
    rms_px: f64,
    max_rms_px: f64,
    click_px: f64,
    tape_m: f64,
    error_px: Vec<f64>,
    estimated_intrinsics: bool,
}

#[derive(Debug, serde::Serialize)]
struct CalibrationOut {
    width: u32,
    height: u32,
    camera: CameraMeta,
    reference_objects: Vec<ReferenceObject>,
    calibrate: CalibrateInfo,
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
    let intrinsics = match (&args.intrinsics, args.fx, args.fy, args.cx, args.cy) {
        (Some(p), ..) => Some(read_intrinsics(p)?),
        (None, Some(fx), Some(fy), Some(cx), Some(cy)) => {
            let k = Intrinsics { fx, fy, cx, cy, distortion: [0.0; 5] };
            k.validate().map_err(|e| usage(format!("--fx/--fy/--cx/--cy: {e}")))?;
            Some(k)
        }
        _ => None,
    };
    let sol =
        calib::calibrate(&refs, intrinsics.as_ref(), &opts).map_err(|e| usage(format!("{}: {e}", points.display())))?;
    let out = args.out.as_deref().ok_or_else(|| usage("--out is required"))?;
    let cam = sol.camera;
    let centre = cam.pose.camera_center();
    let reference_objects = refs
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let away = (r.world.0 - centre.0).try_normalize(1e-9).unwrap_or_default();
            let c = r.world.0 + away * (0.5 * args.ref_size);
            ReferenceObject {
                id: i as u32 + 1,
                size_m: args.ref_size,
                center_w: c.into(),
                front_face_center_w: r.world.0.into(),
            }
        })
        .collect();
    let file = CalibrationOut {
        width: opts.width,
        height: opts.height,
        camera: CameraMeta::from_camera(&cam),
        reference_objects,
        calibrate: CalibrateInfo {
            frame: args.frame.display().to_string(),
            points: points.display().to_string(),
            names: refs.iter().map(|r| r.name.clone()).collect(),
            rms_px: sol.rms_px,
            max_rms_px: args.max_rms,
            click_px: args.click_px,
            tape_m: args.tape_m,
            error_px: sol.residuals.iter().map(|r| r.error_px).collect(),
            estimated_intrinsics: sol.estimated_intrinsics,
        },
    };
    let mut text = serde_json::to_string_pretty(&file).context("encoding the calibration")?;
    text.push('\n');
    // The path is what the user gave: a missing folder or no permission is a usage error (exit 2).
    std::fs::write(out, text).map_err(|e| usage(format!("--out {}: {e}", out.display())))?;
    // Read back through the loader the daemon uses, so a file that it would reject is caught here.
    crate::calibration::load(out).map_err(|e| anyhow::anyhow!("the written calibration does not load: {e}"))?;
    if let Some(p) = &args.overlay {
        overlay(frame, &cam, &refs, &sol.residuals, p)?;
    }
    let mut s = table(&refs, &sol.residuals);
    let k = &cam.intrinsics;
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
    write_stdout(&s)
}

/// Grabs the sixth frame (after exposure settles) from a V4L2 camera or a recorded sequence
/// (`SourceConfig::is_camera`, as for `fme run --source`), and writes it to `out`.
fn grab(src: &Path, config: &super::ConfigArgs, out: &Path) -> anyhow::Result<image::RgbImage> {
    use crate::capture::{CaptureError, FrameSource, RecordedSource, V4l2Source};
    let (cfg, _) = config.load(&[super::set_text("source.path", &src.to_string_lossy())])?;
    let open_err = |e: CaptureError| match e {
        e @ (CaptureError::NotFound { .. } | CaptureError::Open { .. }) => usage(format!("--source: {e}")),
        e => anyhow::Error::new(e).context("--source"),
    };
    let mut source: Box<dyn FrameSource> = if cfg.source.is_camera() {
        let mut cam = V4l2Source::new(cfg.source.clone());
        cam.reopen().map_err(open_err)?;
        Box::new(cam)
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

/// Sets a pixel when it is inside the image.
fn put(img: &mut image::RgbImage, x: i64, y: i64, c: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u64) < u64::from(img.width()) && (y as u64) < u64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, image::Rgb(c));
    }
}

/// A straight line (Bresenham), clipped to the image; far-off end points are skipped.
fn line(img: &mut image::RgbImage, a: Pixel, b: Pixel, c: [u8; 3]) {
    let lim = 4.0 * f64::from(img.width().max(img.height()));
    if ![a.u, a.v, b.u, b.v].iter().all(|v| v.is_finite() && v.abs() < lim) {
        return;
    }
    let (mut x0, mut y0, x1, y1) = (a.u.floor() as i64, a.v.floor() as i64, b.u.floor() as i64, b.v.floor() as i64);
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let mut err = dx + dy;
    loop {
        put(img, x0, y0, c);
        if x0 == x1 && y0 == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x0 += sx;
        }
        if e2 <= dx {
            err += dx;
            y0 += sy;
        }
    }
}

/// A line `a`-`b` 3 px wide with a dark outline (readable on any background).
fn thick_line(img: &mut image::RgbImage, a: Pixel, b: Pixel, c: [u8; 3]) {
    for (dx, dy) in [(-2.0, 0.0), (2.0, 0.0), (0.0, -2.0), (0.0, 2.0)] {
        line(img, Pixel::new(a.u + dx, a.v + dy), Pixel::new(b.u + dx, b.v + dy), [0, 0, 0]);
    }
    for (dx, dy) in [(0.0, 0.0), (-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)] {
        line(img, Pixel::new(a.u + dx, a.v + dy), Pixel::new(b.u + dx, b.v + dy), c);
    }
}

/// Where the world origin is drawn: at its pixel when in view, else an arrow at the image edge
/// pointing towards it. `None` when the origin is at the camera itself.
#[derive(Debug, Clone, Copy, PartialEq)]
enum OriginMark {
    /// In view, at this pixel.
    InView(Pixel),
    /// Out of view: the arrow's tip (on the edge, inset) and the unit direction it points.
    Edge { tip: Pixel, dir: (f64, f64), behind: bool },
}

/// Inset of the origin arrow from the image edge, px.
const EDGE_INSET: f64 = 12.0;

fn origin_mark(cam: &Camera, w: u32, h: u32) -> Option<OriginMark> {
    let (w, h) = (f64::from(w), f64::from(h));
    let o = WorldPoint(nalgebra::Vector3::zeros());
    let c = cam.pose.to_camera(&o).0;
    let centre = (w / 2.0, h / 2.0);
    let (dir, behind) = match cam.world_to_pixel(&o) {
        Ok(p) if (0.0..w).contains(&p.u) && (0.0..h).contains(&p.v) => return Some(OriginMark::InView(p)),
        Ok(p) => ((p.u - centre.0, p.v - centre.1), false),
        // Behind the camera: turn the camera towards its x, y side.
        Err(_) => ((c.x, c.y), true),
    };
    let n = dir.0.hypot(dir.1);
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    let d = (dir.0 / n, dir.1 / n);
    // From the centre along d to the inset border.
    let (hx, hy) = (centre.0 - EDGE_INSET, centre.1 - EDGE_INSET);
    let t = [
        if d.0.abs() > 1e-12 { hx / d.0.abs() } else { f64::INFINITY },
        if d.1.abs() > 1e-12 { hy / d.1.abs() } else { f64::INFINITY },
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min);
    Some(OriginMark::Edge { tip: Pixel::new(centre.0 + d.0 * t, centre.1 + d.1 * t), dir: d, behind })
}

/// The overlay PNG: marked references (green crosses) with their name and error, reprojected (red
/// circles) joined by a yellow line, the world axes, 1 m each (x red, y green, z blue, labelled),
/// from the origin and from the references' centroid, the origin itself (or an arrow at the edge
/// towards it), and a legend.
fn overlay(
    mut img: image::RgbImage,
    cam: &Camera,
    refs: &[Reference],
    res: &[Residual],
    path: &Path,
) -> anyhow::Result<()> {
    use crate::draw::{self, Placer, Rect};
    use image::Rgb;
    let (w, h) = img.dimensions();
    let px = (h as f32 / 36.0).clamp(11.0, 24.0);
    let mut placer = Placer::new(Rect::new(0, 0, i64::from(w), i64::from(h)));
    let (_, lh) = draw::text_size("0", px);
    let rms = (res.iter().map(|r| r.error_px * r.error_px).sum::<f64>() / res.len().max(1) as f64).sqrt();
    let legend = [
        ("+ marked reference: name, reprojection error".to_string(), [0, 255, 0]),
        ("o where the calibration puts it (yellow: the error)".to_string(), [255, 80, 80]),
        ("axes 1 m: x red, y green, z blue".to_string(), [255, 255, 255]),
        (format!("RMS error {rms:.2} px over {} references", refs.len()), [255, 255, 255]),
    ];
    let lw = legend.iter().map(|(t, _)| draw::text_size(t, px).0).max().unwrap_or(0);
    let legend_box = Rect::new(0, 0, lw + 10, legend.len() as i64 * (lh + 2) + 6);
    placer.block(legend_box);
    let mut labels: Vec<(Rect, String, [u8; 3])> = Vec::new();
    // The axes from the world origin, and (the origin is often outside the view, at a cage corner)
    // from the references' centroid.
    let n = refs.len().max(1) as f64;
    let centroid = refs.iter().fold(nalgebra::Vector3::zeros(), |a, r| a + r.world.0 / n);
    for origin in [nalgebra::Vector3::zeros(), centroid] {
        for (axis, colour, name) in [(0usize, [255, 0, 0], "x"), (1, [0, 255, 0], "y"), (2, [0, 128, 255], "z")] {
            // Sampled in 3D so the part of an axis behind the camera is left out.
            let mut prev: Option<Pixel> = None;
            let mut end = None;
            for k in 0..=100 {
                let mut p = origin;
                p[axis] += f64::from(k) / 100.0;
                let px = cam.world_to_pixel(&WorldPoint(p)).ok();
                if let (Some(a), Some(b)) = (prev, px) {
                    thick_line(&mut img, a, b, colour);
                }
                prev = px;
                end = px.or(end);
            }
            if let Some(e) = end {
                let anchor = Rect::new(e.u as i64 - 3, e.v as i64 - 3, 7, 7);
                let text = format!("{name} 1m");
                let (tw, th) = draw::text_size(&text, px);
                if let Some(r) = placer.place(&draw::place::candidates(anchor, tw, th, 2), &[]) {
                    labels.push((r, text, colour));
                }
            }
        }
    }
    for (r, e) in refs.iter().zip(res) {
        let m = r.pixel;
        if let Some(p) = e.projected {
            line(&mut img, m, p, [255, 255, 0]);
            for k in 0..48 {
                let a = f64::from(k) * std::f64::consts::TAU / 48.0;
                for (rad, c) in [(6.0, [0, 0, 0]), (5.0, [255, 0, 0]), (4.0, [0, 0, 0])] {
                    put(&mut img, (p.u + rad * a.cos()).floor() as i64, (p.v + rad * a.sin()).floor() as i64, c);
                }
            }
        }
        draw::cross(&mut img, m.u.floor() as i64, m.v.floor() as i64, 6, Rgb([0, 255, 0]));
    }
    let marks: Vec<Rect> = refs.iter().map(|r| Rect::new(r.pixel.u as i64 - 7, r.pixel.v as i64 - 7, 15, 15)).collect();
    for ((r, e), m) in refs.iter().zip(res).zip(&marks) {
        let text = format!("{} {:.1} px", r.name, e.error_px);
        let (tw, th) = draw::text_size(&text, px);
        let c = if e.error_px > 3.0 { [255, 120, 120] } else { [120, 255, 120] };
        if let Some(b) = placer.place(&draw::place::candidates(*m, tw, th, 3), &marks) {
            labels.push((b, text, c));
        }
    }
    match origin_mark(cam, w, h) {
        Some(OriginMark::InView(p)) => {
            draw::cross(&mut img, p.u as i64, p.v as i64, 9, Rgb([255, 0, 255]));
            let text = "origin (0,0,0)".to_string();
            let (tw, th) = draw::text_size(&text, px);
            if let Some(b) = placer
                .place(&draw::place::candidates(Rect::new(p.u as i64 - 9, p.v as i64 - 9, 19, 19), tw, th, 3), &[])
            {
                labels.push((b, text, [255, 0, 255]));
            }
        }
        Some(OriginMark::Edge { tip, dir, behind }) => {
            let len = 40.0;
            let tail = Pixel::new(tip.u - dir.0 * len, tip.v - dir.1 * len);
            thick_line(&mut img, tail, tip, [255, 0, 255]);
            for a in [-0.5f64, 0.5] {
                // The arrow head: the backward direction turned by +-0.5 rad.
                let (bx, by) = (-dir.0 * a.cos() + dir.1 * a.sin(), -dir.0 * a.sin() - dir.1 * a.cos());
                thick_line(&mut img, tip, Pixel::new(tip.u + bx * 14.0, tip.v + by * 14.0), [255, 0, 255]);
            }
            let text = if behind { "origin (behind the camera)" } else { "origin (out of view)" }.to_string();
            let (tw, th) = draw::text_size(&text, px);
            let anchor = Rect::new(
                tail.u.min(tip.u) as i64,
                tail.v.min(tip.v) as i64,
                (tail.u - tip.u).abs() as i64,
                (tail.v - tip.v).abs() as i64,
            );
            let mut cands = draw::place::candidates(anchor, tw, th, 4).to_vec();
            // Pulled inside the image when the arrow hugs an edge.
            cands.extend(
                cands
                    .clone()
                    .into_iter()
                    .map(|r| Rect::new(r.x.clamp(0, i64::from(w) - tw), r.y.clamp(0, i64::from(h) - th), tw, th)),
            );
            if let Some(b) = placer.place(&cands, &[]) {
                labels.push((b, text, [255, 0, 255]));
            }
        }
        None => {}
    }
    for (b, text, c) in &labels {
        draw::draw_text(&mut img, b.x, b.y, text, px, Rgb(*c), Some(draw::OUTLINE));
    }
    draw::fill_rect(&mut img, legend_box, Rgb([0, 0, 0]), 0.65);
    for (i, (t, c)) in legend.iter().enumerate() {
        draw::draw_text(&mut img, 5, 3 + i as i64 * (lh + 2), t, px, Rgb(*c), None);
    }
    img.save_with_format(path, image::ImageFormat::Png).map_err(|e| usage(format!("--overlay {}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;

    fn cam(eye: (f64, f64, f64), target: (f64, f64, f64)) -> Camera {
        let pose = Pose::look_at(
            WorldPoint::new(eye.0, eye.1, eye.2),
            WorldPoint::new(target.0, target.1, target.2),
            nalgebra::Vector3::z(),
        )
        .expect("pose");
        Camera { intrinsics: Intrinsics::from_hfov(640, 480, 90.0).expect("intrinsics"), pose }
    }

    #[test]
    fn origin_marked_in_view_or_by_an_arrow_at_the_edge() {
        // Looking at the origin from 5 m: in view, at the centre.
        match origin_mark(&cam((0.0, -5.0, 0.0), (0.0, 0.0, 0.0)), 640, 480) {
            Some(OriginMark::InView(p)) => assert!((p.u - 320.0).abs() < 1e-6 && (p.v - 240.0).abs() < 1e-6),
            other => panic!("{other:?}"),
        }
        // The origin 10 m to the left at 5 m: an arrow on the left edge pointing left.
        match origin_mark(&cam((10.0, -5.0, 0.0), (10.0, 0.0, 0.0)), 640, 480) {
            Some(OriginMark::Edge { tip, dir, behind: false }) => {
                assert!((tip.u - EDGE_INSET).abs() < 1e-6 && (tip.v - 240.0).abs() < 1e-6, "{tip:?}");
                assert!(dir.0 < -0.99, "{dir:?}");
            }
            other => panic!("{other:?}"),
        }
        // Behind the camera and below: an arrow on the bottom edge, said to be behind.
        match origin_mark(&cam((0.0, 5.0, 3.0), (0.0, 10.0, 3.0)), 640, 480) {
            Some(OriginMark::Edge { tip, behind: true, .. }) => assert!((tip.v - (480.0 - EDGE_INSET)).abs() < 1e-6),
            other => panic!("{other:?}"),
        }
    }
}
