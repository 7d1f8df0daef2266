//! Depth consistency without depth truth: within one cohort a nearer fish looks longer, so in each
//! frame the depth network's relative inverse depth at the fish should rise with the length of their
//! boxes. The score is the mean over frames of Spearman's rank correlation between the two (+1: the
//! network orders every fish as their sizes do; -1: the reverse).

use fme_core::geometry::PixelBox;

/// Fewer boxes than this in a frame give no correlation worth averaging; the frame is skipped.
pub const MIN_BOXES: usize = 3;

/// Spearman's rank correlation of paired samples (ties share their mean rank; Pearson's correlation
/// of the ranks). `None` for fewer than [`MIN_BOXES`] pairs, different lengths, a value that is
/// not finite, or a sample whose values are all tied (no order to compare).
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < MIN_BOXES || y.len() != n || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let (rx, ry) = (ranks(x), ranks(y));
    let mean = (n as f64 + 1.0) / 2.0;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in rx.iter().zip(&ry) {
        let (da, db) = (a - mean, b - mean);
        sxy += da * db;
        sxx += da * da;
        syy += db * db;
    }
    (sxx > 0.0 && syy > 0.0).then(|| (sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0))
}

/// 1-based ranks, ties given their mean rank.
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i + 1;
        while j < order.len() && v[order[j]] == v[order[i]] {
            j += 1;
        }
        // Positions i..j (0-based) share the mean of ranks i+1..=j.
        let rank = (i + j + 1) as f64 / 2.0;
        for &k in &order[i..j] {
            r[k] = rank;
        }
        i = j;
    }
    r
}

/// True when `b` lies inside a `width x height` frame without touching its edge (a box cut by the
/// edge has a long side shorter than the fish).
pub fn inside_frame(b: &PixelBox, width: f64, height: f64) -> bool {
    b.x > 0.0 && b.y > 0.0 && b.x + b.w < width && b.y + b.h < height
}

/// The mean per-frame Spearman correlation between relative inverse depth and box long side.
#[derive(Debug, Clone, Default)]
pub struct DepthConsistency {
    sum: f64,
    frames: usize,
    inv: Vec<f64>,
    long: Vec<f64>,
}

impl DepthConsistency {
    /// Adds one frame: each fish's relative inverse depth (larger = nearer) and its box. A frame with
    /// fewer than [`MIN_BOXES`] fish or all values tied is skipped.
    pub fn add_frame(&mut self, fish: impl IntoIterator<Item = (f64, PixelBox)>) {
        self.inv.clear();
        self.long.clear();
        for (r, b) in fish {
            self.inv.push(r);
            self.long.push(b.w.max(b.h));
        }
        if let Some(rho) = spearman(&self.inv, &self.long) {
            self.sum += rho;
            self.frames += 1;
        }
    }

    /// The mean correlation, `None` when no frame counted.
    pub fn mean(&self) -> Option<f64> {
        (self.frames > 0).then(|| self.sum / self.frames as f64)
    }

    /// Frames averaged.
    pub fn frames(&self) -> usize {
        self.frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fish `size` pixels long at (x, 50).
    fn fish(x: f64, size: f64) -> PixelBox {
        PixelBox { x, y: 50.0, w: size, h: 0.3 * size }
    }

    #[test]
    fn nearer_larger_fish_score_plus_one_and_the_reverse_minus_one() {
        let mut c = DepthConsistency::default();
        // Nearer = larger box = higher inverse depth.
        c.add_frame([
            (0.5, fish(10.0, 40.0)),
            (0.9, fish(100.0, 80.0)),
            (0.2, fish(200.0, 20.0)),
            (0.7, fish(300.0, 60.0)),
        ]);
        assert_eq!(c.frames(), 1);
        assert!((c.mean().unwrap() - 1.0).abs() < 1e-12, "{:?}", c.mean());
        let mut r = DepthConsistency::default();
        r.add_frame([(0.5, fish(10.0, 40.0)), (0.1, fish(100.0, 80.0)), (0.9, fish(200.0, 20.0))]);
        assert!((r.mean().unwrap() + 1.0).abs() < 1e-12, "{:?}", r.mean());
        // The mean is over frames: +1 and -1 average to 0.
        c.add_frame([(0.5, fish(10.0, 40.0)), (0.1, fish(100.0, 80.0)), (0.9, fish(200.0, 20.0))]);
        assert_eq!((c.frames(), c.mean()), (2, Some(0.0)));
    }

    #[test]
    fn ties_and_small_frames_are_skipped() {
        let mut c = DepthConsistency::default();
        c.add_frame([(0.5, fish(10.0, 40.0)), (0.9, fish(100.0, 80.0))]); // two fish
        c.add_frame([]);
        c.add_frame([(0.5, fish(10.0, 40.0)), (0.9, fish(100.0, 40.0)), (0.1, fish(200.0, 40.0))]); // one size
        c.add_frame([(0.5, fish(10.0, 40.0)), (0.5, fish(100.0, 80.0)), (0.5, fish(200.0, 20.0))]); // one depth
        c.add_frame([(f64::NAN, fish(10.0, 40.0)), (0.5, fish(100.0, 80.0)), (0.4, fish(200.0, 20.0))]);
        assert_eq!((c.frames(), c.mean()), (0, None));
        // Partial ties take mean ranks: sizes 40, 40, 80 against depths 0.1, 0.2, 0.9.
        let rho = spearman(&[0.1, 0.2, 0.9], &[40.0, 40.0, 80.0]).unwrap();
        assert!((rho - 0.866_025_403_784_438_6).abs() < 1e-12, "{rho}");
    }

    #[test]
    fn boxes_touching_the_edge_are_outside() {
        assert!(inside_frame(&PixelBox { x: 1.0, y: 1.0, w: 10.0, h: 10.0 }, 100.0, 50.0));
        assert!(!inside_frame(&PixelBox { x: 0.0, y: 1.0, w: 10.0, h: 10.0 }, 100.0, 50.0));
        assert!(!inside_frame(&PixelBox { x: 90.0, y: 1.0, w: 10.0, h: 10.0 }, 100.0, 50.0));
        assert!(!inside_frame(&PixelBox { x: 10.0, y: 45.0, w: 10.0, h: 5.0 }, 100.0, 50.0));
    }
}
