//! HOTA (Luiten et al., IJCV 2021), following TrackEval's `HOTA.eval_sequence`.
//!
//! Similarity is box IoU. First pass: global alignment score per (gt id, tracker id) from the
//! per-frame normalised similarities. Second pass, per frame: the assignment that maximises
//! `alignment * IoU`; for every `alpha` in 0.05, 0.10, ..., 0.95 pairs with IoU >= alpha are true
//! positives. `DetA = TP / (TP + FN + FP)`, `AssA` = mean over TPs of the pair's association IoU,
//! `HOTA_alpha = sqrt(DetA AssA)`; reported values are means over the 19 alphas.

use fme_core::assign::{UNASSIGNED, assign_vec};
use fme_core::geometry::PixelBox;
use std::collections::HashMap;

const EPS: f64 = f64::EPSILON;
const ALPHAS: usize = 19;

fn alpha(a: usize) -> f64 {
    0.05 * (a + 1) as f64
}

/// Stores frames, computes HOTA at the end (two passes are needed).
#[derive(Debug, Clone, Default)]
pub struct HotaAccumulator {
    frames: Vec<(Vec<usize>, Vec<usize>, Vec<f64>)>,
    gt_index: HashMap<i64, usize>,
    tr_index: HashMap<i64, usize>,
}

/// HOTA and its parts (means over alpha).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Hota {
    /// Higher-order tracking accuracy.
    pub hota: f64,
    /// Detection accuracy.
    pub deta: f64,
    /// Association accuracy.
    pub assa: f64,
    /// Localisation accuracy (mean IoU of TPs).
    pub loca: f64,
}

impl HotaAccumulator {
    /// Adds one frame.
    pub fn update(&mut self, gt: &[(i64, PixelBox)], hyp: &[(i64, PixelBox)]) {
        let mut next = self.gt_index.len();
        let g: Vec<usize> = gt
            .iter()
            .map(|(id, _)| {
                *self.gt_index.entry(*id).or_insert_with(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect();
        let mut next = self.tr_index.len();
        let h: Vec<usize> = hyp
            .iter()
            .map(|(id, _)| {
                *self.tr_index.entry(*id).or_insert_with(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect();
        let mut sim = Vec::with_capacity(gt.len() * hyp.len());
        for (_, gb) in gt {
            for (_, hb) in hyp {
                sim.push(gb.iou(hb));
            }
        }
        self.frames.push((g, h, sim));
    }

    /// HOTA over everything added.
    pub fn compute(&self) -> Hota {
        let (ng, nt) = (self.gt_index.len(), self.tr_index.len());
        let mut potential = vec![0.0; ng * nt];
        let mut gt_count = vec![0.0; ng];
        let mut tr_count = vec![0.0; nt];
        for (g, h, sim) in &self.frames {
            let nh = h.len();
            let col: Vec<f64> = (0..nh).map(|j| (0..g.len()).map(|i| sim[i * nh + j]).sum()).collect();
            for (i, &gi) in g.iter().enumerate() {
                let row: f64 = sim[i * nh..(i + 1) * nh].iter().sum();
                for (j, &hj) in h.iter().enumerate() {
                    let s = sim[i * nh + j];
                    let denom = row + col[j] - s;
                    if denom > EPS {
                        potential[gi * nt + hj] += s / denom;
                    }
                }
                gt_count[gi] += 1.0;
            }
            for &hj in h {
                tr_count[hj] += 1.0;
            }
        }
        let align: Vec<f64> = (0..ng * nt)
            .map(|k| {
                let d = gt_count[k / nt] + tr_count[k % nt] - potential[k];
                if d > 0.0 { potential[k] / d } else { 0.0 }
            })
            .collect();
        let mut tp = [0.0; ALPHAS];
        let mut fnn = [0.0; ALPHAS];
        let mut fp = [0.0; ALPHAS];
        let mut loc = [0.0; ALPHAS];
        let mut matches: Vec<HashMap<(usize, usize), f64>> = vec![HashMap::new(); ALPHAS];
        for (g, h, sim) in &self.frames {
            let (n, nh) = (g.len(), h.len());
            if n == 0 || nh == 0 {
                for a in 0..ALPHAS {
                    fp[a] += nh as f64;
                    fnn[a] += n as f64;
                }
                continue;
            }
            let score = |i: usize, j: usize| -(align[g[i] * nt + h[j]] * sim[i * nh + j]);
            let r2c = assign_vec(&score, n, nh);
            for a in 0..ALPHAS {
                let mut k = 0.0;
                for (i, &j) in r2c.iter().enumerate() {
                    if j != UNASSIGNED && sim[i * nh + j] >= alpha(a) - EPS {
                        k += 1.0;
                        loc[a] += sim[i * nh + j];
                        *matches[a].entry((g[i], h[j])).or_default() += 1.0;
                    }
                }
                tp[a] += k;
                fnn[a] += n as f64 - k;
                fp[a] += nh as f64 - k;
            }
        }
        let mut out = Hota::default();
        for a in 0..ALPHAS {
            let assa: f64 = matches[a]
                .iter()
                .map(|(&(gi, hj), &c)| c * c / (gt_count[gi] + tr_count[hj] - c).max(1.0))
                .sum::<f64>()
                / tp[a].max(1.0);
            let deta = tp[a] / (tp[a] + fnn[a] + fp[a]).max(1.0);
            out.hota += (deta * assa).sqrt();
            out.deta += deta;
            out.assa += assa;
            out.loca += loc[a].max(1e-10) / tp[a].max(1e-10);
        }
        let k = ALPHAS as f64;
        Hota { hota: out.hota / k, deta: out.deta / k, assa: out.assa / k, loca: out.loca / k }
    }
}
