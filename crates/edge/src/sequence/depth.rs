//! Depth maps: 16-bit grey PNG, camera z in millimetres, 0 = no data.

use super::{Error, Result};
use fme_core::units::Metres;
use std::path::Path;

/// A depth map in millimetres of camera z (not ray length), row-major, 0 = no data.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthMap {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height` values, row-major, millimetres.
    pub mm: Vec<u16>,
}

impl DepthMap {
    /// An all-"no data" map.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, mm: vec![0; width as usize * height as usize] }
    }

    /// Depth at integer pixel `(u, v)`, `None` outside the image or where there is no data.
    #[inline]
    pub fn get(&self, u: u32, v: u32) -> Option<Metres> {
        if u >= self.width || v >= self.height {
            return None;
        }
        match self.mm[v as usize * self.width as usize + u as usize] {
            0 => None,
            mm => Some(Metres(f64::from(mm) / 1000.0)),
        }
    }

    /// Converts metres to the stored millimetres (rounded; 0 for no data, saturating at 65.535 m).
    #[inline]
    pub fn encode(depth_m: f64) -> u16 {
        if depth_m.is_finite() && depth_m > 0.0 { (depth_m * 1000.0).round().clamp(1.0, 65535.0) as u16 } else { 0 }
    }
}

/// Reads a 16-bit grey PNG depth map.
pub fn read_depth_png(path: &Path) -> Result<DepthMap> {
    let img = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?
        .decode()
        .map_err(|error| Error::Image { path: path.into(), error })?;
    match img {
        image::DynamicImage::ImageLuma16(buf) => {
            let (width, height) = buf.dimensions();
            Ok(DepthMap { width, height, mm: buf.into_raw() })
        }
        other => Err(Error::invalid(path, format!("depth PNG must be 16-bit grey, got {:?}", other.color()))),
    }
}

/// Writes a depth map as a 16-bit grey PNG (fast compression: depth is written for every frame).
pub fn write_depth_png(path: &Path, depth: &DepthMap) -> Result<()> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let n = depth.width as usize * depth.height as usize;
    if depth.mm.len() != n {
        return Err(Error::invalid(path, format!("depth map has {} values for {n} pixels", depth.mm.len())));
    }
    let mut bytes = Vec::with_capacity(n * 2);
    for v in &depth.mm {
        bytes.extend_from_slice(&v.to_ne_bytes());
    }
    let mut out = Vec::with_capacity(n);
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Paeth)
        .write_image(&bytes, depth.width, depth.height, image::ExtendedColorType::L16)
        .map_err(|error| Error::Image { path: path.into(), error })?;
    std::fs::write(path, out).map_err(|e| Error::io(path, e))
}
