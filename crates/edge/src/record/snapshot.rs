//! Snapshots: what the box sees. The frame with the pipeline's results drawn on it as JPEG: a top bar
//! (activity in m/s and BL/s, smoothed, fish count, local time, camera; green when the depth is
//! calibrated, red when not), track boxes in bright outlined colours with `id speed depth` labels
//! placed so they do not overlap (those with no room are counted), detections in grey, the
//! reference objects with their depth-fit error in cm, and a legend. The metric depth map as a
//! colour PNG with its scale (near = red, far = blue, unknown = black). docs/recording.md.

use super::Overlays;
use crate::draw::{self, Placer, Rect};
use fme_core::pipeline::{ActivitySample, Frame};
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};

/// The grid the depth map is sampled on for a snapshot (columns, rows).
pub const DEPTH_GRID: (u32, u32) = (160, 96);

/// Residuals over this are drawn red (the fit is off there), m.
const RESIDUAL_WARN_M: f64 = 0.1;

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const GREY: Rgb<u8> = Rgb([200, 200, 200]);
const GOOD: Rgb<u8> = Rgb([255, 220, 0]);
const BAD: Rgb<u8> = Rgb([255, 64, 64]);
const CALIBRATED: Rgb<u8> = Rgb([90, 255, 90]);

/// What the top bar says: the activity sample, when and which camera.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Caption {
    /// The frame's activity sample (None: no value yet).
    pub sample: Option<ActivitySample>,
    /// The camera (device or sequence name); empty = not shown.
    pub camera: String,
    /// Wall-clock time of the snapshot as text; empty = not shown.
    pub time: String,
}

impl Caption {
    /// The camera's name (last part of `source`: `video0`, a sequence folder) and the local time now
    /// (the box's zone: `TZ`, `/etc/localtime`).
    pub fn now(source: &Path, sample: Option<&ActivitySample>) -> Self {
        let camera = source.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
        Self { sample: sample.copied(), camera, time: jiff::Zoned::now().strftime("%Y-%m-%d %H:%M:%S %Z").to_string() }
    }
}

fn num(v: f64, decimals: usize) -> String {
    if v.is_finite() { format!("{v:.decimals$}") } else { "-".into() }
}

/// Text size for a picture `h` px high.
fn font_px(h: u32) -> f32 {
    (h as f32 / 30.0).clamp(11.0, 22.0)
}

/// The top bar's parts, each with its colour.
fn bar_parts(sample: Option<&ActivitySample>, fish_tracked: usize, caption: &Caption) -> Vec<(String, Rgb<u8>)> {
    let mut parts = Vec::new();
    match sample {
        Some(s) => {
            let c = if s.flags.unfitted { BAD } else { CALIBRATED };
            parts.push((format!("activity {} m/s ({} BL/s)", num(s.mean.0, 3), num(s.mean_body_lengths, 2)), c));
            parts.push((format!("smoothed {} m/s", num(s.smoothed.0, 3)), c));
            parts.push((format!("{} fish", s.fish), WHITE));
            if s.flags.unfitted {
                parts.push(("depth NOT calibrated".into(), BAD));
            }
            if s.flags.too_few_fish {
                parts.push(("too few fish".into(), BAD));
            }
            if s.flags.unlike_fish {
                parts.push(("detections look unlike fish".into(), BAD));
            }
        }
        None => {
            parts.push(("activity: no value yet".into(), GREY));
            parts.push((format!("{fish_tracked} fish tracked"), WHITE));
        }
    }
    for t in [&caption.time, &caption.camera] {
        if !t.is_empty() {
            parts.push((t.clone(), WHITE));
        }
    }
    parts
}

/// Draws the top bar (the parts joined by ` | `, wrapped to the width) and returns its box.
fn top_bar(img: &mut RgbImage, parts: &[(String, Rgb<u8>)], px: f32) -> Rect {
    let w = i64::from(img.width());
    let (sep_w, lh) = draw::text_size(" | ", px);
    let mut lines: Vec<Vec<&(String, Rgb<u8>)>> = vec![Vec::new()];
    let mut x = 4;
    for p in parts {
        let pw = draw::text_size(&p.0, px).0;
        let line = lines.last_mut().expect("one line");
        if !line.is_empty() && x + sep_w + pw > w - 4 {
            lines.push(vec![p]);
            x = 4 + pw;
        } else {
            x += if line.is_empty() { pw } else { sep_w + pw };
            line.push(p);
        }
    }
    let bar = Rect::new(0, 0, w, lines.len() as i64 * (lh + 2) + 4);
    draw::fill_rect(img, bar, Rgb([0, 0, 0]), 0.8);
    for (i, line) in lines.iter().enumerate() {
        let (mut x, y) = (4, 2 + i as i64 * (lh + 2));
        for (k, (text, c)) in line.iter().enumerate() {
            if k > 0 {
                draw::draw_text(img, x, y, " | ", px, GREY, None);
                x += sep_w;
            }
            draw::draw_text(img, x, y, text, px, *c, None);
            x += draw::text_size(text, px).0;
        }
    }
    bar
}

/// The legend's lines: what each mark means (only the marks in the picture).
fn legend_lines(overlays: &Overlays) -> Vec<(String, Rgb<u8>)> {
    let mut l = Vec::new();
    if !overlays.fish.is_empty() {
        l.push(("box: fish track; label: id speed(m/s) depth(m)".into(), WHITE));
    }
    if !overlays.detections.is_empty() {
        l.push(("grey box: detection".into(), GREY));
    }
    if !overlays.references.is_empty() {
        l.push(("+ reference: depth fit error in cm".into(), GOOD));
        l.push((format!("  (yellow ok, red over {:.0} cm)", RESIDUAL_WARN_M * 100.0), BAD));
    }
    l
}

/// The frame with overlays.
pub fn overlay(frame: &Frame, overlays: &Overlays, caption: &Caption) -> Result<RgbImage, String> {
    let mut rgb = Vec::new();
    let (w, h) = frame.to_rgb_into(&mut rgb)?;
    let mut img = RgbImage::from_raw(w, h, rgb).ok_or("decoded frame has the wrong size")?;
    let px = font_px(h);
    let small = (px * 0.9).max(10.0);
    let pbox = |b: fme_core::geometry::PixelBox| Rect::new(b.x as i64, b.y as i64, b.w as i64, b.h as i64);
    for (b, _) in &overlays.detections {
        let r = pbox(*b);
        for x in r.x..=r.x + r.w {
            draw::put(&mut img, x, r.y, GREY);
            draw::put(&mut img, x, r.y + r.h, GREY);
        }
        for y in r.y..=r.y + r.h {
            draw::put(&mut img, r.x, y, GREY);
            draw::put(&mut img, r.x + r.w, y, GREY);
        }
    }
    for t in &overlays.fish {
        draw::outlined_rect(&mut img, pbox(t.bbox), draw::id_colour(t.id), 2);
    }
    let bar = top_bar(&mut img, &bar_parts(caption.sample.as_ref(), overlays.fish.len(), caption), px);
    let mut placer = Placer::new(Rect::new(0, 0, i64::from(w), i64::from(h)));
    placer.block(bar);
    // The legend, bottom left, with a line kept for the count of hidden labels.
    let mut legend = legend_lines(overlays);
    let lh = draw::text_size("0", small).1 + 1;
    let hidden_slot = !overlays.fish.is_empty() || !overlays.references.is_empty();
    let rows = legend.len() as i64 + i64::from(hidden_slot);
    let lw = legend
        .iter()
        .map(|(t, _)| draw::text_size(t, small).0)
        .chain([draw::text_size("99 labels hidden (no room)", small).0])
        .max()
        .unwrap_or(0);
    let legend_box = Rect::new(0, i64::from(h) - rows * lh - 6, lw + 8, rows * lh + 6);
    if rows > 0 {
        placer.block(legend_box);
    }
    let marks: Vec<Rect> = overlays
        .fish
        .iter()
        .map(|t| pbox(t.bbox))
        .chain(overlays.references.iter().map(|(p, _)| Rect::new(p.u as i64 - 5, p.v as i64 - 5, 11, 11)))
        .collect();
    // Labels are drawn after every mark, so no mark covers one.
    let mut labels: Vec<(Rect, String, Rgb<u8>)> = Vec::new();
    // A label never covers a reference's cross (it may cover a fish: the box stays visible).
    for r in &marks[overlays.fish.len()..] {
        placer.block(*r);
    }
    for t in &overlays.fish {
        let label = format!(
            "{} {}m/s {}m",
            t.id,
            num(t.speed.map_or(f64::NAN, |s| s.0), 2),
            num(t.depth.map_or(f64::NAN, |d| d.0), 1)
        );
        let (tw, th) = draw::text_size(&label, small);
        if let Some(r) = placer.place(&draw::place::candidates(pbox(t.bbox), tw, th, 3), &marks) {
            labels.push((r, label, draw::id_colour(t.id)));
        }
    }
    // Reference objects: a cross, and the fit's residual there in cm (fitted minus known depth).
    for &(p, residual) in &overlays.references {
        let c = if residual.abs() > RESIDUAL_WARN_M { BAD } else { GOOD };
        let (x, y) = (p.u as i64, p.v as i64);
        draw::cross(&mut img, x, y, 5, c);
        let cm = (residual * 100.0).round();
        let label = match cm {
            _ if !cm.is_finite() => "? cm".to_string(),
            0.0 => "0 cm".to_string(),
            _ => format!("{cm:+.0} cm"),
        };
        let (tw, th) = draw::text_size(&label, small);
        if let Some(r) = placer.place(&draw::place::candidates(Rect::new(x - 5, y - 5, 11, 11), tw, th, 2), &marks) {
            labels.push((r, label, c));
        }
    }
    for (r, text, c) in &labels {
        draw::draw_text(&mut img, r.x, r.y, text, small, *c, Some(draw::OUTLINE));
    }
    if placer.dropped > 0 {
        legend.push((format!("{} labels hidden (no room)", placer.dropped), WHITE));
    }
    if rows > 0 {
        draw::fill_rect(&mut img, legend_box, Rgb([0, 0, 0]), 0.6);
        for (i, (t, c)) in legend.iter().enumerate() {
            draw::draw_text(&mut img, 4, legend_box.y + 3 + i as i64 * lh, t, small, *c, None);
        }
    }
    Ok(img)
}

/// Width of the depth map's scale panel, px.
const SCALE_W: u32 = 120;

/// The metric depth grid as a colour image, each cell 4x4 px, with a colour scale (metres) to its
/// right.
pub fn depth_image(depth: &[f32], grid: (u32, u32)) -> RgbImage {
    let finite = depth.iter().copied().filter(|d| d.is_finite());
    let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), d| (a.min(d), b.max(d)));
    let span = (hi - lo).max(1e-6);
    let (mw, mh) = (grid.0 * 4, grid.1 * 4);
    let height = mh.max(200);
    let mut img = RgbImage::from_pixel(mw + SCALE_W, height, Rgb([255, 255, 255]));
    for y in 0..mh {
        for x in 0..mw {
            let d = depth.get(((y / 4) * grid.0 + x / 4) as usize).copied().unwrap_or(f32::NAN);
            let c = if d.is_finite() { draw::depth_colour((d - lo) / span) } else { Rgb([0, 0, 0]) };
            img.put_pixel(x, y, c);
        }
    }
    let black = Rgb([0, 0, 0]);
    let px = 13.0;
    let th = draw::text_size("0", px).1;
    let x0 = i64::from(mw) + 10;
    draw::draw_text(&mut img, x0, 4, "depth (m)", px, black, None);
    let (top, bottom) = (8 + th + 4, i64::from(height) - 2 * th - 12);
    if lo.is_finite() {
        // The bar: near (lo) at the top, as in the map's red.
        for y in top..=bottom {
            let q = (y - top) as f32 / (bottom - top).max(1) as f32;
            draw::fill_rect(&mut img, Rect::new(x0, y, 18, 1), draw::depth_colour(q), 1.0);
        }
        for k in 0..=4 {
            let y = top + (bottom - top) * k / 4;
            let v = lo + span * k as f32 / 4.0;
            draw::fill_rect(&mut img, Rect::new(x0 + 18, y, 5, 1), black, 1.0);
            draw::draw_text(&mut img, x0 + 26, y - th / 2, &format!("{v:.2}"), px, black, None);
        }
    } else {
        draw::draw_text(&mut img, x0, top, "no depth", px, black, None);
    }
    draw::fill_rect(&mut img, Rect::new(x0, i64::from(height) - th - 4, 12, th), black, 1.0);
    draw::draw_text(&mut img, x0 + 16, i64::from(height) - th - 4, "unknown", px * 0.9, black, None);
    img
}

/// Writes `<dir>/<name>.jpg` (the overlay) and, when `depth` is given, `<dir>/<name>-depth.png`,
/// then keeps the newest `keep` snapshots. Returns the JPEG's path. Errors name the file.
pub fn write(
    dir: &Path,
    name: &str,
    frame: &Frame,
    overlays: &Overlays,
    caption: &Caption,
    depth: Option<&[f32]>,
    keep: usize,
) -> Result<PathBuf, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let img = overlay(frame, overlays, caption).map_err(|e| format!("frame {}: {e}", frame.seq))?;
    let jpg = dir.join(format!("{name}.jpg"));
    let bytes = crate::sequence::encode_jpeg(&img, 90).map_err(|e| format!("{}: {e}", jpg.display()))?;
    std::fs::write(&jpg, bytes).map_err(|e| format!("{}: {e}", jpg.display()))?;
    if let Some(d) = depth {
        let png = dir.join(format!("{name}-depth.png"));
        depth_image(d, DEPTH_GRID).save(&png).map_err(|e| format!("{}: {e}", png.display()))?;
    }
    // Two files per snapshot.
    super::freeze::rotate(dir, keep * 2);
    Ok(jpg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, grey: u8) -> Frame {
        let mut jpg = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 90);
        image::DynamicImage::from(RgbImage::from_pixel(w, h, Rgb([grey; 3]))).write_with_encoder(enc).expect("encode");
        Frame {
            seq: 0,
            timestamp: fme_core::units::Seconds(0.0),
            arrived: std::time::Instant::now(),
            width: w,
            height: h,
            format: fme_core::pipeline::PixelFormat::Jpeg,
            data: jpg,
        }
    }

    fn sample(uncalibrated: bool) -> ActivitySample {
        ActivitySample {
            timestamp: fme_core::units::Seconds(1.0),
            mean: fme_core::units::MetresPerSecond(0.402),
            mean_body_lengths: 1.21,
            smoothed: fme_core::units::MetresPerSecond(0.39),
            ci95_half: fme_core::units::MetresPerSecond(0.02),
            fish: 22,
            latency: fme_core::units::Seconds(0.5),
            flags: fme_core::pipeline::QualityFlags { unfitted: uncalibrated, ..Default::default() },
            scale: fme_core::pipeline::ScaleSource::default(),
        }
    }

    #[test]
    fn references_marked_with_their_residual() {
        let mut overlays = Overlays::default();
        let p = |u, v| fme_core::geometry::Pixel { u, v };
        overlays.references.extend([(p(100.0, 120.0), 0.02), (p(220.0, 120.0), -0.3)]);
        let img = overlay(&frame(320, 240, 0), &overlays, &Caption::default()).expect("overlay");
        assert_eq!(img.get_pixel(100, 120).0, [255, 220, 0], "a good reference is yellow");
        assert_eq!(img.get_pixel(220, 116).0, [255, 64, 64], "a reference 30 cm off is red");
        // The legend (bottom left) explains the marks: text pixels in the reference colour there.
        let legend = (0..160).flat_map(|x| (200..240).map(move |y| (x, y)));
        assert!(
            legend
                .filter(|&(x, y)| {
                    let p = img.get_pixel(x, y).0;
                    p[0] > 120 && p[1] > 100 && p[2] < 60
                })
                .count()
                > 30
        );
    }

    #[test]
    fn top_bar_says_what_where_and_when() {
        let cap =
            Caption { sample: Some(sample(false)), camera: "cam0".into(), time: "2030-01-15 14:03:21 UTC".into() };
        let parts: Vec<String> = bar_parts(Some(&sample(false)), 0, &cap).into_iter().map(|p| p.0).collect();
        assert_eq!(
            parts,
            ["activity 0.402 m/s (1.21 BL/s)", "smoothed 0.390 m/s", "22 fish", "2030-01-15 14:03:21 UTC", "cam0"]
        );
        let parts = bar_parts(Some(&sample(true)), 0, &Caption::default());
        assert!(parts.iter().any(|p| p.0 == "depth NOT calibrated" && p.1 == BAD), "{parts:?}");
        assert_eq!(bar_parts(None, 3, &Caption::default())[1].0, "3 fish tracked");
        // Drawn: on a bright frame the bar is dark, with green (calibrated) and white text in it; it
        // wraps to two lines on a narrow frame rather than running off the edge.
        let img = overlay(&frame(640, 384, 230), &Overlays::default(), &cap).expect("overlay");
        let bar = |img: &RgbImage, y0: u32, y1: u32| {
            let px: Vec<[u8; 3]> = (y0..y1)
                .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
                .map(|(x, y)| img.get_pixel(x, y).0)
                .collect();
            let green = px.iter().filter(|p| p[1] > 200 && p[0] < 150).count();
            let white = px.iter().filter(|p| p.iter().all(|&c| c > 200)).count();
            let dark = px.iter().filter(|p| p.iter().all(|&c| c < 80)).count();
            (green, white, dark, px.len())
        };
        let (green, white, dark, n) = bar(&img, 0, 16);
        assert!(green > 100 && white > 100 && dark > n / 2, "{green} {white} {dark} of {n}");
        assert_eq!(bar(&img, 60, 70).2, 0, "the frame below the bar is untouched");
        let narrow = overlay(&frame(320, 240, 230), &Overlays::default(), &cap).expect("overlay");
        let (_, white2, dark2, n2) = bar(&narrow, 18, 28);
        assert!(white2 > 20 && dark2 > n2 / 2, "second line of the bar: {white2} {dark2} of {n2}");
    }

    #[test]
    fn palette_is_bright_for_dark_water() {
        for c in draw::PALETTE {
            let luma = 0.299 * f64::from(c[0]) + 0.587 * f64::from(c[1]) + 0.114 * f64::from(c[2]);
            assert!(luma > 120.0, "{c:?} too dark");
        }
        assert_ne!(draw::id_colour(1), draw::id_colour(2));
    }

    #[test]
    fn depth_coloured_with_a_scale() {
        let d = depth_image(&[1.0, f32::NAN, 3.0, 2.0], (2, 2));
        assert_eq!(d.get_pixel(0, 0).0[0], 255, "near is red");
        assert_eq!(d.get_pixel(4, 0).0, [0, 0, 0], "unknown is black");
        assert_eq!(d.get_pixel(0, 4).0[2], 255, "far is blue");
        // The scale bar right of the map: red at its top, blue at its bottom, dark value text beside.
        assert_eq!(d.width(), 8 + SCALE_W);
        let col: Vec<[u8; 3]> = (0..d.height()).map(|y| d.get_pixel(8 + 15, y).0).collect();
        let first_red = col.iter().position(|p| p[0] > 240 && p[2] < 20).expect("red in the bar");
        let last_blue = col.iter().rposition(|p| p[2] > 240 && p[0] < 20).expect("blue in the bar");
        assert!(first_red < last_blue, "near at the top");
        let text = (8 + 40..d.width()).flat_map(|x| (0..d.height()).map(move |y| (x, y)));
        assert!(text.filter(|&(x, y)| d.get_pixel(x, y).0[0] < 100).count() > 100, "tick values written");
    }
}
