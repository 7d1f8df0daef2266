//! The overlay PNG of `fme calibrate`: the marked and reprojected references, the world axes and
//! origin, drawn on the frame the references were marked on.

use super::usage;
use crate::calib::{Reference, Residual};
use crate::draw::{self, Placer, Rect};
use crate::geometry::{Camera, Pixel, WorldPoint};
use image::Rgb;
use std::path::Path;

/// The overlay PNG: marked references (green crosses) with their name and error, reprojected (red
/// circles) joined by a yellow line, the world axes, 1 m each (x red, y green, z blue, labelled),
/// from the origin and from the references' centroid, the origin itself (or an arrow at the edge
/// towards it), and a legend.
pub(super) fn overlay(
    img: image::RgbImage,
    cam: &Camera,
    refs: &[Reference],
    res: &[Residual],
    path: &Path,
) -> anyhow::Result<()> {
    let mut o = Overlay::new(img);
    let legend = o.legend(refs, res);
    o.axes(cam, refs);
    o.references(refs, res);
    o.origin(cam);
    o.finish(&legend, path)
}

/// A line of the legend and its colour.
type LegendLine = (String, [u8; 3]);

/// The legend's lines and the box they are drawn in (top left).
struct Legend {
    lines: [LegendLine; 4],
    rect: Rect,
}

/// The image being drawn on and the labels placed so far (drawn last, over everything else).
struct Overlay {
    img: image::RgbImage,
    /// Text size, pixels.
    px: f32,
    /// Height of a line of text, pixels.
    lh: i64,
    placer: Placer,
    labels: Vec<(Rect, String, [u8; 3])>,
}

impl Overlay {
    fn new(img: image::RgbImage) -> Self {
        let (w, h) = img.dimensions();
        let px = (h as f32 / 36.0).clamp(11.0, 24.0);
        let placer = Placer::new(Rect::new(0, 0, i64::from(w), i64::from(h)));
        let (_, lh) = draw::text_size("0", px);
        Self { img, px, lh, placer, labels: Vec::new() }
    }

    /// The legend's text, its box kept free of labels.
    fn legend(&mut self, refs: &[Reference], res: &[Residual]) -> Legend {
        let rms = (res.iter().map(|r| r.error_px * r.error_px).sum::<f64>() / res.len().max(1) as f64).sqrt();
        let lines = [
            ("+ marked reference: name, reprojection error".to_string(), [0, 255, 0]),
            ("o where the calibration puts it (yellow: the error)".to_string(), [255, 80, 80]),
            ("axes 1 m: x red, y green, z blue".to_string(), [255, 255, 255]),
            (format!("RMS error {rms:.2} px over {} references", refs.len()), [255, 255, 255]),
        ];
        let lw = lines.iter().map(|(t, _)| draw::text_size(t, self.px).0).max().unwrap_or(0);
        let rect = Rect::new(0, 0, lw + 10, lines.len() as i64 * (self.lh + 2) + 6);
        self.placer.block(rect);
        Legend { lines, rect }
    }

    /// Places a label of `text` at one of the candidate spots around `anchor`, if one is free.
    fn label(&mut self, anchor: Rect, text: String, gap: i64, avoid: &[Rect], colour: [u8; 3]) {
        let (tw, th) = draw::text_size(&text, self.px);
        if let Some(r) = self.placer.place(&draw::place::candidates(anchor, tw, th, gap), avoid) {
            self.labels.push((r, text, colour));
        }
    }

    /// The axes from the world origin, and (the origin is often outside the view, at a cage corner)
    /// from the references' centroid.
    fn axes(&mut self, cam: &Camera, refs: &[Reference]) {
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
                        thick_line(&mut self.img, a, b, colour);
                    }
                    prev = px;
                    end = px.or(end);
                }
                if let Some(e) = end {
                    let anchor = Rect::new(e.u as i64 - 3, e.v as i64 - 3, 7, 7);
                    self.label(anchor, format!("{name} 1m"), 2, &[], colour);
                }
            }
        }
    }

    /// Each reference: its reprojection (a red circle, joined by a yellow line), its mark (a green
    /// cross) and a label with its name and error.
    fn references(&mut self, refs: &[Reference], res: &[Residual]) {
        for (r, e) in refs.iter().zip(res) {
            let m = r.pixel;
            if let Some(p) = e.projected {
                line(&mut self.img, m, p, [255, 255, 0]);
                for k in 0..48 {
                    let a = f64::from(k) * std::f64::consts::TAU / 48.0;
                    for (rad, c) in [(6.0, [0, 0, 0]), (5.0, [255, 0, 0]), (4.0, [0, 0, 0])] {
                        let (x, y) = ((p.u + rad * a.cos()).floor() as i64, (p.v + rad * a.sin()).floor() as i64);
                        put(&mut self.img, x, y, c);
                    }
                }
            }
            draw::cross(&mut self.img, m.u.floor() as i64, m.v.floor() as i64, 6, Rgb([0, 255, 0]));
        }
        let marks: Vec<Rect> =
            refs.iter().map(|r| Rect::new(r.pixel.u as i64 - 7, r.pixel.v as i64 - 7, 15, 15)).collect();
        for ((r, e), m) in refs.iter().zip(res).zip(&marks) {
            let c = if e.error_px > 3.0 { [255, 120, 120] } else { [120, 255, 120] };
            self.label(*m, format!("{} {:.1} px", r.name, e.error_px), 3, &marks, c);
        }
    }

    /// The world origin: a cross where it is in view, else an arrow at the edge towards it.
    fn origin(&mut self, cam: &Camera) {
        let (w, h) = self.img.dimensions();
        match origin_mark(cam, w, h) {
            Some(OriginMark::InView(p)) => {
                draw::cross(&mut self.img, p.u as i64, p.v as i64, 9, Rgb([255, 0, 255]));
                let anchor = Rect::new(p.u as i64 - 9, p.v as i64 - 9, 19, 19);
                self.label(anchor, "origin (0,0,0)".to_string(), 3, &[], [255, 0, 255]);
            }
            Some(OriginMark::Edge { tip, dir, behind }) => self.origin_arrow(tip, dir, behind),
            None => {}
        }
    }

    /// The arrow towards an origin out of view (or behind the camera), and its label.
    fn origin_arrow(&mut self, tip: Pixel, dir: (f64, f64), behind: bool) {
        let (w, h) = self.img.dimensions();
        let len = 40.0;
        let tail = Pixel::new(tip.u - dir.0 * len, tip.v - dir.1 * len);
        thick_line(&mut self.img, tail, tip, [255, 0, 255]);
        for a in [-0.5f64, 0.5] {
            // The arrow head: the backward direction turned by +-0.5 rad.
            let (bx, by) = (-dir.0 * a.cos() + dir.1 * a.sin(), -dir.0 * a.sin() - dir.1 * a.cos());
            thick_line(&mut self.img, tip, Pixel::new(tip.u + bx * 14.0, tip.v + by * 14.0), [255, 0, 255]);
        }
        let text = if behind { "origin (behind the camera)" } else { "origin (out of view)" }.to_string();
        let (tw, th) = draw::text_size(&text, self.px);
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
        if let Some(b) = self.placer.place(&cands, &[]) {
            self.labels.push((b, text, [255, 0, 255]));
        }
    }

    /// Draws the labels and the legend over everything else and writes the PNG.
    fn finish(mut self, legend: &Legend, path: &Path) -> anyhow::Result<()> {
        let (img, px, lh) = (&mut self.img, self.px, self.lh);
        for (b, text, c) in &self.labels {
            draw::draw_text(img, b.x, b.y, text, px, Rgb(*c), Some(draw::OUTLINE));
        }
        draw::fill_rect(img, legend.rect, Rgb([0, 0, 0]), 0.65);
        for (i, (t, c)) in legend.lines.iter().enumerate() {
            draw::draw_text(img, 5, 3 + i as i64 * (lh + 2), t, px, Rgb(*c), None);
        }
        img.save_with_format(path, image::ImageFormat::Png)
            .map_err(|e| usage(format!("--overlay {}: {e}", path.display())))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};

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
