//! Angles a box subtends from the camera: what a fish's apparent length is made of.

use super::{Intrinsics, Pixel, PixelBox};
use crate::units::Metres;

/// Angle between two directions (any non-zero lengths), radians; accurate for small angles too.
pub fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let unit = |v: [f64; 3]| {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    };
    let (a, b) = (unit(a), unit(b));
    let chord = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    2.0 * (0.5 * chord).min(1.0).asin()
}

/// A box's apparent length at `range` (metres from the camera): the larger of its angular width
/// (between the middles of its left and right edges) and angular height, times the range.
pub fn apparent_length(intrinsics: &Intrinsics, bbox: &PixelBox, range: Metres) -> Metres {
    let c = bbox.center();
    let ray = |u: f64, v: f64| {
        let r = intrinsics.ray(Pixel::new(u, v));
        [r.x, r.y, r.z]
    };
    let across = angle_between(ray(c.u - 0.5 * bbox.w, c.v), ray(c.u + 0.5 * bbox.w, c.v));
    let down = angle_between(ray(c.u, c.v - 0.5 * bbox.h), ray(c.u, c.v + 0.5 * bbox.h));
    Metres(across.max(down) * range.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_and_apparent_lengths() {
        assert!((angle_between([1.0, 0.0, 0.0], [0.0, 2.0, 0.0]) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((angle_between([0.0, 0.0, 1.0], [1e-4, 0.0, 1.0]) - 1e-4).abs() < 1e-12);
        // A 0.4 m fish square to the line of sight, 3 m away, at the centre and 40 degrees off the axis:
        // the same apparent length, though it spans fewer pixels off the axis.
        let k = Intrinsics::from_hfov(640, 384, 90.0).unwrap();
        for off in [0.0f64, 40.0] {
            let (a, half) = (off.to_radians(), (0.2f64 / 3.0).atan());
            let (u0, u1) = (k.cx + k.fx * (a - half).tan(), k.cx + k.fx * (a + half).tan());
            let b = PixelBox::from_center(Pixel::new(0.5 * (u0 + u1), k.cy), u1 - u0, 4.0);
            let l = apparent_length(&k, &b, Metres(3.0)).0;
            assert!((l - 0.4).abs() < 0.002, "{off} degrees: {l}");
        }
    }
}
