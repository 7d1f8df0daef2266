//! The frame: one timestamped image as the camera delivered it, still encoded, and its decoding.
//! Capture produces frames; the pipeline decodes only the frames a network runs on.

use crate::units::Seconds;

/// How the bytes of a [`Frame`] are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// A JPEG image (recorded `img1/*.jpg` or MJPEG camera frames).
    Jpeg,
    /// Packed YUYV 4:2:2, `width * height * 2` bytes.
    Yuyv,
    /// 8-bit grey, `width * height` bytes.
    Gray8,
    /// Planar YUV 4:2:0 (I420: the Y plane, then U and V at half width and height, rounded up), as
    /// an H.264 decoder gives it: kept planar so only the frames the networks run on are converted.
    I420,
}

/// Bytes of an I420 frame of `w` x `h` px (chroma planes rounded up for odd sizes).
pub fn i420_len(w: usize, h: usize) -> usize {
    w * h + 2 * w.div_ceil(2) * h.div_ceil(2)
}

/// One captured frame. The bytes stay encoded: decoding is the pipeline's job, so capture never
/// waits on CPU work.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Sequence number from the source (monotonic, never reset by a loop or reconnect).
    pub seq: u64,
    /// Capture time (kernel timestamp for V4L2; frame index / fps for recordings).
    pub timestamp: Seconds,
    /// When the frame reached user space (start of the frame-to-register latency).
    pub arrived: std::time::Instant,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Encoding of `data`.
    pub format: PixelFormat,
    /// The bytes, cut to the valid length (V4L2 `bytesused`).
    pub data: Vec<u8>,
}

impl Frame {
    /// Decodes to 8-bit grey (YUYV: the Y samples; JPEG: decoded then converted).
    pub fn to_luma(&self) -> Result<image::GrayImage, String> {
        let (w, h) = (self.width as usize, self.height as usize);
        match self.format {
            PixelFormat::Jpeg => image::load_from_memory_with_format(&self.data, image::ImageFormat::Jpeg)
                .map(|i| i.to_luma8())
                .map_err(|e| e.to_string()),
            PixelFormat::Yuyv => {
                if self.data.len() < w * h * 2 {
                    return Err(format!("YUYV frame has {} bytes, expected {}", self.data.len(), w * h * 2));
                }
                let y: Vec<u8> = self.data.iter().step_by(2).take(w * h).copied().collect();
                image::GrayImage::from_raw(self.width, self.height, y).ok_or_else(|| "bad YUYV size".to_string())
            }
            PixelFormat::Gray8 => image::GrayImage::from_raw(self.width, self.height, self.data.clone())
                .ok_or_else(|| format!("grey frame has {} bytes, expected {}", self.data.len(), w * h)),
            PixelFormat::I420 => {
                if self.data.len() < i420_len(w, h) {
                    return Err(format!("I420 frame has {} bytes, expected {}", self.data.len(), i420_len(w, h)));
                }
                image::GrayImage::from_raw(self.width, self.height, self.data[..w * h].to_vec())
                    .ok_or_else(|| "bad I420 size".to_string())
            }
        }
    }
}

impl Frame {
    /// The image size the bytes say, read from the JPEG header only (nothing is decoded); the
    /// source's size for raw formats.
    pub fn encoded_dimensions(&self) -> Result<(u32, u32), String> {
        match self.format {
            PixelFormat::Jpeg => {
                image::ImageReader::with_format(std::io::Cursor::new(&self.data), image::ImageFormat::Jpeg)
                    .into_dimensions()
                    .map_err(|e| e.to_string())
            }
            PixelFormat::Yuyv | PixelFormat::Gray8 | PixelFormat::I420 => Ok((self.width, self.height)),
        }
    }

    /// A frame larger than `max_pixels` (by its header, before any decoding) is a bad frame: a
    /// 4000x4000 JPEG in an MJPEG stream would otherwise be decoded in full (+50 MB, kept).
    /// `max_pixels = 0`: 4 x the larger of `configured` (width, height) and the source's own size.
    pub fn check_size(&self, max_pixels: u64, configured: (u32, u32)) -> Result<(), String> {
        let limit = if max_pixels > 0 {
            max_pixels
        } else {
            4 * (u64::from(configured.0) * u64::from(configured.1)).max(u64::from(self.width) * u64::from(self.height))
        };
        let (w, h) = self.encoded_dimensions()?;
        let n = u64::from(w) * u64::from(h);
        if n > limit {
            return Err(format!("frame {}: {w}x{h} px is more than source.max_pixels ({limit} px)", self.seq));
        }
        Ok(())
    }

    /// Decodes to packed RGB8 into `out` (resized to `width * height * 3`; reuse it across frames
    /// so the output buffer is not reallocated). JPEG: decoded (grey JPEGs are expanded); YUYV:
    /// BT.601 limited-range conversion; grey: replicated. Returns (width, height).
    pub fn to_rgb_into(&self, out: &mut Vec<u8>) -> Result<(u32, u32), String> {
        use image::ImageDecoder as _;
        let (w, h) = (self.width as usize, self.height as usize);
        match self.format {
            PixelFormat::Jpeg => {
                let dec = image::codecs::jpeg::JpegDecoder::new(std::io::Cursor::new(&self.data))
                    .map_err(|e| e.to_string())?;
                let (dw, dh) = dec.dimensions();
                let n = dw as usize * dh as usize;
                match dec.color_type() {
                    image::ColorType::Rgb8 => {
                        out.resize(n * 3, 0);
                        dec.read_image(out).map_err(|e| e.to_string())?;
                    }
                    image::ColorType::L8 => {
                        out.resize(n * 3, 0);
                        dec.read_image(&mut out[..n]).map_err(|e| e.to_string())?;
                        // Expand in place from the back so no source byte is overwritten before use.
                        for i in (0..n).rev() {
                            let g = out[i];
                            out[3 * i..3 * i + 3].fill(g);
                        }
                    }
                    other => return Err(format!("unsupported JPEG colour type {other:?}")),
                }
                Ok((dw, dh))
            }
            PixelFormat::Yuyv => {
                if self.data.len() < w * h * 2 || w % 2 != 0 {
                    return Err(format!("YUYV frame has {} bytes for {w}x{h}", self.data.len()));
                }
                out.resize(w * h * 3, 0);
                for (px, o) in self.data[..w * h * 2].chunks_exact(4).zip(out.chunks_exact_mut(6)) {
                    let (u, v) = (f32::from(px[1]) - 128.0, f32::from(px[3]) - 128.0);
                    for (k, y) in [px[0], px[2]].into_iter().enumerate() {
                        let c = 1.164 * (f32::from(y) - 16.0);
                        let rgb = [c + 1.596 * v, c - 0.392 * u - 0.813 * v, c + 2.017 * u];
                        for (j, x) in rgb.into_iter().enumerate() {
                            o[3 * k + j] = x.round().clamp(0.0, 255.0) as u8;
                        }
                    }
                }
                Ok((self.width, self.height))
            }
            PixelFormat::Gray8 => {
                if self.data.len() < w * h {
                    return Err(format!("grey frame has {} bytes for {w}x{h}", self.data.len()));
                }
                out.resize(w * h * 3, 0);
                for (g, o) in self.data[..w * h].iter().zip(out.chunks_exact_mut(3)) {
                    o.fill(*g);
                }
                Ok((self.width, self.height))
            }
            PixelFormat::I420 => {
                i420_to_rgb(&self.data, w, h, out)?;
                Ok((self.width, self.height))
            }
        }
    }
}

/// BT.601 limited-range I420 to packed RGB8 (the same conversion as YUYV's), into `out`.
fn i420_to_rgb(data: &[u8], w: usize, h: usize, out: &mut Vec<u8>) -> Result<(), String> {
    if data.len() < i420_len(w, h) {
        return Err(format!("I420 frame has {} bytes for {w}x{h}", data.len()));
    }
    let cw = w.div_ceil(2);
    let (y_plane, chroma) = data.split_at(w * h);
    let (u_plane, v_plane) = chroma.split_at(cw * h.div_ceil(2));
    out.resize(w * h * 3, 0);
    for (row, o_row) in out.chunks_exact_mut(w * 3).enumerate() {
        let (ys, us, vs) = (&y_plane[row * w..][..w], &u_plane[row / 2 * cw..][..cw], &v_plane[row / 2 * cw..][..cw]);
        for (x, o) in o_row.chunks_exact_mut(3).enumerate() {
            let (u, v) = (f32::from(us[x / 2]) - 128.0, f32::from(vs[x / 2]) - 128.0);
            let c = 1.164 * (f32::from(ys[x]) - 16.0);
            let rgb = [c + 1.596 * v, c - 0.392 * u - 0.813 * v, c + 2.017 * u];
            for (j, x) in rgb.into_iter().enumerate() {
                o[j] = x.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(format: PixelFormat, width: u32, height: u32, data: Vec<u8>) -> Frame {
        Frame { seq: 0, timestamp: Seconds(0.0), arrived: std::time::Instant::now(), width, height, format, data }
    }

    #[test]
    fn rgb_from_yuyv_gray_and_jpeg() {
        let mut out = Vec::new();
        // Y=235 U=V=128 is white, Y=16 is black (limited range).
        let f = frame(PixelFormat::Yuyv, 2, 1, vec![235, 128, 16, 128]);
        assert_eq!(f.to_rgb_into(&mut out), Ok((2, 1)));
        assert_eq!(out, vec![255, 255, 255, 0, 0, 0]);
        // Pure red in BT.601 limited range: Y=81 U=90 V=240.
        let f = frame(PixelFormat::Yuyv, 2, 1, vec![81, 90, 81, 240]);
        assert!(f.to_rgb_into(&mut out).is_ok());
        assert!(out[0] > 250 && out[1] < 5 && out[2] < 5, "{out:?}");
        assert!(frame(PixelFormat::Yuyv, 3, 1, vec![0; 6]).to_rgb_into(&mut out).is_err(), "odd width");
        let f = frame(PixelFormat::Gray8, 2, 1, vec![7, 9]);
        assert_eq!(f.to_rgb_into(&mut out), Ok((2, 1)));
        assert_eq!(out, vec![7, 7, 7, 9, 9, 9]);
        for color in [true, false] {
            let mut jpg = Vec::new();
            let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 95);
            let img: image::DynamicImage = if color {
                image::RgbImage::from_pixel(8, 4, image::Rgb([200, 40, 40])).into()
            } else {
                image::GrayImage::from_pixel(8, 4, image::Luma([90])).into()
            };
            img.write_with_encoder(enc).expect("encode");
            let f = frame(PixelFormat::Jpeg, 8, 4, jpg);
            assert_eq!(f.to_rgb_into(&mut out), Ok((8, 4)));
            assert_eq!(out.len(), 8 * 4 * 3);
            let want = if color { [200, 40, 40] } else { [90, 90, 90] };
            assert!(out.chunks(3).all(|p| p.iter().zip(want).all(|(a, b)| a.abs_diff(b) <= 6)), "{:?}", &out[..6]);
        }
        assert!(frame(PixelFormat::Jpeg, 8, 4, vec![0xFF, 0xD8, 0x00]).to_rgb_into(&mut out).is_err());
    }

    #[test]
    fn i420_gives_rgb_and_luma() {
        // 2x2 white-ish luma over pure red chroma (BT.601 limited: Y=81 U=90 V=240), and a 3x1 frame
        // (odd width: chroma rounded up).
        let f = frame(PixelFormat::I420, 2, 2, vec![81, 81, 81, 81, 90, 240]);
        let mut out = Vec::new();
        assert_eq!(f.to_rgb_into(&mut out), Ok((2, 2)));
        assert!(out.chunks(3).all(|p| p[0] > 250 && p[1] < 5 && p[2] < 5), "{out:?}");
        assert_eq!(f.to_luma().map(|i| i.into_raw()), Ok(vec![81; 4]));
        let odd = frame(PixelFormat::I420, 3, 1, vec![235, 16, 235, 128, 128, 128, 128]);
        assert_eq!(odd.to_rgb_into(&mut out), Ok((3, 1)));
        assert_eq!(out, vec![255, 255, 255, 0, 0, 0, 255, 255, 255]);
        assert!(frame(PixelFormat::I420, 2, 2, vec![0; 5]).to_rgb_into(&mut out).is_err(), "short");
        assert!(frame(PixelFormat::I420, 2, 2, vec![0; 5]).to_luma().is_err(), "short");
    }

    #[test]
    fn yuyv_to_luma_takes_y_samples() {
        let f = Frame {
            seq: 0,
            timestamp: Seconds(0.0),
            arrived: std::time::Instant::now(),
            width: 2,
            height: 1,
            format: PixelFormat::Yuyv,
            data: vec![10, 128, 20, 128],
        };
        assert_eq!(f.to_luma().map(|i| i.into_raw()), Ok(vec![10, 20]));
        let short = Frame { data: vec![1, 2], ..f };
        assert!(short.to_luma().is_err());
    }

    #[test]
    fn oversized_frames_are_found_from_the_header() {
        let mut jpg = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 80);
        let img: image::DynamicImage = image::GrayImage::from_pixel(64, 48, image::Luma([90])).into();
        img.write_with_encoder(enc).expect("encode");
        // The source says 8x4 (a rogue frame in its stream is 64x48): more than 4 x 32 px.
        let f = frame(PixelFormat::Jpeg, 8, 4, jpg.clone());
        assert_eq!(f.encoded_dimensions(), Ok((64, 48)));
        let e = f.check_size(0, (8, 4)).expect_err("too large");
        assert!(e.contains("64x48") && e.contains("source.max_pixels"), "{e}");
        assert!(f.check_size(0, (32, 24)).is_ok(), "4 x the configured size");
        assert!(f.check_size(64 * 48, (8, 4)).is_ok(), "an explicit limit");
        assert!(f.check_size(64 * 48 - 1, (8, 4)).is_err());
        let native = frame(PixelFormat::Jpeg, 64, 48, jpg);
        assert!(native.check_size(0, (8, 4)).is_ok(), "the source's own size counts");
        assert!(frame(PixelFormat::Jpeg, 8, 4, vec![0xFF, 0xD8]).check_size(0, (8, 4)).is_err(), "no header");
    }
}
