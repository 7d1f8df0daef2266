//! Scalar metrics: RMSE, Szekely's distance correlation, error interval, depth accuracy.

/// Root mean square of `est - truth` over paired values; `None` for no pairs.
pub fn rmse(est: &[f64], truth: &[f64]) -> Option<f64> {
    let n = est.len().min(truth.len());
    if n == 0 {
        return None;
    }
    let sse: f64 = est.iter().zip(truth).map(|(e, t)| (e - t).powi(2)).sum();
    Some((sse / n as f64).sqrt())
}

/// Mean of `est - truth`.
pub fn bias(est: &[f64], truth: &[f64]) -> Option<f64> {
    let n = est.len().min(truth.len());
    (n > 0).then(|| est.iter().zip(truth).map(|(e, t)| e - t).sum::<f64>() / n as f64)
}

/// Row means of the pairwise distance matrix `|x_i - x_j|` and their grand mean, O(n) memory.
fn row_means(x: &[f64]) -> (Vec<f64>, f64) {
    let n = x.len() as f64;
    let rows: Vec<f64> = x.iter().map(|&xi| x.iter().map(|&xj| (xi - xj).abs()).sum::<f64>() / n).collect();
    let grand = rows.iter().sum::<f64>() / n;
    (rows, grand)
}

/// Szekely's (biased, V-statistic) distance correlation of two equally long samples, the paper's
/// DistCorr and PyPI `dcor.distance_correlation`. The double-centred distance matrices are never
/// stored: their entries are recomputed from the row means, so memory is O(n) and time O(n^2).
/// `None` for fewer than 2 pairs or different lengths; 0 when either sample is constant.
pub fn distance_correlation(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 2 || y.len() != n || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let (ax, gx) = row_means(x);
    let (ay, gy) = row_means(y);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        for j in 0..n {
            let a = (x[i] - x[j]).abs() - ax[i] - ax[j] + gx;
            let b = (y[i] - y[j]).abs() - ay[i] - ay[j] + gy;
            sxy += a * b;
            sxx += a * a;
            syy += b * b;
        }
    }
    let denom = (sxx * syy).sqrt();
    if denom <= 0.0 {
        return Some(0.0);
    }
    Some((sxy.max(0.0) / denom).sqrt())
}

/// Empirical quantile (linear interpolation between order statistics, numpy's default) of `v`.
pub fn quantile(v: &[f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s: Vec<f64> = v.to_vec();
    s.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    Some(s[lo] + (s[hi] - s[lo]) * (pos - lo as f64))
}

/// Accumulates depth accuracy at fish centres: RMSE and the threshold accuracies
/// `delta < 1.25` and `delta < 1.25^2`, with `delta = max(est/true, true/est)`.
#[derive(Debug, Clone, Copy, Default)]
pub struct DepthAccuracy {
    n: usize,
    sse: f64,
    within_125: usize,
    within_125_2: usize,
}

impl DepthAccuracy {
    /// Adds one estimated/true pair (both metres, positive).
    pub fn add(&mut self, est: f64, truth: f64) {
        if !(est.is_finite() && truth.is_finite() && est > 0.0 && truth > 0.0) {
            return;
        }
        self.n += 1;
        self.sse += (est - truth).powi(2);
        let delta = (est / truth).max(truth / est);
        self.within_125 += (delta < 1.25) as usize;
        self.within_125_2 += (delta < 1.25 * 1.25) as usize;
    }
    /// Number of pairs.
    pub fn count(&self) -> usize {
        self.n
    }
    /// RMSE in metres.
    pub fn rmse(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sse / self.n as f64).sqrt())
    }
    /// Fraction with `delta < 1.25`.
    pub fn delta_1_25(&self) -> Option<f64> {
        (self.n > 0).then(|| self.within_125 as f64 / self.n as f64)
    }
    /// Fraction with `delta < 1.25^2`.
    pub fn delta_1_25_2(&self) -> Option<f64> {
        (self.n > 0).then(|| self.within_125_2 as f64 / self.n as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference: the textbook definition with full n x n matrices.
    fn dcor_naive(x: &[f64], y: &[f64]) -> f64 {
        let n = x.len();
        let centred = |v: &[f64]| {
            let d: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| (v[i] - v[j]).abs()).collect()).collect();
            let row: Vec<f64> = d.iter().map(|r| r.iter().sum::<f64>() / n as f64).collect();
            let g = row.iter().sum::<f64>() / n as f64;
            (0..n).map(|i| (0..n).map(|j| d[i][j] - row[i] - row[j] + g).collect::<Vec<_>>()).collect::<Vec<_>>()
        };
        let (a, b) = (centred(x), centred(y));
        let m = |p: &Vec<Vec<f64>>, q: &Vec<Vec<f64>>| {
            p.iter().zip(q).map(|(r, s)| r.iter().zip(s).map(|(u, v)| u * v).sum::<f64>()).sum::<f64>() / (n * n) as f64
        };
        (m(&a, &b) / (m(&a, &a) * m(&b, &b)).sqrt()).sqrt()
    }

    #[test]
    fn distance_correlation_matches_definition_and_known_cases() {
        let x: Vec<f64> = (0..50).map(|i| (i as f64 * 0.37).sin()).collect();
        let y: Vec<f64> = x.iter().enumerate().map(|(i, v)| v * v + 0.1 * (i as f64 * 1.3).cos()).collect();
        let d = distance_correlation(&x, &y).unwrap();
        assert!((d - dcor_naive(&x, &y)).abs() < 1e-12);
        assert!(d > 0.3 && d < 1.0);
        // Affine transforms give exactly 1; a constant gives 0.
        let z: Vec<f64> = x.iter().map(|v| -3.0 * v + 2.0).collect();
        assert!((distance_correlation(&x, &z).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(distance_correlation(&x, &vec![1.0; 50]), Some(0.0));
        assert_eq!(distance_correlation(&x[..1], &y[..1]), None);
        assert_eq!(distance_correlation(&x, &y[..10]), None);
    }

    #[test]
    fn rmse_quantile_and_depth_accuracy() {
        assert_eq!(rmse(&[1.0, 3.0], &[0.0, 3.0]), Some((0.5f64).sqrt()));
        assert_eq!(rmse(&[], &[]), None);
        assert_eq!(bias(&[1.0, 3.0], &[0.0, 3.0]), Some(0.5));
        assert_eq!(quantile(&[3.0, 1.0, 2.0, 4.0], 0.5), Some(2.5));
        assert_eq!(quantile(&[3.0, 1.0, 2.0, 5.0, 4.0], 0.25), Some(2.0));
        let mut d = DepthAccuracy::default();
        d.add(2.0, 2.0);
        d.add(2.4, 2.0); // delta 1.2
        d.add(3.0, 2.0); // delta 1.5
        d.add(5.0, 2.0); // delta 2.5
        d.add(f64::NAN, 2.0); // ignored
        assert_eq!(d.count(), 4);
        assert_eq!(d.delta_1_25(), Some(0.5));
        assert_eq!(d.delta_1_25_2(), Some(0.75));
        assert!((d.rmse().unwrap() - ((0.16 + 1.0 + 9.0) / 4.0f64).sqrt()).abs() < 1e-12);
    }
}
