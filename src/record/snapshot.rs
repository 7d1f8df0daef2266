//! Snapshots: what the box sees. The frame with the pipeline's results drawn on it (boxes coloured by
//! track id with the id, speed in m/s and depth in m in small drawn digits; detections in grey; a top
//! bar with the smoothed activity and the fish count, green when calibrated, red when not) as JPEG,
//! and the metric depth map as a colour PNG (near = red, far = blue, unknown = black).
//! No font dependency: a 3x5 digit font drawn at 2x. docs/recording.md.

use crate::pipeline::{ActivitySample, Frame, FrameView};
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};

/// The grid the depth map is sampled on for a snapshot (columns, rows).
pub const DEPTH_GRID: (u32, u32) = (160, 96);

/// 3x5 glyphs, one row per entry (bit 2 = left column), for `0-9 . - m`.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        'n' => [0, 0, 6, 5, 5],
        _ => [0; 5],
    }
}

/// Draws `text` with its top-left at (x, y), 2x scale (8 px per character), clipped to the image.
fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, colour: Rgb<u8>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for (i, c) in text.chars().enumerate() {
        let g = glyph(c);
        for (r, bits) in g.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let px = x + i as i64 * 8 + col * 2 + dx;
                    let py = y + r as i64 * 2 + dy;
                    if (0..w).contains(&px) && (0..h).contains(&py) {
                        img.put_pixel(px as u32, py as u32, colour);
                    }
                }
            }
        }
    }
}

fn draw_rect(img: &mut RgbImage, b: crate::geometry::PixelBox, colour: Rgb<u8>, thick: i64) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    let (x0, y0, x1, y1) = (b.x as i64, b.y as i64, (b.x + b.w) as i64, (b.y + b.h) as i64);
    let mut put = |x: i64, y: i64| {
        if (0..w).contains(&x) && (0..h).contains(&y) {
            img.put_pixel(x as u32, y as u32, colour);
        }
    };
    for k in 0..thick {
        for x in x0..=x1 {
            put(x, y0 + k);
            put(x, y1 - k);
        }
        for y in y0..=y1 {
            put(x0 + k, y);
            put(x1 - k, y);
        }
    }
}

fn id_colour(id: u32) -> Rgb<u8> {
    let h = id.wrapping_mul(2_654_435_761);
    Rgb([(h >> 24) as u8 | 0x40, (h >> 16) as u8 | 0x40, (h >> 8) as u8 | 0x40])
}

fn num(v: f64, decimals: usize) -> String {
    if v.is_finite() { format!("{v:.decimals$}") } else { "-".into() }
}

/// The frame with overlays.
pub fn overlay(frame: &Frame, view: &FrameView, sample: Option<&ActivitySample>) -> Result<RgbImage, String> {
    let mut rgb = Vec::new();
    let (w, h) = frame.to_rgb_into(&mut rgb)?;
    let mut img = RgbImage::from_raw(w, h, rgb).ok_or("decoded frame has the wrong size")?;
    for (b, _) in &view.detections {
        draw_rect(&mut img, *b, Rgb([160, 160, 160]), 1);
    }
    for t in &view.tracks {
        let c = id_colour(t.id);
        draw_rect(&mut img, t.bbox, c, 2);
        draw_text(&mut img, t.bbox.x as i64, t.bbox.y as i64 - 12, &t.id.to_string(), c);
        let line = format!("{} {}", num(t.speed_mps, 2), num(t.depth_m, 1));
        draw_text(&mut img, t.bbox.x as i64, (t.bbox.y + t.bbox.h) as i64 + 3, &line, c);
    }
    // Reference objects: a cross, and the fit's residual there in cm (yellow; red over 10 cm).
    for &(px, residual) in &view.references {
        let c = if residual.abs() > 0.1 { Rgb([255, 64, 64]) } else { Rgb([255, 220, 0]) };
        let (x, y) = (px.u as i64, px.v as i64);
        for d in -4..=4i64 {
            for (xx, yy) in [(x + d, y), (x, y + d)] {
                if xx >= 0 && yy >= 0 && xx < i64::from(w) && yy < i64::from(h) {
                    img.put_pixel(xx as u32, yy as u32, c);
                }
            }
        }
        draw_text(&mut img, x + 6, y - 2, &num(residual * 100.0, 0), c);
    }
    for y in 0..14.min(h) {
        for x in 0..w {
            img.put_pixel(x, y, Rgb([0, 0, 0]));
        }
    }
    if let Some(s) = sample {
        let colour = if s.flags.depth_uncalibrated { Rgb([255, 64, 64]) } else { Rgb([64, 255, 64]) };
        draw_text(&mut img, 2, 2, &format!("{} {}", num(s.smoothed.0, 3), s.fish), colour);
    }
    Ok(img)
}

/// The metric depth grid as a colour image, each cell 4x4 px.
pub fn depth_image(depth: &[f32], grid: (u32, u32)) -> RgbImage {
    let finite = depth.iter().copied().filter(|d| d.is_finite());
    let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), d| (a.min(d), b.max(d)));
    let span = (hi - lo).max(1e-6);
    RgbImage::from_fn(grid.0 * 4, grid.1 * 4, |x, y| {
        let d = depth.get(((y / 4) * grid.0 + x / 4) as usize).copied().unwrap_or(f32::NAN);
        if !d.is_finite() {
            return Rgb([0, 0, 0]);
        }
        let q = ((d - lo) / span).clamp(0.0, 1.0);
        // Near = red, middle = green, far = blue.
        let r = (255.0 * (1.0 - 2.0 * q).clamp(0.0, 1.0)) as u8;
        let g = (255.0 * (1.0 - (2.0 * q - 1.0).abs())) as u8;
        let b = (255.0 * (2.0 * q - 1.0).clamp(0.0, 1.0)) as u8;
        Rgb([r, g, b])
    })
}

/// Writes `<dir>/<name>.jpg` (the overlay) and, when `depth` is given, `<dir>/<name>-depth.png`,
/// then keeps the newest `keep` snapshots. Returns the JPEG's path. Errors name the file.
pub fn write(
    dir: &Path,
    name: &str,
    frame: &Frame,
    view: &FrameView,
    sample: Option<&ActivitySample>,
    depth: Option<&[f32]>,
    keep: usize,
) -> Result<PathBuf, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let img = overlay(frame, view, sample).map_err(|e| format!("frame {}: {e}", frame.seq))?;
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

    #[test]
    fn references_marked_with_their_residual() {
        let mut jpg = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 90);
        image::DynamicImage::from(RgbImage::new(64, 48)).write_with_encoder(enc).expect("encode");
        let frame = Frame {
            seq: 0,
            timestamp: crate::units::Seconds(0.0),
            arrived: std::time::Instant::now(),
            width: 64,
            height: 48,
            format: crate::pipeline::PixelFormat::Jpeg,
            data: jpg,
        };
        let mut view = FrameView::default();
        let p = |u, v| crate::geometry::Pixel { u, v };
        view.references.extend([(p(20.0, 30.0), 0.02), (p(44.0, 30.0), -0.3)]);
        let img = overlay(&frame, &view, None).expect("overlay");
        assert_eq!(img.get_pixel(20, 30).0, [255, 220, 0], "a good reference is yellow");
        assert_eq!(img.get_pixel(44, 26).0, [255, 64, 64], "a reference 30 cm off is red");
    }

    #[test]
    fn digits_drawn_and_depth_coloured() {
        let mut img = RgbImage::new(40, 12);
        draw_text(&mut img, 0, 0, "10", Rgb([255, 255, 255]));
        let lit = img.pixels().filter(|p| p.0[0] == 255).count();
        // "1": 8 cells, "0": 12 cells, 4 px each.
        assert_eq!(lit, (8 + 12) * 4);
        let d = depth_image(&[1.0, f32::NAN, 3.0, 2.0], (2, 2));
        assert_eq!(d.get_pixel(0, 0).0[0], 255, "near is red");
        assert_eq!(d.get_pixel(4, 0).0, [0, 0, 0], "unknown is black");
        assert_eq!(d.get_pixel(0, 4).0[2], 255, "far is blue");
    }
}
