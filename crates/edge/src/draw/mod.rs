//! Drawing on images for people: text in the bundled font with a dark outline (readable on dark and
//! bright water alike), a bright track palette, greedy placement of labels so they do not overlap,
//! and a colour scale. Used by the snapshots (`record::snapshot`) and the calibration overlay
//! (`fme calibrate --overlay`); the plots (`fme report`, `fme eval --plot`) register the same font
//! with plotters. docs/recording.md "What the pictures show".

pub mod place;
pub mod text;

pub use place::{Placer, Rect};
pub use text::{FONT, draw_text, fill_rect, text_size};

use image::{Rgb, RgbImage};
use std::sync::Once;

static REGISTER_PLOT_FONT: Once = Once::new();

/// Registers the bundled font ([`FONT`]) as plotters' `sans-serif` (once per process; every plot fme
/// draws uses it).
pub fn register_plot_font() {
    REGISTER_PLOT_FONT.call_once(|| {
        // A bundled valid TTF; if it were rejected, text would be missing but the plot still drawn.
        let _ = plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT);
    });
}

/// Bright, mutually distinct colours for tracks: each is drawn with a dark outline, so none may be
/// dark itself (a dark colour vanishes on dark water).
pub const PALETTE: [[u8; 3]; 12] = [
    [255, 80, 80],
    [255, 170, 0],
    [255, 255, 60],
    [110, 255, 60],
    [0, 240, 170],
    [0, 220, 255],
    [110, 160, 255],
    [210, 130, 255],
    [255, 100, 220],
    [255, 255, 255],
    [190, 255, 190],
    [255, 200, 150],
];

/// The palette colour of a track id (consecutive ids get different colours).
pub fn id_colour(id: u32) -> Rgb<u8> {
    Rgb(PALETTE[id as usize % PALETTE.len()])
}

/// The outline drawn around marks and text.
pub const OUTLINE: Rgb<u8> = Rgb([0, 0, 0]);

/// Sets a pixel when it is inside the image.
pub fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u64) < u64::from(img.width()) && (y as u64) < u64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A rectangle's border `thick` px wide in `colour`, with a 1 px dark outline on both sides.
pub fn outlined_rect(img: &mut RgbImage, r: Rect, colour: Rgb<u8>, thick: i64) {
    let ring = |img: &mut RgbImage, k: i64, c: Rgb<u8>| {
        let (x0, y0, x1, y1) = (r.x + k, r.y + k, r.x + r.w - k, r.y + r.h - k);
        if x1 < x0 || y1 < y0 {
            return;
        }
        for x in x0..=x1 {
            put(img, x, y0, c);
            put(img, x, y1, c);
        }
        for y in y0..=y1 {
            put(img, x0, y, c);
            put(img, x1, y, c);
        }
    };
    ring(img, -1, OUTLINE);
    for k in 0..thick {
        ring(img, k, colour);
    }
    ring(img, thick, OUTLINE);
}

/// A `+` of half-length `r` px, 1 px wide in `colour` with a dark outline.
pub fn cross(img: &mut RgbImage, x: i64, y: i64, r: i64, colour: Rgb<u8>) {
    for d in -r - 1..=r + 1 {
        for o in [-1, 1] {
            put(img, x + d, y + o, OUTLINE);
            put(img, x + o, y + d, OUTLINE);
        }
    }
    for d in -r..=r {
        put(img, x + d, y, colour);
        put(img, x, y + d, colour);
    }
}

/// The depth colour of `q` in 0..=1: near (0) red, middle green, far (1) blue.
pub fn depth_colour(q: f32) -> Rgb<u8> {
    let q = q.clamp(0.0, 1.0);
    let r = (255.0 * (1.0 - 2.0 * q).clamp(0.0, 1.0)) as u8;
    let g = (255.0 * (1.0 - (2.0 * q - 1.0).abs())) as u8;
    let b = (255.0 * (2.0 * q - 1.0).clamp(0.0, 1.0)) as u8;
    Rgb([r, g, b])
}
