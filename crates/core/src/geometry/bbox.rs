//! Axis-aligned boxes in the pixel frame, MOTChallenge convention (top-left corner, width, height).

use super::Pixel;

/// A box in pixels: `x`, `y` are the top-left corner, `w`, `h` the size (MOTChallenge `bb_left,
/// bb_top, bb_width, bb_height`).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct PixelBox {
    /// Left edge, pixels.
    pub x: f64,
    /// Top edge, pixels.
    pub y: f64,
    /// Width, pixels.
    pub w: f64,
    /// Height, pixels.
    pub h: f64,
}

impl PixelBox {
    /// A box from its top-left corner and size.
    #[inline]
    pub const fn new(x: f64, y: f64, w: f64, h: f64) -> Self {
        Self { x, y, w, h }
    }
    /// A box from its centre and size.
    #[inline]
    pub fn from_center(c: Pixel, w: f64, h: f64) -> Self {
        Self { x: c.u - w * 0.5, y: c.v - h * 0.5, w, h }
    }
    /// The centre of the box.
    #[inline]
    pub fn center(&self) -> Pixel {
        Pixel::new(self.x + self.w * 0.5, self.y + self.h * 0.5)
    }
    /// Area in square pixels (0 for degenerate boxes).
    #[inline]
    pub fn area(&self) -> f64 {
        self.w.max(0.0) * self.h.max(0.0)
    }
    /// Right edge.
    #[inline]
    pub fn right(&self) -> f64 {
        self.x + self.w
    }
    /// Bottom edge.
    #[inline]
    pub fn bottom(&self) -> f64 {
        self.y + self.h
    }
    /// True when the point lies inside the box (edges included).
    #[inline]
    pub fn contains(&self, p: Pixel) -> bool {
        p.u >= self.x && p.u <= self.right() && p.v >= self.y && p.v <= self.bottom()
    }
    /// True when all fields are finite and the size is not negative.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.w.is_finite()
            && self.h.is_finite()
            && self.w >= 0.0
            && self.h >= 0.0
    }
    /// Intersection over union, in `[0, 1]`.
    #[inline]
    pub fn iou(&self, o: &PixelBox) -> f64 {
        let iw = (self.right().min(o.right()) - self.x.max(o.x)).max(0.0);
        let ih = (self.bottom().min(o.bottom()) - self.y.max(o.y)).max(0.0);
        let inter = iw * ih;
        let union = self.area() + o.area() - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_identical_disjoint_and_half_overlapping_boxes() {
        let a = PixelBox::new(0.0, 0.0, 10.0, 10.0);
        assert_eq!(a.iou(&a), 1.0);
        assert_eq!(a.iou(&PixelBox::new(20.0, 0.0, 10.0, 10.0)), 0.0);
        let b = PixelBox::new(5.0, 0.0, 10.0, 10.0);
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(a.center(), Pixel::new(5.0, 5.0));
        assert_eq!(PixelBox::from_center(Pixel::new(5.0, 5.0), 10.0, 10.0), a);
    }
}
