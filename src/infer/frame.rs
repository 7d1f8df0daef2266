//! A borrowed packed-RGB8 frame, the input of both networks, and the bilinear resampler that fills
//! a network's planar float input without allocating per frame.

use super::InferError;

/// A packed RGB8 image (row-major, 3 bytes per pixel, no row padding) borrowed from the capture.
#[derive(Debug, Clone, Copy)]
pub struct RgbFrame<'a> {
    width: u32,
    height: u32,
    data: &'a [u8],
}

impl<'a> RgbFrame<'a> {
    /// Wraps a buffer, checking that its length is `width * height * 3`.
    pub fn new(width: u32, height: u32, data: &'a [u8]) -> Result<Self, InferError> {
        let expected = width as usize * height as usize * 3;
        if width == 0 || height == 0 || data.len() != expected {
            return Err(InferError::BadFrame { width, height, len: data.len(), expected });
        }
        Ok(Self { width, height, data })
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// The packed RGB bytes.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
}

impl<'a> From<&'a image::RgbImage> for RgbFrame<'a> {
    fn from(img: &'a image::RgbImage) -> Self {
        Self { width: img.width(), height: img.height(), data: img.as_raw() }
    }
}

/// One axis of a bilinear resize: for each destination index, the two source indices and the
/// weight of the second. Half-pixel centres, as OpenCV's `INTER_LINEAR` (what Ultralytics and
/// MiDaS preprocessing use).
#[derive(Debug, Clone, Default)]
pub(crate) struct AxisMap {
    pub(crate) i0: Vec<u32>,
    pub(crate) i1: Vec<u32>,
    pub(crate) w1: Vec<f32>,
}

impl AxisMap {
    /// Rebuilds the table for `src` -> `dst` samples; reuses the vectors' capacity.
    pub(crate) fn build(&mut self, src: u32, dst: u32) {
        self.i0.clear();
        self.i1.clear();
        self.w1.clear();
        let scale = src as f64 / dst as f64;
        let last = src.saturating_sub(1) as f64;
        for d in 0..dst {
            let s = ((d as f64 + 0.5) * scale - 0.5).clamp(0.0, last);
            let f = s.floor();
            let i0 = f as u32;
            let i1 = (i0 + 1).min(src - 1);
            self.i0.push(i0);
            self.i1.push(i1);
            self.w1.push((s - f) as f32);
        }
    }
}

/// Per-channel affine normalisation applied to `byte / 255`: `(x - mean) / std`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalize {
    /// Channel means (R, G, B) in 0..1 units.
    pub mean: [f32; 3],
    /// Channel standard deviations (R, G, B) in 0..1 units.
    pub std: [f32; 3],
}

impl Normalize {
    /// Plain `byte / 255` (Ultralytics detectors).
    pub const UNIT: Normalize = Normalize { mean: [0.0; 3], std: [1.0; 3] };
    /// ImageNet statistics (Depth Anything V2, self-exported MiDaS).
    pub const IMAGENET: Normalize = Normalize { mean: [0.485, 0.456, 0.406], std: [0.229, 0.224, 0.225] };
}

/// Bilinearly resamples `frame` into the rectangle `[left, left+xs.len()) x [top, top+ys.len())` of
/// a planar `[3, net_h, net_w]` float buffer, normalised with `norm`. Pixels outside the rectangle
/// are left untouched (the caller fills padding once).
#[allow(clippy::too_many_arguments)] // a hot inner loop; a struct would only rename these
pub(crate) fn resample_into(
    frame: &RgbFrame<'_>,
    xs: &AxisMap,
    ys: &AxisMap,
    left: usize,
    top: usize,
    net_w: usize,
    net_h: usize,
    norm: &Normalize,
    out: &mut [f32],
) {
    let plane = net_w * net_h;
    let stride = frame.width as usize * 3;
    let data = frame.data;
    // Fold /255, mean and std into one multiply-add per channel.
    let mul: [f32; 3] = core::array::from_fn(|c| 1.0 / (255.0 * norm.std[c]));
    let add: [f32; 3] = core::array::from_fn(|c| -norm.mean[c] / norm.std[c]);
    for (dy, ((&y0, &y1), &wy)) in ys.i0.iter().zip(&ys.i1).zip(&ys.w1).enumerate() {
        let r0 = &data[y0 as usize * stride..][..stride];
        let r1 = &data[y1 as usize * stride..][..stride];
        let row = (top + dy) * net_w + left;
        for (dx, ((&x0, &x1), &wx)) in xs.i0.iter().zip(&xs.i1).zip(&xs.w1).enumerate() {
            let (a, b) = (x0 as usize * 3, x1 as usize * 3);
            for c in 0..3 {
                let top_v = r0[a + c] as f32 + (r0[b + c] as f32 - r0[a + c] as f32) * wx;
                let bot_v = r1[a + c] as f32 + (r1[b + c] as f32 - r1[a + c] as f32) * wx;
                let v = top_v + (bot_v - top_v) * wy;
                out[c * plane + row + dx] = v * mul[c] + add[c];
            }
        }
    }
    debug_assert!(top + ys.i0.len() <= net_h);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_rejects_wrong_length() {
        let buf = [0u8; 10];
        let e = RgbFrame::new(2, 2, &buf).unwrap_err().to_string();
        assert!(e.contains("2x2") && e.contains("10 bytes") && e.contains("12"), "{e}");
    }

    #[test]
    fn axis_map_identity_and_downscale() {
        let mut m = AxisMap::default();
        m.build(4, 4);
        assert_eq!(m.i0, vec![0, 1, 2, 3]);
        assert!(m.w1.iter().all(|w| *w == 0.0));
        m.build(4, 2); // centres at 0.5 and 2.5
        assert_eq!(m.i0, vec![0, 2]);
        assert_eq!(m.w1, vec![0.5, 0.5]);
    }

    #[test]
    fn resample_normalises() {
        let data = [255u8, 0, 51, 255, 0, 51];
        let f = RgbFrame::new(2, 1, &data).unwrap();
        let (mut xs, mut ys) = (AxisMap::default(), AxisMap::default());
        xs.build(2, 2);
        ys.build(1, 1);
        let mut out = vec![9.0f32; 3 * 2];
        resample_into(&f, &xs, &ys, 0, 0, 2, 1, &Normalize::UNIT, &mut out);
        let want = [1.0, 1.0, 0.0, 0.0, 0.2, 0.2];
        assert!(out.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-6), "{out:?}");
    }
}
