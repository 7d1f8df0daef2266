//! Optimal assignment against brute force on small random matrices.

use fme::assign::{FixedAssigner, UNASSIGNED, assign_vec};

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Best total over all injective maps of the smaller side into the larger.
fn brute(c: &[f64], n: usize, m: usize) -> f64 {
    fn rec(c: &[f64], n: usize, m: usize, i: usize, used: &mut Vec<bool>, transposed: bool) -> f64 {
        let (rows, cols) = if transposed { (m, n) } else { (n, m) };
        if i == rows {
            return 0.0;
        }
        let mut best = f64::INFINITY;
        for j in 0..cols {
            if !used[j] {
                used[j] = true;
                let v = if transposed { c[j * m + i] } else { c[i * m + j] };
                best = best.min(v + rec(c, n, m, i + 1, used, transposed));
                used[j] = false;
            }
        }
        best
    }
    let transposed = n > m;
    let mut used = vec![false; n.max(m)];
    rec(c, n, m, 0, &mut used, transposed)
}

#[test]
fn optimal_on_random_matrices() {
    let mut rng = Lcg(42);
    let mut fixed = FixedAssigner::<9>::default();
    for trial in 0..400 {
        let n = 1 + (rng.next() * 6.0) as usize;
        let m = 1 + (rng.next() * 6.0) as usize;
        // Some trials with many ties (integer costs), some with negative costs.
        let c: Vec<f64> = (0..n * m)
            .map(|_| if trial % 3 == 0 { (rng.next() * 4.0).floor() } else { rng.next() * 2.0 - 1.0 })
            .collect();
        let r = assign_vec(&|i, j| c[i * m + j], n, m);
        let mut seen = vec![false; m];
        let mut total = 0.0;
        let mut count = 0;
        for (i, &j) in r.iter().enumerate() {
            if j != UNASSIGNED {
                assert!(!seen[j], "column {j} used twice");
                seen[j] = true;
                total += c[i * m + j];
                count += 1;
            }
        }
        assert_eq!(count, n.min(m), "trial {trial}: not a full assignment");
        let best = brute(&c, n, m);
        assert!((total - best).abs() < 1e-9, "trial {trial} {n}x{m}: {total} vs optimum {best}");
        let mut out = [UNASSIGNED; 8];
        assert!(fixed.solve(&|i, j| c[i * m + j], n, m, &mut out));
        let ft: f64 = (0..n).filter(|&i| out[i] != UNASSIGNED).map(|i| c[i * m + out[i]]).sum();
        assert!((ft - best).abs() < 1e-9);
    }
}

#[test]
fn fixed_assigner_refuses_oversized_problems() {
    let mut fixed = FixedAssigner::<4>::default();
    let mut out = [0usize; 8];
    assert!(!fixed.solve(&|_, _| 0.0, 4, 2, &mut out));
    assert!(!fixed.solve(&|_, _| 0.0, 2, 2, &mut out[..1]));
    assert!(fixed.solve(&|i, j| if i == j { 0.0 } else { 1.0 }, 3, 3, &mut out));
    assert_eq!(&out[..3], &[0, 1, 2]);
}
