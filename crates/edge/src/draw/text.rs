//! Anti-aliased text in the bundled DejaVu Sans Mono, with an optional dark outline.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use image::{Rgb, RgbImage};
use std::sync::OnceLock;

/// DejaVu Sans Mono (Bitstream Vera licence, `assets/fonts/DejaVuSansMono-LICENSE.txt`): every
/// picture fme draws uses it.
pub static FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSansMono.ttf");

fn font() -> Option<&'static FontRef<'static>> {
    static F: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    // A bundled valid TTF; if it were rejected, text would be missing but the picture still drawn.
    F.get_or_init(|| FontRef::try_from_slice(FONT).ok()).as_ref()
}

/// Width and height in px of `text` at `px` pixels per em (one line).
pub fn text_size(text: &str, px: f32) -> (i64, i64) {
    let Some(f) = font() else { return (0, 0) };
    let s = f.as_scaled(PxScale::from(px));
    let w: f32 = text.chars().map(|c| s.h_advance(f.glyph_id(c))).sum();
    (w.ceil() as i64, (s.ascent() - s.descent()).ceil() as i64)
}

fn blend(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>, a: f32) {
    if x < 0 || y < 0 || x >= i64::from(img.width()) || y >= i64::from(img.height()) || a <= 0.0 {
        return;
    }
    let p = img.get_pixel_mut(x as u32, y as u32);
    for k in 0..3 {
        p.0[k] = (f32::from(p.0[k]) * (1.0 - a) + f32::from(c.0[k]) * a).round() as u8;
    }
}

fn glyphs(img: &mut RgbImage, x: i64, y: i64, text: &str, px: f32, colour: Rgb<u8>) {
    let Some(f) = font() else { return };
    let s = f.as_scaled(PxScale::from(px));
    let mut caret = x as f32;
    for c in text.chars() {
        let id = f.glyph_id(c);
        let g = id.with_scale_and_position(PxScale::from(px), point(caret, y as f32 + s.ascent()));
        if let Some(o) = f.outline_glyph(g) {
            let b = o.px_bounds();
            o.draw(|gx, gy, cov| {
                blend(img, b.min.x as i64 + i64::from(gx), b.min.y as i64 + i64::from(gy), colour, cov.min(1.0))
            });
        }
        caret += s.h_advance(id);
    }
}

/// Draws `text` with its top-left corner at (x, y) in `colour`; with `outline`, first a 1 px halo in
/// that colour so the text reads on any background. Clipped to the image.
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, px: f32, colour: Rgb<u8>, outline: Option<Rgb<u8>>) {
    if let Some(o) = outline {
        for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
            glyphs(img, x + dx, y + dy, text, px, o);
        }
    }
    glyphs(img, x, y, text, px, colour);
}

/// Fills a rectangle with `colour` at opacity `alpha` (0..=1), clipped to the image.
pub fn fill_rect(img: &mut RgbImage, r: super::Rect, colour: Rgb<u8>, alpha: f32) {
    for y in r.y..r.y + r.h {
        for x in r.x..r.x + r.w {
            blend(img, x, y, colour, alpha);
        }
    }
}
