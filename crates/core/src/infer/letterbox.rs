//! Ultralytics letterboxing: scale the frame to fit the network input keeping its aspect ratio,
//! centre it, and pad with grey 114. Boxes from the network map back to frame pixels with the
//! inverse transform.

use crate::geometry::PixelBox;

/// Padding value of Ultralytics' `LetterBox` (before the /255 scaling).
pub const PAD_VALUE: u8 = 114;

/// The transform between frame pixels and letterboxed network-input pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Letterbox {
    /// Frame width and height, pixels.
    pub src: (u32, u32),
    /// Network input width and height, pixels.
    pub dst: (u32, u32),
    /// Scale factor frame -> input, `min(W/w, H/h)` (upscaling allowed, as Ultralytics).
    pub gain: f64,
    /// Size of the scaled image inside the input, pixels (`round(w * gain)`, `round(h * gain)`).
    pub inner: (u32, u32),
    /// Left and top padding, pixels.
    pub pad: (u32, u32),
}

impl Letterbox {
    /// The letterbox of a `src` frame into a `dst` network input, computed as
    /// `ultralytics.data.augment.LetterBox` (centre, `round(d - 0.1)` on the top/left pad).
    pub fn new(src: (u32, u32), dst: (u32, u32)) -> Self {
        let gain = (dst.0 as f64 / src.0 as f64).min(dst.1 as f64 / src.1 as f64);
        let inner = (
            ((src.0 as f64 * gain).round() as u32).clamp(1, dst.0),
            ((src.1 as f64 * gain).round() as u32).clamp(1, dst.1),
        );
        let dw = (dst.0 - inner.0) as f64 / 2.0;
        let dh = (dst.1 - inner.1) as f64 / 2.0;
        let pad = ((dw - 0.1).round().max(0.0) as u32, (dh - 0.1).round().max(0.0) as u32);
        Self { src, dst, gain, inner, pad }
    }

    /// Maps a box in network-input pixels (centre x, centre y, width, height, as YOLO outputs) to a
    /// frame box, clipped to the frame. Same as Ultralytics' `scale_boxes` (which clips).
    pub fn to_frame(&self, cx: f32, cy: f32, w: f32, h: f32) -> PixelBox {
        self.clip(&self.to_frame_unclipped(cx, cy, w, h))
    }

    /// As [`Self::to_frame`] without clipping: a uniform scale and shift, so IoUs are unchanged
    /// (NMS runs on these, as Ultralytics runs NMS before `scale_boxes`).
    pub fn to_frame_unclipped(&self, cx: f32, cy: f32, w: f32, h: f32) -> PixelBox {
        let (cx, cy, w, h) = (cx as f64, cy as f64, w as f64, h as f64);
        let x0 = (cx - w * 0.5 - self.pad.0 as f64) / self.gain;
        let y0 = (cy - h * 0.5 - self.pad.1 as f64) / self.gain;
        PixelBox::new(x0, y0, w / self.gain, h / self.gain)
    }

    /// Clips a frame box to the frame.
    pub fn clip(&self, b: &PixelBox) -> PixelBox {
        let (sw, sh) = (self.src.0 as f64, self.src.1 as f64);
        let x0 = b.x.clamp(0.0, sw);
        let y0 = b.y.clamp(0.0, sh);
        let x1 = b.right().clamp(0.0, sw);
        let y1 = b.bottom().clamp(0.0, sh);
        PixelBox::new(x0, y0, x1 - x0, y1 - y0)
    }

    /// Maps a frame box to network-input pixels `(cx, cy, w, h)` (the forward transform; used for
    /// round-trip checks and for drawing).
    pub fn to_input(&self, b: &PixelBox) -> (f32, f32, f32, f32) {
        let c = b.center();
        (
            (c.u * self.gain + self.pad.0 as f64) as f32,
            (c.v * self.gain + self.pad.1 as f64) as f32,
            (b.w * self.gain) as f32,
            (b.h * self.gain) as f32,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_ultralytics_for_wide_frame() {
        // 1280x720 into 640x640: gain 0.5, inner 640x360, pad top (280/2 - 0.1).round() = 140.
        let lb = Letterbox::new((1280, 720), (640, 640));
        assert_eq!(lb.gain, 0.5);
        assert_eq!(lb.inner, (640, 360));
        assert_eq!(lb.pad, (0, 140));
        // Odd padding rounds the top/left down: 640x481 -> inner 640x481, dh = 79.5 -> 79.
        let lb = Letterbox::new((640, 481), (640, 640));
        assert_eq!(lb.pad, (0, 79));
    }

    #[test]
    fn upscales_small_frames() {
        let lb = Letterbox::new((160, 120), (320, 320));
        assert_eq!(lb.gain, 2.0);
        assert_eq!(lb.inner, (320, 240));
        assert_eq!(lb.pad, (0, 40));
    }
}
