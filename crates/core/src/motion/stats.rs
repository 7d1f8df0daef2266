//! Small statistics helpers: Student-t quantile and the 95% interval of a mean.

/// Two-sided 95% quantiles of Student's t for 1..=30 degrees of freedom.
const T975: [f64; 30] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131, 2.120,
    2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
];

/// The 0.975 quantile of Student's t with `df` degrees of freedom (table up to 30, then the
/// Cornish-Fisher expansion around the normal quantile, accurate to about 1e-4). `df = 0` gives
/// infinity.
pub fn student_t975(df: usize) -> f64 {
    match df {
        0 => f64::INFINITY,
        1..=30 => T975[df - 1],
        _ => {
            let z: f64 = 1.959_963_984_540_054;
            let n = df as f64;
            z + (z.powi(3) + z) / (4.0 * n) + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * n * n)
        }
    }
}

/// Mean and its 95% t-interval from running sums (`n`, `sum`, `sum of squares`). `None` for `n = 0`;
/// for `n = 1` the interval is the point itself (no spread is known).
pub fn mean_ci95(n: usize, sum: f64, sum_sq: f64) -> Option<(f64, f64, f64)> {
    if n == 0 {
        return None;
    }
    let nf = n as f64;
    let mean = sum / nf;
    if n == 1 {
        return Some((mean, mean, mean));
    }
    let var = ((sum_sq - nf * mean * mean) / (nf - 1.0)).max(0.0);
    let half = student_t975(n - 1) * (var / nf).sqrt();
    Some((mean, mean - half, mean + half))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantiles_and_interval() {
        assert_eq!(student_t975(1), 12.706);
        assert!((student_t975(40) - 2.021).abs() < 1e-3);
        assert!((student_t975(120) - 1.980).abs() < 1e-3);
        assert!((student_t975(100_000) - 1.96).abs() < 1e-3);
        assert!(mean_ci95(0, 0.0, 0.0).is_none());
        // Values 1, 2, 3: mean 2, sd 1, half-width 4.303 / sqrt(3).
        let (m, lo, hi) = mean_ci95(3, 6.0, 14.0).unwrap();
        assert_eq!(m, 2.0);
        assert!((hi - 2.0 - 4.303 / 3f64.sqrt()).abs() < 1e-12 && (2.0 - lo - 4.303 / 3f64.sqrt()).abs() < 1e-12);
    }
}
