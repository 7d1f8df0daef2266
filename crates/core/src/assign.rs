//! Optimal linear assignment (minimum-cost bipartite matching) on caller-provided buffers.
//!
//! The solver is the Hungarian method in its shortest-augmenting-path form with dual potentials
//! (Kuhn-Munkres as refined by Jonker and Volgenant): for an `n x m` cost matrix with `n <= m` it
//! adds one row at a time and augments along a Dijkstra-like shortest path in reduced costs, which
//! is `O(n^2 m)`. Rectangular matrices with more rows than columns are solved transposed.
//!
//! [`FixedAssigner`] owns its work buffers in fixed-size arrays (no heap, used by the tracker every
//! frame); [`assign_vec`] allocates them (used by the MOT metrics, whose matrices have no bound).

/// Marker in a row-to-column result for a row left unassigned.
pub const UNASSIGNED: usize = usize::MAX;

/// Work buffers of one solve; every slice must hold at least `max(n, m) + 1` entries.
struct Work<'a> {
    u: &'a mut [f64],
    v: &'a mut [f64],
    p: &'a mut [usize],
    way: &'a mut [usize],
    minv: &'a mut [f64],
    used: &'a mut [bool],
}

/// Solves `min sum cost(i, col[i])` over one-to-one assignments of `n` rows to `m` columns; every
/// row is assigned when `n <= m`, every column when `n > m`. Costs must be finite. Writes the column
/// of each row (or [`UNASSIGNED`]) into `row_to_col[..n]`.
fn solve(cost: &dyn Fn(usize, usize) -> f64, n: usize, m: usize, w: Work<'_>, row_to_col: &mut [usize]) {
    row_to_col[..n].fill(UNASSIGNED);
    if n == 0 || m == 0 {
        return;
    }
    if n > m {
        // Solve the transpose: its "rows" are our columns.
        let t = |i: usize, j: usize| cost(j, i);
        solve_rows_le_cols(&t, m, n, w, |c, r| row_to_col[r] = c);
    } else {
        solve_rows_le_cols(cost, n, m, w, |r, c| row_to_col[r] = c);
    }
}

/// The core algorithm for `n <= m` (1-based internally, index 0 is the virtual start column).
fn solve_rows_le_cols(
    a: &dyn Fn(usize, usize) -> f64,
    n: usize,
    m: usize,
    w: Work<'_>,
    mut emit: impl FnMut(usize, usize),
) {
    let Work { u, v, p, way, minv, used } = w;
    u[..=n].fill(0.0);
    v[..=m].fill(0.0);
    p[..=m].fill(0);
    way[..=m].fill(0);
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0usize;
        minv[..=m].fill(f64::INFINITY);
        used[..=m].fill(false);
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0usize;
            for j in 1..=m {
                if !used[j] {
                    let cur = a(i0 - 1, j - 1) - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            if j1 == 0 {
                // Only reachable with non-finite costs; stop rather than loop forever.
                break;
            }
            for j in 0..=m {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        // Augment along the path back to the virtual column 0.
        while j0 != 0 {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
        }
    }
    for (j, &row) in p.iter().enumerate().take(m + 1).skip(1) {
        if row != 0 {
            emit(row - 1, j - 1);
        }
    }
}

/// An assignment solver with fixed-size work buffers for matrices up to `N x N` (`N` rows and `N`
/// columns at most); it never allocates.
#[derive(Debug, Clone)]
pub struct FixedAssigner<const N: usize> {
    u: [f64; N],
    v: [f64; N],
    p: [usize; N],
    way: [usize; N],
    minv: [f64; N],
    used: [bool; N],
}

impl<const N: usize> Default for FixedAssigner<N> {
    fn default() -> Self {
        Self { u: [0.0; N], v: [0.0; N], p: [0; N], way: [0; N], minv: [0.0; N], used: [false; N] }
    }
}

impl<const N: usize> FixedAssigner<N> {
    /// Largest side of a matrix this solver accepts (`N - 1`: one slot is the virtual column).
    pub const MAX_SIDE: usize = N - 1;

    /// Minimum-cost assignment of `n` rows to `m` columns; writes each row's column or [`UNASSIGNED`]
    /// into `row_to_col[..n]`. Returns `false` (and assigns nothing) when `n` or `m` exceeds
    /// [`Self::MAX_SIDE`] or `row_to_col` is shorter than `n`.
    pub fn solve(&mut self, cost: &dyn Fn(usize, usize) -> f64, n: usize, m: usize, row_to_col: &mut [usize]) -> bool {
        if n > Self::MAX_SIDE || m > Self::MAX_SIDE || row_to_col.len() < n {
            return false;
        }
        let w = Work {
            u: &mut self.u,
            v: &mut self.v,
            p: &mut self.p,
            way: &mut self.way,
            minv: &mut self.minv,
            used: &mut self.used,
        };
        solve(cost, n, m, w, row_to_col);
        true
    }
}

/// Minimum-cost assignment of any size, with heap-allocated buffers. Returns each row's column or
/// [`UNASSIGNED`].
pub fn assign_vec(cost: &dyn Fn(usize, usize) -> f64, n: usize, m: usize) -> Vec<usize> {
    let k = n.max(m) + 1;
    let (mut u, mut v, mut minv) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let (mut p, mut way) = (vec![0usize; k], vec![0usize; k]);
    let mut used = vec![false; k];
    let mut out = vec![UNASSIGNED; n];
    let w = Work { u: &mut u, v: &mut v, p: &mut p, way: &mut way, minv: &mut minv, used: &mut used };
    solve(cost, n, m, w, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classic_three_by_three() {
        let c = [[4.0, 1.0, 3.0], [2.0, 0.0, 5.0], [3.0, 2.0, 2.0]];
        let r = assign_vec(&|i, j| c[i][j], 3, 3);
        let total: f64 = r.iter().enumerate().map(|(i, &j)| c[i][j]).sum();
        assert_eq!(total, 5.0);
        assert_eq!(r, vec![1, 0, 2]);
    }

    #[test]
    fn rectangular_both_ways() {
        let c = [[1.0, 10.0], [10.0, 1.0], [0.5, 0.6]];
        let r = assign_vec(&|i, j| c[i][j], 3, 2);
        let assigned: Vec<_> = r.iter().filter(|&&j| j != UNASSIGNED).collect();
        assert_eq!(assigned.len(), 2);
        assert_eq!(r, vec![UNASSIGNED, 1, 0]);
        let t = assign_vec(&|i, j| c[j][i], 2, 3);
        assert_eq!(t, vec![2, 1]);
    }
}
