//! Sampling a relative depth map at a pixel with a small robust window.

use crate::geometry::Pixel;

/// A borrowed single-channel map (relative inverse depth, or metric depth), row-major.
#[derive(Debug, Clone, Copy)]
pub struct RelativeMap<'a> {
    /// Row-major values, `width * height` of them; non-finite values mean "no data".
    pub data: &'a [f32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl<'a> RelativeMap<'a> {
    /// Wraps a row-major buffer; `None` when its length is not `width * height`.
    pub fn new(data: &'a [f32], width: usize, height: usize) -> Option<Self> {
        (width.checked_mul(height)? == data.len() && width > 0 && height > 0).then_some(Self { data, width, height })
    }

    /// Value of the pixel containing `px`, if inside the map and finite.
    #[inline]
    pub fn at(&self, px: Pixel) -> Option<f64> {
        if !px.is_finite() || px.u < 0.0 || px.v < 0.0 {
            return None;
        }
        let (x, y) = (px.u as usize, px.v as usize);
        if x >= self.width || y >= self.height {
            return None;
        }
        let v = self.data[y * self.width + x] as f64;
        v.is_finite().then_some(v)
    }
}

/// Largest supported window radius (a 9x9 window).
pub const MAX_RADIUS: usize = 4;

/// Median of the finite values in the `(2r+1) x (2r+1)` window centred on the pixel containing
/// `px` (clipped to the image), the paper's "sample R at the reference point" made robust to a
/// pixel or two of misregistration and to the object's edge. `values_ok` filters values (e.g.
/// "non-zero" for depth maps where 0 means no data). Returns `None` when no value qualifies or the
/// centre lies outside the map. `radius` is capped at [`MAX_RADIUS`]. Allocation-free.
pub fn sample_median(map: &RelativeMap<'_>, px: Pixel, radius: usize, values_ok: impl Fn(f32) -> bool) -> Option<f64> {
    if !px.is_finite() || px.u < 0.0 || px.v < 0.0 {
        return None;
    }
    let (cx, cy) = (px.u as usize, px.v as usize);
    if cx >= map.width || cy >= map.height {
        return None;
    }
    let r = radius.min(MAX_RADIUS);
    let mut buf = [0f32; (2 * MAX_RADIUS + 1) * (2 * MAX_RADIUS + 1)];
    let mut n = 0;
    for y in cy.saturating_sub(r)..=(cy + r).min(map.height - 1) {
        let row = &map.data[y * map.width..(y + 1) * map.width];
        for &v in &row[cx.saturating_sub(r)..=(cx + r).min(map.width - 1)] {
            if v.is_finite() && values_ok(v) {
                buf[n] = v;
                n += 1;
            }
        }
    }
    if n == 0 {
        return None;
    }
    let vals = &mut buf[..n];
    vals.sort_unstable_by(|a, b| a.total_cmp(b));
    let m = if n % 2 == 1 { vals[n / 2] as f64 } else { 0.5 * (vals[n / 2 - 1] as f64 + vals[n / 2] as f64) };
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_ignores_an_outlier_pixel_and_nan() {
        let mut data = vec![1.0f32; 25];
        data[12] = 100.0; // the centre pixel is fouled
        data[0] = f32::NAN;
        let map = RelativeMap::new(&data, 5, 5).unwrap();
        assert_eq!(map.at(Pixel::new(2.5, 2.5)), Some(100.0));
        assert_eq!(sample_median(&map, Pixel::new(2.5, 2.5), 1, |_| true), Some(1.0));
        assert_eq!(sample_median(&map, Pixel::new(2.5, 2.5), 0, |_| true), Some(100.0));
        assert_eq!(sample_median(&map, Pixel::new(5.5, 2.5), 1, |_| true), None);
        assert_eq!(sample_median(&map, Pixel::new(-0.5, 2.5), 1, |_| true), None);
        assert_eq!(sample_median(&map, Pixel::new(0.5, 0.5), 1, |v| v > 1.0), None);
        assert!(RelativeMap::new(&data, 4, 5).is_none());
    }

    #[test]
    fn median_of_even_count_is_mean_of_middle_two() {
        let data = [1.0f32, 2.0, 3.0, 4.0];
        let map = RelativeMap::new(&data, 2, 2).unwrap();
        assert_eq!(sample_median(&map, Pixel::new(0.5, 0.5), 1, |_| true), Some(2.5));
    }
}
