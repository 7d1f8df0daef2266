//! The multi-object tracker: fixed-capacity tracks, SORT and ByteTrack-style association.

use super::config::{Mode, TrackerConfig};
use super::kalman::{CvKalman, SortKalman};
use crate::assign::{FixedAssigner, UNASSIGNED};
pub use crate::detection::Detection;
use crate::geometry::PixelBox;
use crate::units::{Metres, Seconds};

/// Most tracks alive at once (tentative, confirmed and lost).
pub const MAX_TRACKS: usize = 128;
/// Most detections used per frame; beyond it the highest scores are kept and the rest counted.
pub const MAX_DETS: usize = 256;

/// Life-cycle state of a track (internal: [`Tracker::outputs`] reports confirmed tracks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TrackState {
    /// Seen fewer than `min_hits` times; not reported.
    Tentative,
    /// Confirmed and matched recently.
    Confirmed,
    /// Confirmed but unmatched in the last update; kept for `max_age_s` to be recovered.
    Lost,
}

/// A reported track at the current frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    /// Track identity, from 1.
    pub id: u32,
    /// Filtered box.
    pub bbox: PixelBox,
    /// Score of the last matched detection.
    pub score: f64,
    /// Time since the track started.
    pub age: Seconds,
    /// Number of matched detections.
    pub hits: u32,
    /// Smoothed depth, when detections carried one.
    pub depth: Option<Metres>,
}

/// Counters since the tracker was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackerStats {
    /// Updates processed.
    pub frames: u64,
    /// Detections dropped because a frame had more than [`MAX_DETS`].
    pub det_overflow: u64,
    /// New tracks not started (or lost tracks evicted) because [`MAX_TRACKS`] were alive.
    pub track_overflow: u64,
    /// Detections ignored because their box or score was not finite or their size not positive.
    pub invalid_dets: u64,
    /// Tracks started.
    pub tracks_started: u64,
}

/// Error of [`Tracker::update`] / [`Tracker::predict`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TrackError {
    /// Timestamps must be finite and strictly increasing.
    #[error("frame time {t} s is not after the previous one ({prev} s)")]
    TimeNotIncreasing {
        /// The offending time.
        t: f64,
        /// The previous update's time.
        prev: f64,
    },
}

#[derive(Debug, Clone, Copy)]
enum Filter {
    Sort(SortKalman),
    Cv(CvKalman),
}

#[derive(Debug, Clone, Copy)]
struct TrackSlot {
    id: u32,
    filter: Filter,
    state: TrackState,
    hits: u32,
    hit_streak: u32,
    /// Updates since the last match (SORT's `time_since_update`).
    tsu: u32,
    t_filter: f64,
    t_last: f64,
    t_first: f64,
    score: f64,
    depth: Option<f64>,
    /// Predicted box at the current frame, used for association.
    pred: PixelBox,
}

impl TrackSlot {
    fn bbox(&self) -> PixelBox {
        match &self.filter {
            Filter::Sort(k) => k.bbox(),
            Filter::Cv(k) => k.bbox(),
        }
    }
    fn correct(&mut self, d: &Detection) {
        match &mut self.filter {
            Filter::Sort(k) => k.update(&d.bbox),
            Filter::Cv(k) => k.update(&d.bbox),
        }
        self.score = d.score;
        if let Some(z) = d.depth.map(|m| m.get()).filter(|z| z.is_finite()) {
            self.depth = Some(match self.depth {
                Some(old) => 0.5 * old + 0.5 * z,
                None => z,
            });
        }
    }
}

const BIG: f64 = 1e6;
const ASSIGN_N: usize = MAX_DETS + 1;

/// Fixed-capacity multi-object tracker. All memory is reserved by [`Tracker::new`]; `predict` and
/// `update` never allocate.
pub struct Tracker {
    cfg: TrackerConfig,
    tracks: heapless::Vec<TrackSlot, MAX_TRACKS>,
    dets: heapless::Vec<Detection, MAX_DETS>,
    det_used: [bool; MAX_DETS],
    trk_used: [bool; MAX_TRACKS],
    rows: heapless::Vec<u16, MAX_DETS>,
    cols: heapless::Vec<u16, MAX_DETS>,
    row_to_col: [usize; MAX_DETS],
    cnt_r: [u16; MAX_DETS],
    cnt_c: [u16; MAX_DETS],
    rmap: [u16; MAX_DETS],
    cmap: [u16; MAX_DETS],
    cost: Box<[f64]>,
    assigner: Box<FixedAssigner<ASSIGN_N>>,
    outputs: heapless::Vec<Track, MAX_TRACKS>,
    next_id: u32,
    last_t: Option<f64>,
    predicted_t: Option<f64>,
    stats: TrackerStats,
}

impl std::fmt::Debug for Tracker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tracker").field("cfg", &self.cfg).field("tracks", &self.tracks.len()).finish()
    }
}

impl Tracker {
    /// A tracker with the given settings (call [`TrackerConfig::validate`] first for user input).
    pub fn new(cfg: TrackerConfig) -> Self {
        Self {
            cfg,
            tracks: heapless::Vec::new(),
            dets: heapless::Vec::new(),
            det_used: [false; MAX_DETS],
            trk_used: [false; MAX_TRACKS],
            rows: heapless::Vec::new(),
            cols: heapless::Vec::new(),
            row_to_col: [UNASSIGNED; MAX_DETS],
            cnt_r: [0; MAX_DETS],
            cnt_c: [0; MAX_DETS],
            rmap: [0; MAX_DETS],
            cmap: [0; MAX_DETS],
            cost: vec![0.0; MAX_DETS * MAX_DETS].into_boxed_slice(),
            assigner: Box::default(),
            outputs: heapless::Vec::new(),
            next_id: 1,
            last_t: None,
            predicted_t: None,
            stats: TrackerStats::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    /// Counters.
    pub fn stats(&self) -> TrackerStats {
        self.stats
    }

    /// Number of live tracks (all states).
    pub fn live_tracks(&self) -> usize {
        self.tracks.len()
    }

    /// Tracks reported at the last update: confirmed tracks matched at that frame (in sort mode,
    /// SORT's rule `time_since_update < 1 and (hit_streak >= min_hits or frame <= min_hits)`, in
    /// SORT's order).
    pub fn outputs(&self) -> &[Track] {
        &self.outputs
    }

    /// The tracks reported at the last update, with their box at the last predicted time (after
    /// [`Tracker::predict`] on a frame without detections, the propagated box) and age up to it.
    pub fn confirmed(&self) -> impl Iterator<Item = Track> + '_ {
        let now = self.predicted_t.unwrap_or(0.0);
        self.outputs.iter().filter_map(move |o| {
            self.tracks.iter().find(|t| t.id == o.id).map(|t| Track {
                bbox: t.bbox(),
                age: Seconds(now - t.t_first),
                ..*o
            })
        })
    }

    fn check_time(&self, t: f64) -> Result<(), TrackError> {
        let prev = self.last_t.unwrap_or(f64::NEG_INFINITY);
        if !t.is_finite() || t <= prev {
            return Err(TrackError::TimeNotIncreasing { t, prev });
        }
        Ok(())
    }

    /// Propagates every track to time `t` (idempotent for the same `t`). Byte mode uses the real
    /// `dt` from the last filter time; sort mode steps one frame per new `t`, like SORT.
    pub fn predict(&mut self, t: Seconds) -> Result<(), TrackError> {
        let t = t.get();
        self.check_time(t)?;
        if self.predicted_t == Some(t) {
            return Ok(());
        }
        self.predicted_t = Some(t);
        let mut i = 0;
        while i < self.tracks.len() {
            let tr = &mut self.tracks[i];
            match &mut tr.filter {
                Filter::Sort(k) => {
                    k.predict(1.0);
                    if tr.tsu > 0 {
                        tr.hit_streak = 0;
                    }
                    tr.tsu += 1;
                }
                Filter::Cv(k) => {
                    k.predict(t - tr.t_filter);
                    tr.tsu += 1;
                }
            }
            tr.t_filter = t;
            tr.pred = tr.bbox();
            if !tr.pred.is_valid() {
                // SORT drops trackers whose prediction is NaN; so do we, in both modes.
                self.tracks.remove(i);
                continue;
            }
            i += 1;
        }
        Ok(())
    }

    /// Processes the detections of the frame at time `t`: predicts (if not done for `t`),
    /// associates, updates, starts and ends tracks, and refreshes [`Tracker::outputs`].
    pub fn update(&mut self, t: Seconds, detections: &[Detection]) -> Result<&[Track], TrackError> {
        if let Some(p) = self.predicted_t.filter(|&p| p > t.get()) {
            // The filters were already propagated past `t`: updating in their past is not possible.
            return Err(TrackError::TimeNotIncreasing { t: t.get(), prev: p });
        }
        self.predict(t)?;
        let t = t.get();
        self.last_t = Some(t);
        self.stats.frames += 1;
        self.load_detections(detections);
        match self.cfg.mode {
            Mode::Sort => self.update_sort(t),
            Mode::Byte => self.update_byte(t),
        }
        Ok(&self.outputs)
    }

    /// Copies valid detections above `det_threshold`; on overflow keeps the highest scores.
    fn load_detections(&mut self, detections: &[Detection]) {
        self.dets.clear();
        for d in detections {
            if !d.bbox.is_valid() || d.bbox.w <= 0.0 || d.bbox.h <= 0.0 || !d.score.is_finite() {
                self.stats.invalid_dets += 1;
                continue;
            }
            if d.score < self.cfg.det_threshold {
                continue;
            }
            let mut d = *d;
            if d.depth.is_some_and(|z| !(z.get().is_finite() && z.get() > 0.0)) {
                d.depth = None; // an unusable depth is dropped, the box is kept
            }
            let d = &d;
            if self.dets.push(*d).is_err() {
                self.stats.det_overflow += 1;
                let (mut lo, mut lo_i) = (f64::INFINITY, 0);
                for (i, e) in self.dets.iter().enumerate() {
                    if e.score < lo {
                        lo = e.score;
                        lo_i = i;
                    }
                }
                if d.score > lo {
                    self.dets[lo_i] = *d;
                }
            }
        }
    }

    fn new_track(&mut self, t: f64, d: &Detection) {
        if self.tracks.is_full() || self.tracks.len() >= self.cfg.max_tracks {
            // Make room by evicting the longest-lost track, if any.
            let victim = self
                .tracks
                .iter()
                .enumerate()
                .filter(|(_, tr)| tr.state == TrackState::Lost)
                .min_by(|a, b| a.1.t_last.total_cmp(&b.1.t_last))
                .map(|(i, _)| i);
            self.stats.track_overflow += 1;
            match victim {
                Some(i) => {
                    self.tracks.remove(i);
                }
                None => return,
            }
        }
        let filter = match self.cfg.mode {
            Mode::Sort => Filter::Sort(SortKalman::new(&d.bbox)),
            Mode::Byte => Filter::Cv(CvKalman::new(&d.bbox, self.cfg.noise)),
        };
        let confirmed = self.cfg.mode == Mode::Byte && self.cfg.min_hits <= 1;
        let tr = TrackSlot {
            id: self.next_id,
            filter,
            state: if confirmed { TrackState::Confirmed } else { TrackState::Tentative },
            hits: if self.cfg.mode == Mode::Sort { 0 } else { 1 },
            hit_streak: 0,
            tsu: 0,
            t_filter: t,
            t_last: t,
            t_first: t,
            score: d.score,
            depth: d.depth.map(|m| m.get()).filter(|z| z.is_finite()),
            pred: d.bbox,
        };
        if self.tracks.push(tr).is_ok() {
            self.next_id = self.next_id.wrapping_add(1).max(1);
            self.stats.tracks_started += 1;
        }
    }

    fn output_of(tr: &TrackSlot, t: f64) -> Track {
        Track {
            id: tr.id,
            bbox: tr.bbox(),
            score: tr.score,
            age: Seconds(t - tr.t_first),
            hits: tr.hits,
            depth: tr.depth.map(Metres),
        }
    }

    /// SORT's `Sort.update` after prediction.
    fn update_sort(&mut self, t: f64) {
        let (nd, nt) = (self.dets.len(), self.tracks.len());
        let thr = self.cfg.iou_threshold;
        // IoU matrix, detections as rows (SORT's orientation).
        for i in 0..nd {
            for j in 0..nt {
                self.cost[i * nt + j] = sort_iou(&self.dets[i].bbox, &self.tracks[j].pred);
            }
        }
        self.det_used[..nd].fill(false);
        self.trk_used[..nt].fill(false);
        self.rows.clear(); // matched det rows, in SORT's match order
        self.cols.clear(); // their track columns
        // Rejected pairs become unmatched detections appended after the never-matched ones.
        let mut rejected: heapless::Vec<u16, MAX_DETS> = heapless::Vec::new();
        if nd > 0 && nt > 0 {
            let iou = &self.cost[..nd * nt];
            let mut max_row = 0;
            for i in 0..nd {
                max_row = max_row.max((0..nt).filter(|&j| iou[i * nt + j] > thr).count());
            }
            let mut max_col = 0;
            for j in 0..nt {
                max_col = max_col.max((0..nd).filter(|&i| iou[i * nt + j] > thr).count());
            }
            let mut pairs: heapless::Vec<(u16, u16), MAX_DETS> = heapless::Vec::new();
            if max_row == 1 && max_col == 1 {
                for i in 0..nd {
                    for j in 0..nt {
                        if iou[i * nt + j] > thr {
                            let _ = pairs.push((i as u16, j as u16));
                        }
                    }
                }
            } else {
                let cost = |i: usize, j: usize| -iou[i * nt + j];
                self.assigner.solve(&cost, nd, nt, &mut self.row_to_col);
                for i in 0..nd {
                    if self.row_to_col[i] != UNASSIGNED {
                        let _ = pairs.push((i as u16, self.row_to_col[i] as u16));
                    }
                }
            }
            for &(i, j) in &pairs {
                if iou[i as usize * nt + j as usize] < thr {
                    let _ = rejected.push(i);
                } else {
                    self.det_used[i as usize] = true;
                    let _ = self.rows.push(i);
                    let _ = self.cols.push(j);
                }
            }
        }
        for k in 0..self.rows.len() {
            let (i, j) = (self.rows[k] as usize, self.cols[k] as usize);
            let d = self.dets[i];
            let tr = &mut self.tracks[j];
            tr.tsu = 0;
            tr.hits += 1;
            tr.hit_streak += 1;
            tr.t_last = t;
            tr.correct(&d);
        }
        for i in 0..nd {
            if !self.det_used[i] && !rejected.contains(&(i as u16)) {
                let d = self.dets[i];
                self.new_track(t, &d);
            }
        }
        for k in 0..rejected.len() {
            let d = self.dets[rejected[k] as usize];
            self.new_track(t, &d);
        }
        // Output in reverse list order and drop tracks older than max_age.
        self.outputs.clear();
        let warmup = self.stats.frames <= u64::from(self.cfg.min_hits);
        let mut i = self.tracks.len();
        while i > 0 {
            i -= 1;
            let tr = &mut self.tracks[i];
            if tr.tsu < 1 && (tr.hit_streak >= self.cfg.min_hits || warmup) {
                tr.state = TrackState::Confirmed;
                let _ = self.outputs.push(Self::output_of(tr, t));
            }
            if tr.tsu > self.cfg.max_age_frames {
                self.tracks.remove(i);
            }
        }
    }

    /// One association stage: tracks selected by `trk` against unused detections selected by
    /// `det`, gated at `min_iou`; matched tracks are corrected.
    fn stage(
        &mut self,
        t: f64,
        min_iou: f64,
        fuse: bool,
        buffered: bool,
        trk: impl Fn(&TrackSlot) -> bool,
        det: impl Fn(&Detection) -> bool,
    ) {
        self.rows.clear();
        self.cols.clear();
        for (j, tr) in self.tracks.iter().enumerate() {
            if !self.trk_used[j] && trk(tr) {
                let _ = self.rows.push(j as u16);
            }
        }
        for (i, d) in self.dets.iter().enumerate() {
            if !self.det_used[i] && det(d) {
                let _ = self.cols.push(i as u16);
            }
        }
        let (nr, nc) = (self.rows.len(), self.cols.len());
        if nr == 0 || nc == 0 {
            return;
        }
        let dw = self.cfg.depth_weight;
        for (a, &j) in self.rows.iter().enumerate() {
            let tr = &self.tracks[j as usize];
            // Only tentative tracks (velocity still unknown) get the buffer: on confirmed and lost
            // tracks it caused wrong matches when measured on mot15.
            let buf = if buffered && tr.state == TrackState::Tentative {
                (self.cfg.buffer_rate * (t - tr.t_last)).min(self.cfg.buffer_max)
            } else {
                0.0
            };
            let tb = widen(&tr.pred, buf);
            for (b, &i) in self.cols.iter().enumerate() {
                let d = &self.dets[i as usize];
                let iou = if buf > 0.0 { tb.iou(&widen(&d.bbox, buf)) } else { tr.pred.iou(&d.bbox) };
                let c = if iou < min_iou {
                    BIG
                } else {
                    let mut c = 1.0 - if fuse { iou * d.score } else { iou };
                    if dw > 0.0
                        && let (Some(zt), Some(zd)) = (tr.depth, d.depth.map(|m| m.get()))
                    {
                        c += dw * ((zd - zt).abs() / zt.abs().max(0.1)).min(1.0);
                    }
                    c
                };
                // A non-finite cost (bad depth) would break the solver's invariants: forbid the pair.
                self.cost[a * nc + b] = if c.is_finite() { c } else { BIG };
            }
        }
        self.solve_sparse(nr, nc);
        for a in 0..nr {
            let b = self.row_to_col[a];
            if b == UNASSIGNED || self.cost[a * nc + b] >= BIG {
                continue;
            }
            let (j, i) = (self.rows[a] as usize, self.cols[b] as usize);
            self.trk_used[j] = true;
            self.det_used[i] = true;
            let d = self.dets[i];
            let min_hits = self.cfg.min_hits;
            let tr = &mut self.tracks[j];
            tr.correct(&d);
            tr.hits += 1;
            tr.hit_streak += 1;
            tr.tsu = 0;
            tr.t_last = t;
            tr.state = match tr.state {
                TrackState::Tentative if tr.hits < min_hits => TrackState::Tentative,
                _ => TrackState::Confirmed,
            };
        }
    }

    /// Assignment on `cost[..nr * nc]` (entries `>= BIG` are forbidden) into `row_to_col`. Rows and
    /// columns without any allowed entry are left out of the solve, and when no row or column has
    /// two allowed entries the pairs are taken directly: the same optimum, much less work in sparse
    /// scenes.
    fn solve_sparse(&mut self, nr: usize, nc: usize) {
        self.row_to_col[..nr].fill(UNASSIGNED);
        self.cnt_c[..nc].fill(0);
        let (mut max_r, mut max_c) = (0u16, 0u16);
        for a in 0..nr {
            let mut n = 0u16;
            for b in 0..nc {
                if self.cost[a * nc + b] < BIG {
                    n += 1;
                    self.cnt_c[b] += 1;
                    max_c = max_c.max(self.cnt_c[b]);
                }
            }
            self.cnt_r[a] = n;
            max_r = max_r.max(n);
        }
        if max_r == 0 {
            return;
        }
        if max_r == 1 && max_c == 1 {
            for a in 0..nr {
                if self.cnt_r[a] == 1 {
                    self.row_to_col[a] = (0..nc).find(|&b| self.cost[a * nc + b] < BIG).unwrap_or(UNASSIGNED);
                }
            }
            return;
        }
        let (mut rn, mut cn) = (0, 0);
        for a in 0..nr {
            if self.cnt_r[a] > 0 {
                self.rmap[rn] = a as u16;
                rn += 1;
            }
        }
        for b in 0..nc {
            if self.cnt_c[b] > 0 {
                self.cmap[cn] = b as u16;
                cn += 1;
            }
        }
        let (cost, rmap, cmap) = (&self.cost, &self.rmap, &self.cmap);
        let f = |a: usize, b: usize| cost[rmap[a] as usize * nc + cmap[b] as usize];
        let mut reduced = [UNASSIGNED; MAX_TRACKS];
        if rn <= MAX_TRACKS {
            self.assigner.solve(&f, rn, cn, &mut reduced);
            for a in 0..rn {
                if reduced[a] != UNASSIGNED {
                    self.row_to_col[rmap[a] as usize] = cmap[reduced[a]] as usize;
                }
            }
        } else {
            self.assigner.solve(&|a, b| cost[a * nc + b], nr, nc, &mut self.row_to_col);
        }
    }

    /// ByteTrack-style update after prediction.
    fn update_byte(&mut self, t: f64) {
        let c = self.cfg;
        let (nd, nt) = (self.dets.len(), self.tracks.len());
        self.det_used[..nd].fill(false);
        self.trk_used[..nt].fill(false);
        let hi = c.track_threshold;
        // 1: confirmed and lost tracks with high-score detections.
        self.stage(t, c.iou_threshold, c.fuse_score, false, |tr| tr.state != TrackState::Tentative, |d| d.score >= hi);
        // 2: still-tracked tracks with low-score detections (occluded fish score low).
        self.stage(t, c.low_iou_threshold, false, false, |tr| tr.state == TrackState::Confirmed, |d| d.score < hi);
        // 3: tentative tracks with the remaining high-score detections.
        self.stage(
            t,
            c.unconfirmed_iou_threshold,
            c.fuse_score,
            true,
            |tr| tr.state == TrackState::Tentative,
            |d| d.score >= hi,
        );
        // Unmatched: tentative tracks die, confirmed ones become lost, lost ones expire.
        let mut j = nt;
        while j > 0 {
            j -= 1;
            if self.trk_used[j] {
                continue;
            }
            let tr = &mut self.tracks[j];
            let expired = t - tr.t_last > c.max_age_s + 1e-9;
            if tr.state == TrackState::Tentative || expired {
                self.tracks.remove(j);
            } else {
                tr.state = TrackState::Lost;
                tr.hit_streak = 0;
            }
        }
        for i in 0..nd {
            if !self.det_used[i] && self.dets[i].score >= hi && self.dets[i].score >= c.new_track_threshold {
                let d = self.dets[i];
                self.new_track(t, &d);
            }
        }
        self.outputs.clear();
        for tr in &self.tracks {
            if tr.state == TrackState::Confirmed && tr.t_last == t {
                let _ = self.outputs.push(Self::output_of(tr, t));
            }
        }
    }
}

/// The box widened by `b` times its width and height on each side (C-BIoU's buffer).
fn widen(p: &PixelBox, b: f64) -> PixelBox {
    PixelBox::new(p.x - b * p.w, p.y - b * p.h, p.w * (1.0 + 2.0 * b), p.h * (1.0 + 2.0 * b))
}

/// SORT's `iou_batch` for one pair (corners, no clamping of the union).
fn sort_iou(a: &PixelBox, b: &PixelBox) -> f64 {
    let (ax2, ay2, bx2, by2) = (a.x + a.w, a.y + a.h, b.x + b.w, b.y + b.h);
    let w = (ax2.min(bx2) - a.x.max(b.x)).max(0.0);
    let h = (ay2.min(by2) - a.y.max(b.y)).max(0.0);
    let wh = w * h;
    wh / ((ax2 - a.x) * (ay2 - a.y) + (bx2 - b.x) * (by2 - b.y) - wh)
}
