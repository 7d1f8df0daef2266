//! CLEAR MOT (MOTA, MOTP), identity (IDF1, IDP, IDR) and track-quality metrics.
//!
//! Conventions follow py-motmetrics 1.4.0 / the MOTChallenge devkit with IoU distance: a ground-truth
//! object and a hypothesis may pair when `1 - IoU <= 0.5`. Per frame: (1) correspondences from the
//! previous frame are kept while still pairable; (2) the remaining objects and hypotheses are
//! matched by a minimum-distance assignment that first maximises the number of pairs; a match whose
//! object was last paired with another hypothesis is an ID switch; (3) unpaired objects are misses,
//! unpaired hypotheses false positives. MOTA = 1 - (FN + FP + IDSW) / GT; MOTP is the mean
//! `1 - IoU` of matches (motmetrics' convention: lower is better; the devkit reports `1 - MOTP`).
//! IDF1 = 2 IDTP / (GT + hypotheses), with IDTP from the global one-to-one assignment of object ids
//! to hypothesis ids that maximises the number of pairable frames (Ristani et al. 2016).

use fme_core::assign::{UNASSIGNED, assign_vec};
use fme_core::geometry::PixelBox;
use fme_edge::sequence::mot_text::MotRow;
use std::collections::HashMap;

/// Default pairing threshold on `1 - IoU`.
pub const MAX_IOU_DISTANCE: f64 = 0.5;

/// Accumulates frames of ground truth and hypotheses.
#[derive(Debug, Clone, Default)]
pub struct MotAccumulator {
    max_dist: f64,
    m: HashMap<i64, i64>,
    frames: u64,
    matches: u64,
    switches: u64,
    fp: u64,
    misses: u64,
    dist_sum: f64,
    ocs: HashMap<i64, u64>,
    hcs: HashMap<i64, u64>,
    tps: HashMap<(i64, i64), u64>,
    tracked: HashMap<i64, u64>,
    frag_state: HashMap<i64, (bool, bool)>,
    frags: u64,
    hota: Option<super::hota::HotaAccumulator>,
}

/// Summary metrics of an accumulator (ratios in `[0, 1]`, MOTA may be negative).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MotMetrics {
    /// Frames seen.
    pub num_frames: u64,
    /// Ground-truth boxes.
    pub num_objects: u64,
    /// Hypothesis boxes.
    pub num_predictions: u64,
    /// Distinct ground-truth ids.
    pub num_unique_objects: u64,
    /// Matches that are not switches.
    pub num_matches: u64,
    /// Identity switches.
    pub num_switches: u64,
    /// False positives.
    pub num_false_positives: u64,
    /// Misses (false negatives).
    pub num_misses: u64,
    /// Fragmentations (tracked -> missed transitions inside an object's tracked span).
    pub num_fragmentations: u64,
    /// Objects tracked at least 80% of their frames.
    pub mostly_tracked: u64,
    /// Objects tracked 20-80% of their frames.
    pub partially_tracked: u64,
    /// Objects tracked under 20% of their frames.
    pub mostly_lost: u64,
    /// Matched / ground truth.
    pub recall: f64,
    /// Matched / hypotheses.
    pub precision: f64,
    /// Multiple-object tracking accuracy.
    pub mota: f64,
    /// Mean `1 - IoU` of matched pairs (motmetrics' MOTP).
    pub motp: f64,
    /// Identity true positives.
    pub idtp: u64,
    /// Identity false positives.
    pub idfp: u64,
    /// Identity false negatives.
    pub idfn: u64,
    /// Identity precision.
    pub idp: f64,
    /// Identity recall.
    pub idr: f64,
    /// Identity F1.
    pub idf1: f64,
    /// HOTA (mean over alpha; see [`super::hota`]); NaN when not computed.
    pub hota: f64,
    /// HOTA's detection accuracy.
    pub deta: f64,
    /// HOTA's association accuracy.
    pub assa: f64,
}

fn ratio(a: f64, b: f64) -> f64 {
    if b == 0.0 { 0.0 } else { a / b }
}

impl MotAccumulator {
    /// An accumulator pairing at `1 - IoU <= 0.5`.
    pub fn new() -> Self {
        Self::with_max_distance(MAX_IOU_DISTANCE)
    }

    /// An accumulator with another pairing threshold on `1 - IoU`.
    pub fn with_max_distance(max_dist: f64) -> Self {
        Self { max_dist, hota: Some(Default::default()), ..Self::default() }
    }

    /// Skips HOTA (which keeps every frame for its second pass): the HOTA fields read NaN. For
    /// grid searches, where only CLEAR and identity metrics rank the points.
    pub fn without_hota(mut self) -> Self {
        self.hota = None;
        self
    }

    /// Adds one frame: ground-truth `(id, box)` and hypothesis `(id, box)` lists.
    pub fn update(&mut self, gt: &[(i64, PixelBox)], hyp: &[(i64, PixelBox)]) {
        self.frames += 1;
        if let Some(h) = &mut self.hota {
            h.update(gt, hyp);
        }
        let (no, nh) = (gt.len(), hyp.len());
        let mut d = vec![f64::NAN; no * nh];
        for (i, (oid, ob)) in gt.iter().enumerate() {
            *self.ocs.entry(*oid).or_default() += 1;
            for (j, (hid, hb)) in hyp.iter().enumerate() {
                let dist = 1.0 - ob.iou(hb);
                // NaN distances (degenerate boxes) never pair.
                if dist <= self.max_dist {
                    d[i * nh + j] = dist;
                    *self.tps.entry((*oid, *hid)).or_default() += 1;
                }
            }
        }
        for (hid, _) in hyp {
            *self.hcs.entry(*hid).or_default() += 1;
        }
        let mut o_done = vec![false; no];
        let mut h_done = vec![false; nh];
        let matched = |s: &mut Self, i: usize, j: usize, o_done: &mut [bool], h_done: &mut [bool]| {
            o_done[i] = true;
            h_done[j] = true;
            s.dist_sum += d[i * nh + j];
            *s.tracked.entry(gt[i].0).or_default() += 1;
            s.m.insert(gt[i].0, hyp[j].0);
        };
        // 1. Keep last frame's correspondences that are still pairable.
        for i in 0..no {
            let Some(&hprev) = self.m.get(&gt[i].0) else { continue };
            let Some(j) = (0..nh).find(|&j| !h_done[j] && hyp[j].0 == hprev) else { continue };
            if d[i * nh + j].is_finite() {
                self.matches += 1;
                matched(self, i, j, &mut o_done, &mut h_done);
            }
        }
        // 2. Assignment on the rest: invalid pairs cost so much that cardinality comes first.
        let valid = |i: usize, j: usize| !o_done[i] && !h_done[j] && d[i * nh + j].is_finite();
        // Only rows and columns with an allowed pair take part (same optimum, far smaller problems
        // in sparse scenes); when no row or column has two allowed pairs they are taken directly.
        let rows: Vec<usize> = (0..no).filter(|&i| (0..nh).any(|j| valid(i, j))).collect();
        let cols: Vec<usize> = (0..nh).filter(|&j| (0..no).any(|i| valid(i, j))).collect();
        let unique = rows.iter().all(|&i| (0..nh).filter(|&j| valid(i, j)).count() == 1)
            && cols.iter().all(|&j| (0..no).filter(|&i| valid(i, j)).count() == 1);
        let pairs: Vec<(usize, usize)> = if rows.is_empty() {
            Vec::new()
        } else if unique {
            rows.iter().filter_map(|&i| (0..nh).find(|&j| valid(i, j)).map(|j| (i, j))).collect()
        } else {
            let cmax = rows
                .iter()
                .flat_map(|&i| cols.iter().map(move |&j| (i, j)))
                .filter(|&(i, j)| valid(i, j))
                .map(|(i, j)| d[i * nh + j].abs())
                .fold(0.0, f64::max);
            let large = 2.0 * rows.len().min(cols.len()) as f64 * (cmax + 1.0) + 1.0;
            let cost = |a: usize, b: usize| {
                let (i, j) = (rows[a], cols[b]);
                if valid(i, j) { d[i * nh + j] } else { large }
            };
            let r2c = assign_vec(&cost, rows.len(), cols.len());
            (0..rows.len())
                .filter(|&a| r2c[a] != UNASSIGNED && valid(rows[a], cols[r2c[a]]))
                .map(|a| (rows[a], cols[r2c[a]]))
                .collect()
        };
        for (i, j) in pairs {
            let o = gt[i].0;
            if self.m.get(&o).is_some_and(|&h| h != hyp[j].0) {
                self.switches += 1;
            } else {
                self.matches += 1;
            }
            matched(self, i, j, &mut o_done, &mut h_done);
        }
        // 3. Misses and false positives; fragmentation bookkeeping.
        for (i, (oid, _)) in gt.iter().enumerate() {
            let st = self.frag_state.entry(*oid).or_insert((false, false));
            if o_done[i] {
                if st.0 && st.1 {
                    self.frags += 1;
                }
                *st = (true, false);
            } else {
                self.misses += 1;
                if st.0 {
                    st.1 = true;
                }
            }
        }
        self.fp += h_done.iter().filter(|&&x| !x).count() as u64;
    }

    /// Adds a whole sequence of MOT rows (ground truth and hypotheses), frame by frame over
    /// `1..=max frame`.
    pub fn update_rows(&mut self, gt: &[MotRow], hyp: &[MotRow]) {
        type Frame = (Vec<(i64, PixelBox)>, Vec<(i64, PixelBox)>);
        let mut by_frame: std::collections::BTreeMap<u32, Frame> = std::collections::BTreeMap::new();
        for r in gt {
            by_frame.entry(r.frame).or_default().0.push((r.id, r.bbox));
        }
        for r in hyp {
            by_frame.entry(r.frame).or_default().1.push((r.id, r.bbox));
        }
        for (g, h) in by_frame.values() {
            self.update(g, h);
        }
    }

    /// The metrics so far.
    pub fn metrics(&self) -> MotMetrics {
        let num_objects: u64 = self.ocs.values().sum();
        let num_predictions: u64 = self.hcs.values().sum();
        let det = self.matches + self.switches;
        let (mut mt, mut pt, mut ml) = (0, 0, 0);
        for (o, n) in &self.ocs {
            let r = *self.tracked.get(o).unwrap_or(&0) as f64 / *n as f64;
            if r >= 0.8 {
                mt += 1;
            } else if r >= 0.2 {
                pt += 1;
            } else {
                ml += 1;
            }
        }
        let idtp = self.idtp();
        let h = self
            .hota
            .as_ref()
            .map_or(super::hota::Hota { hota: f64::NAN, deta: f64::NAN, assa: f64::NAN, loca: f64::NAN }, |a| {
                a.compute()
            });
        let (idfp, idfn) = (num_predictions - idtp, num_objects - idtp);
        MotMetrics {
            num_frames: self.frames,
            num_objects,
            num_predictions,
            num_unique_objects: self.ocs.len() as u64,
            num_matches: self.matches,
            num_switches: self.switches,
            num_false_positives: self.fp,
            num_misses: self.misses,
            num_fragmentations: self.frags,
            mostly_tracked: mt,
            partially_tracked: pt,
            mostly_lost: ml,
            recall: ratio(det as f64, num_objects as f64),
            precision: ratio(det as f64, num_predictions as f64),
            mota: 1.0 - ratio((self.misses + self.switches + self.fp) as f64, num_objects as f64),
            motp: ratio(self.dist_sum, det as f64),
            idtp,
            idfp,
            idfn,
            idp: ratio(idtp as f64, num_predictions as f64),
            idr: ratio(idtp as f64, num_objects as f64),
            idf1: ratio(2.0 * idtp as f64, (num_objects + num_predictions) as f64),
            hota: h.hota,
            deta: h.deta,
            assa: h.assa,
        }
    }

    /// Identity true positives of the best global id-to-id assignment.
    fn idtp(&self) -> u64 {
        let mut oids: Vec<i64> = self.ocs.keys().copied().collect();
        let mut hids: Vec<i64> = self.hcs.keys().copied().collect();
        oids.sort_unstable();
        hids.sort_unstable();
        if oids.is_empty() || hids.is_empty() {
            return 0;
        }
        let oi: HashMap<i64, usize> = oids.iter().enumerate().map(|(i, o)| (*o, i)).collect();
        let hi: HashMap<i64, usize> = hids.iter().enumerate().map(|(i, h)| (*h, i)).collect();
        let nh = hids.len();
        let mut w = vec![0.0; oids.len() * nh];
        for ((o, h), n) in &self.tps {
            w[oi[o] * nh + hi[h]] = *n as f64;
        }
        let r2c = assign_vec(&|i, j| -w[i * nh + j], oids.len(), nh);
        r2c.iter().enumerate().filter(|(_, j)| **j != UNASSIGNED).map(|(i, &j)| w[i * nh + j] as u64).sum()
    }
}
