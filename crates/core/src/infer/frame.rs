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

    /// `/255`, mean and std folded into one multiply-add per channel on a byte-scale value:
    /// `(mul, add)` with `x_norm = v * mul[c] + add[c]`.
    fn per_byte(&self) -> ([f32; 3], [f32; 3]) {
        (core::array::from_fn(|c| 1.0 / (255.0 * self.std[c])), core::array::from_fn(|c| -self.mean[c] / self.std[c]))
    }
}

/// The bilinear resampler of one network input: the axis tables for the current frame size and two
/// rows of horizontally resampled source pixels, all reused from frame to frame.
///
/// Separable: each source row an output row needs is resampled horizontally once, into one of the
/// two row buffers, and kept while the next output row needs it too (when shrinking 384 -> 288
/// rows, 4 output rows use 5 source rows instead of 8). The row buffers are planar (R, G, B runs),
/// so the vertical blend and normalisation are three plain loops over slices that the compiler
/// vectorises. The arithmetic is the direct bilinear form's, operation for operation, so the
/// output is bit-identical to it (tested against it below).
#[derive(Debug, Clone, Default)]
pub(crate) struct Resampler {
    xs: AxisMap,
    ys: AxisMap,
    rows: [Vec<f32>; 2],
    /// The source row being resampled, as floats.
    src_row: Vec<f32>,
    /// Source row held in each buffer during one call (`u32::MAX`: none).
    held: [u32; 2],
}

impl Resampler {
    /// Rebuilds the tables for a `src` frame resampled to a `dst` rectangle (both `(width, height)`).
    pub(crate) fn build(&mut self, src: (u32, u32), dst: (u32, u32)) {
        self.xs.build(src.0, dst.0);
        self.ys.build(src.1, dst.1);
    }

    /// Bilinearly resamples `frame` into the rectangle `[left, left + dst width) x [top, top + dst
    /// height)` of a planar `[3, net_h, net_w]` float buffer, normalised with `norm`. Pixels outside
    /// the rectangle are left untouched (the caller fills padding once). [`Self::build`] must have
    /// been called for this frame size.
    #[allow(clippy::too_many_arguments)] // a hot loop's geometry; a struct would only rename these
    pub(crate) fn run(
        &mut self,
        frame: &RgbFrame<'_>,
        left: usize,
        top: usize,
        net_w: usize,
        net_h: usize,
        norm: &Normalize,
        out: &mut [f32],
    ) {
        let plane = net_w * net_h;
        let n = self.xs.i0.len();
        debug_assert!(top + self.ys.i0.len() <= net_h && left + n <= net_w);
        let (mul, add) = norm.per_byte();
        let (p0, rest) = out.split_at_mut(plane);
        let (p1, p2) = rest.split_at_mut(plane);
        self.held = [u32::MAX; 2]; // a new frame: nothing held is valid
        for dy in 0..self.ys.i0.len() {
            let (y0, y1, wy) = (self.ys.i0[dy], self.ys.i1[dy], self.ys.w1[dy]);
            let (b0, b1) = self.hold_pair(frame, y0, y1);
            let (h0, h1) = (&self.rows[b0], &self.rows[b1]);
            let row = (top + dy) * net_w + left;
            let planes = [&mut p0[row..row + n], &mut p1[row..row + n], &mut p2[row..row + n]];
            for (c, o) in planes.into_iter().enumerate() {
                let (t, b) = (&h0[c * n..][..n], &h1[c * n..][..n]);
                for ((o, &t), &b) in o.iter_mut().zip(t).zip(b) {
                    *o = (t + (b - t) * wy) * mul[c] + add[c];
                }
            }
        }
    }

    /// The buffers holding source rows `y0` and `y1` (the same one when equal), resampling only
    /// the rows not already held.
    fn hold_pair(&mut self, frame: &RgbFrame<'_>, y0: u32, y1: u32) -> (usize, usize) {
        let find = |held: &[u32; 2], y: u32| held.iter().position(|&h| h == y);
        match (find(&self.held, y0), find(&self.held, y1)) {
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => (a, self.fill(1 - a, frame, y1)),
            (None, Some(b)) => (self.fill(1 - b, frame, y0), b),
            (None, None) => {
                let a = self.fill(0, frame, y0);
                (a, if y1 == y0 { a } else { self.fill(1, frame, y1) })
            }
        }
    }

    /// Resamples source row `y` horizontally into buffer `slot` (planar: n R values, n G, n B).
    /// The row is converted to floats once first (each source byte feeds about 1.5 taps when
    /// shrinking 640 -> 480, and the conversion is a plain loop the compiler vectorises).
    fn fill(&mut self, slot: usize, frame: &RgbFrame<'_>, y: u32) -> usize {
        let stride = frame.width as usize * 3;
        let src = &frame.data[y as usize * stride..][..stride];
        self.src_row.resize(stride, 0.0); // allocates on the first frame of a size only
        for (d, &s) in self.src_row.iter_mut().zip(src) {
            *d = s as f32;
        }
        let src = &self.src_row[..];
        let n = self.xs.i0.len();
        let buf = &mut self.rows[slot];
        buf.resize(n * 3, 0.0);
        let (r, rest) = buf.split_at_mut(n);
        let (g, b) = rest.split_at_mut(n);
        let taps = self.xs.i0.iter().zip(&self.xs.i1).zip(&self.xs.w1);
        for ((((&x0, &x1), &wx), r), (g, b)) in taps.zip(r).zip(g.iter_mut().zip(b)) {
            let (p, q) = (&src[x0 as usize * 3..][..3], &src[x1 as usize * 3..][..3]);
            *r = p[0] + (q[0] - p[0]) * wx;
            *g = p[1] + (q[1] - p[1]) * wx;
            *b = p[2] + (q[2] - p[2]) * wx;
        }
        self.held[slot] = y;
        slot
    }
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
        let mut r = Resampler::default();
        r.build((2, 1), (2, 1));
        let mut out = vec![9.0f32; 3 * 2];
        r.run(&f, 0, 0, 2, 1, &Normalize::UNIT, &mut out);
        let want = [1.0, 1.0, 0.0, 0.0, 0.2, 0.2];
        assert!(out.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-6), "{out:?}");
    }

    /// The direct bilinear form the separable [`Resampler`] must reproduce bit for bit, on the
    /// resampler's own tables; `at` is the rectangle's `(left, top)` in a `net_w`-wide buffer.
    fn reference(
        r: &Resampler,
        frame: &RgbFrame<'_>,
        at: (usize, usize),
        net_w: usize,
        norm: &Normalize,
        out: &mut [f32],
    ) {
        let ((left, top), (xs, ys)) = (at, (&r.xs, &r.ys));
        let plane = out.len() / 3;
        let stride = frame.width as usize * 3;
        let data = frame.data;
        let (mul, add) = norm.per_byte();
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
        assert!(top + ys.i0.len() <= plane / net_w);
    }

    /// Pseudo-random bytes (xorshift), so the test needs no crate.
    fn noise(n: usize, seed: u64) -> Vec<u8> {
        let mut x = seed | 1;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 24) as u8
            })
            .collect()
    }

    #[test]
    fn separable_resampler_is_bit_identical_to_the_direct_form() {
        // (source, destination rectangle, offset in a net) for shrinking (the cameras' case),
        // enlarging, equal size, odd ratios, and the letterbox offsets.
        let cases = [
            ((640, 384), (480, 288), (0, 0), (480, 288)),
            ((640, 480), (384, 288), (48, 0), (480, 288)),
            ((1920, 1080), (480, 270), (0, 9), (480, 288)),
            ((64, 40), (480, 300), (0, 0), (480, 300)),
            ((97, 53), (97, 53), (0, 0), (97, 53)),
            ((33, 71), (50, 17), (3, 2), (60, 20)),
            ((1, 1), (5, 3), (0, 0), (5, 3)),
        ];
        let mut r = Resampler::default();
        for (k, &(src, dst, (left, top), (nw, nh))) in cases.iter().enumerate() {
            r.build(src, dst);
            // Two frames per size through the same resampler: rows held from the first frame must
            // not leak into the second.
            for seed in [k as u64 + 1, k as u64 + 100] {
                let data = noise(src.0 as usize * src.1 as usize * 3, seed);
                let f = RgbFrame::new(src.0, src.1, &data).unwrap();
                for norm in [Normalize::UNIT, Normalize::IMAGENET] {
                    let mut want = vec![-7.0f32; 3 * nw * nh];
                    let mut got = want.clone();
                    reference(&r, &f, (left, top), nw, &norm, &mut want);
                    r.run(&f, left, top, nw, nh, &norm, &mut got);
                    let same = want.iter().zip(&got).all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "case {k} seed {seed}: separable output differs from the direct form");
                }
            }
        }
    }
}
