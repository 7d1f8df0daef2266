//! Sampling a relative depth map at a pixel with a small robust window.

use crate::geometry::{Pixel, PixelBox};

/// How a fish's depth is read from a depth map (`depth.sample`, `fme eval --depth-sample`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthSample {
    /// A small median window at the (corrected) box centre: the paper's "depth at the centre point".
    Centre,
    /// A quantile over the central half of the box taking its nearest quarter (`sample_box_quantile`):
    /// the fish, not the water or wall behind a thin or bent fish.
    Box,
    /// As `Box`, but only where no other fish's box covers the core (`sample_box_quantile_visible`):
    /// a fish partly hidden behind another is read where it is seen, not on the fish in front. A fish
    /// that another box covers gets no depth in that frame when fewer than `MIN_VISIBLE_POINTS` of
    /// its 81 grid points are left uncovered (and inside the image), or fewer than
    /// `MIN_VISIBLE_POINTS_BEHIND` while the map shows one of the fish covering it nearer than it
    /// (`behind_a_nearer_fish`): the estimator skips it, and its speed resumes from its last
    /// position when it is seen again. At most `MAX_OVERLAPS` other boxes are considered per fish.
    Visible,
}

impl crate::choice::Choice for DepthSample {
    const ALL: &'static [Self] = &[Self::Centre, Self::Box, Self::Visible];
}

/// Uncovered grid points (of 81) [`DepthSample::Visible`] needs to read a covered fish. Chosen on
/// set 7021's swarms (seeds 7031-7033, groups B and D: 8, 15, 22, 30 and 50 tried; 15 best; 30 and
/// 50 leave out so many fish that the swarm mean is biased low, 8 lets the fish in front back in).
pub const MIN_VISIBLE_POINTS: usize = 15;

/// Uncovered grid points (of 81) [`DepthSample::Visible`] needs to read a covered fish that the map
/// shows behind one of the fish covering it. What is seen of such a fish is a sliver along the
/// edge of the fish in front, where the depth network blurs the two (on the 60-fish swarm s7033,
/// the 2,855 readings this leaves out were 0.68 m off the body centre). 30 was set on seed sets
/// 7021 and 7041 (40 tried as well) and checked on sets 7061 and 7081 (docs/lab-notes/2026-12-depth.md, "Fish behind fish").
pub const MIN_VISIBLE_POINTS_BEHIND: usize = 30;

/// Fraction of a box (each side, about its centre) whose grid the box samplers read: the fish's
/// core, where a bent or thin fish still is and the water beside it mostly is not.
pub const CORE_FRAC: f64 = 0.5;

/// What a map holds, which says where its near quarter is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapKind {
    /// Relative inverse depth (a depth network's output): larger is nearer.
    InverseDepth,
    /// Metric depth (camera z): smaller is nearer.
    Depth,
}

impl MapKind {
    /// The quantile that is the near quarter of the values.
    pub fn near_quarter(self) -> f64 {
        match self {
            MapKind::InverseDepth => 0.75,
            MapKind::Depth => 0.25,
        }
    }
}

/// One fish's value from a map, read the way `how` says: `centre()` for [`DepthSample::Centre`]
/// (the caller's window at the corrected centre), else the near quarter of `bbox`'s core read
/// through `at`, for [`DepthSample::Visible`] only where none of `others` (the other fish's boxes)
/// covers it, and not at all for a fish seen behind another with little of it left (see
/// [`DepthSample::Visible`]). The daemon and `fme eval` both read fish through this, so they cannot
/// drift apart.
pub fn sample_fish<'b, I>(
    how: DepthSample,
    kind: MapKind,
    bbox: &PixelBox,
    others: I,
    centre: impl FnOnce() -> Option<f64>,
    at: impl Fn(Pixel) -> Option<f64>,
) -> Option<f64>
where
    I: IntoIterator<Item = &'b PixelBox>,
    I::IntoIter: Clone,
{
    let q = kind.near_quarter();
    match how {
        DepthSample::Centre => centre(),
        DepthSample::Box => sample_box_quantile(bbox, CORE_FRAC, q, at),
        DepthSample::Visible => {
            let others = others.into_iter();
            let overlaps = Overlaps::collect(bbox, CORE_FRAC, others.clone());
            let keep = |p| !overlaps.covers(p);
            let (value, seen) = box_grid_quantile(bbox, CORE_FRAC, q, keep, MIN_VISIBLE_POINTS, &at)?;
            if overlaps.is_empty() || seen >= MIN_VISIBLE_POINTS_BEHIND {
                return Some(value);
            }
            (!behind_a_nearer_fish(kind, bbox, value, &overlaps, others, &at)).then_some(value)
        }
    }
}

/// True when the map shows one of the fish whose boxes cover `bbox`'s core (`overlaps`) nearer than
/// `value`, this fish's own visible reading: each covering fish is read as [`DepthSample::Visible`]
/// reads it (its core, less what the other boxes, this fish's included, cover). Which of two
/// overlapping fish is in front is not known from their boxes; on the 60-fish swarm s7033 this
/// test agreed with the truth for 91% of the covered fish. `others` are the other fish's boxes, as
/// given to [`sample_fish`]; a box equal to a covering one is taken for that fish. Allocation-free.
pub fn behind_a_nearer_fish<'b>(
    kind: MapKind,
    bbox: &PixelBox,
    value: f64,
    overlaps: &Overlaps,
    others: impl Iterator<Item = &'b PixelBox> + Clone,
    at: &impl Fn(Pixel) -> Option<f64>,
) -> bool {
    let q = kind.near_quarter();
    overlaps.boxes.iter().any(|front| {
        let mut covering = Overlaps::collect(front, CORE_FRAC, others.clone().filter(|b| *b != front));
        covering.offer(&core_of(front, CORE_FRAC), bbox);
        let keep = |p| !covering.covers(p);
        box_grid_quantile(front, CORE_FRAC, q, keep, MIN_VISIBLE_POINTS, at).is_some_and(|(w, _)| match kind {
            MapKind::InverseDepth => w > value,
            MapKind::Depth => w < value,
        })
    })
}

/// A borrowed single-channel map (relative inverse depth, or metric depth), row-major.
#[derive(Debug, Clone, Copy)]
pub struct RelativeMap<'a> {
    /// Row-major values, `width * height` of them; non-finite values mean "no data".
    pub data: &'a [f32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl<'a> RelativeMap<'a> {
    /// Wraps a row-major buffer; `None` when its length is not `width * height`.
    pub fn new(data: &'a [f32], width: usize, height: usize) -> Option<Self> {
        (width.checked_mul(height)? == data.len() && width > 0 && height > 0).then_some(Self { data, width, height })
    }

    /// Value of the pixel containing `px`, if inside the map and finite.
    #[inline]
    pub fn at(&self, px: Pixel) -> Option<f64> {
        if !px.is_finite() || px.u < 0.0 || px.v < 0.0 {
            return None;
        }
        let (x, y) = (px.u as usize, px.v as usize);
        if x >= self.width || y >= self.height {
            return None;
        }
        let v = self.data[y * self.width + x] as f64;
        v.is_finite().then_some(v)
    }
}

/// Largest supported window radius (a 9x9 window).
pub const MAX_RADIUS: usize = 4;

/// Median of the finite values in the `(2r+1) x (2r+1)` window centred on the pixel containing
/// `px` (clipped to the image), the paper's "sample R at the reference point" made robust to a
/// pixel or two of misregistration and to the object's edge. `values_ok` filters values (e.g.
/// "non-zero" for depth maps where 0 means no data). Returns `None` when no value qualifies or the
/// centre lies outside the map. `radius` is capped at [`MAX_RADIUS`]. Allocation-free.
pub fn sample_median(map: &RelativeMap<'_>, px: Pixel, radius: usize, values_ok: impl Fn(f32) -> bool) -> Option<f64> {
    if !px.is_finite() || px.u < 0.0 || px.v < 0.0 {
        return None;
    }
    let (cx, cy) = (px.u as usize, px.v as usize);
    if cx >= map.width || cy >= map.height {
        return None;
    }
    let r = radius.min(MAX_RADIUS);
    let mut buf = [0f32; (2 * MAX_RADIUS + 1) * (2 * MAX_RADIUS + 1)];
    let mut n = 0;
    for y in cy.saturating_sub(r)..=(cy + r).min(map.height - 1) {
        let row = &map.data[y * map.width..(y + 1) * map.width];
        for &v in &row[cx.saturating_sub(r)..=(cx + r).min(map.width - 1)] {
            if v.is_finite() && values_ok(v) {
                buf[n] = v;
                n += 1;
            }
        }
    }
    if n == 0 {
        return None;
    }
    let vals = &mut buf[..n];
    vals.sort_unstable_by(|a, b| a.total_cmp(b));
    let m = if n % 2 == 1 { vals[n / 2] as f64 } else { 0.5 * (vals[n / 2 - 1] as f64 + vals[n / 2] as f64) };
    Some(m)
}

/// The central `frac` of a box (each side, about its centre).
fn core_of(bbox: &PixelBox, frac: f64) -> PixelBox {
    let f = frac.clamp(0.0, 1.0);
    PixelBox::from_center(bbox.center(), bbox.w * f, bbox.h * f)
}

/// Most other boxes [`Overlaps`] keeps for one fish, in the order given. Past that (a wall of fish)
/// the rest are left out, and what they cover counts as visible: the fish may then be read on one
/// of them, as [`DepthSample::Box`] would.
pub const MAX_OVERLAPS: usize = 16;

/// Boxes of other fish that overlap the core of one fish's box (the part the samplers read): where
/// they cover it, the depth map may show those fish (in front) instead of this one. Which fish is in
/// front is not known, so every overlapping box counts: the fish in front loses the part of its core
/// it shares, and one whose core lies almost all inside a bigger box behind it loses its depth for
/// that frame too. Fixed capacity, allocation-free.
#[derive(Debug, Clone, Default)]
pub struct Overlaps {
    boxes: heapless::Vec<PixelBox, MAX_OVERLAPS>,
}

impl Overlaps {
    /// The boxes among `others` that intersect the central `frac` of `bbox` (pass the other fish
    /// only, not `bbox` itself); past [`MAX_OVERLAPS`] the rest are left out.
    pub fn collect<'b>(bbox: &PixelBox, frac: f64, others: impl IntoIterator<Item = &'b PixelBox>) -> Self {
        let core = core_of(bbox, frac);
        let mut overlaps = Self::default();
        for b in others {
            if !overlaps.offer(&core, b) {
                break;
            }
        }
        overlaps
    }

    /// Keeps `other` if it intersects `core` (from [`core_of`]); false once full (it was not kept).
    fn offer(&mut self, core: &PixelBox, other: &PixelBox) -> bool {
        let hit = other.is_valid()
            && other.x <= core.right()
            && core.x <= other.right()
            && other.y <= core.bottom()
            && core.y <= other.bottom();
        !hit || self.boxes.push(*other).is_ok()
    }

    /// True when another fish's box covers the pixel.
    #[inline]
    pub fn covers(&self, p: Pixel) -> bool {
        self.boxes.iter().any(|b| b.contains(p))
    }

    /// Number of overlapping boxes kept.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// True when no other box overlaps.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }
}

/// [`sample_box_quantile`] over the grid points that no other fish's box covers. When another box
/// covers any of them and fewer than `min_visible` uncovered points with data are left, `None`: the
/// fish is hidden, and whatever the map shows there is another fish. A fish partly hidden behind
/// another is read where it is seen, not on the fish in front (whose near quarter the plain quantile
/// picks). Where nothing covers it, this is exactly [`sample_box_quantile`]. `overlaps` should come
/// from [`Overlaps::collect`] with the same box and `frac`.
pub fn sample_box_quantile_visible(
    bbox: &PixelBox,
    frac: f64,
    q: f64,
    overlaps: &Overlaps,
    min_visible: usize,
    at: impl Fn(Pixel) -> Option<f64>,
) -> Option<f64> {
    box_grid_quantile(bbox, frac, q, |p| !overlaps.covers(p), min_visible, &at).map(|(v, _)| v)
}

/// A low quantile of the values on a 9x9 grid spread over the central `frac` of a box (clipped to
/// the image): a fish is nearer than the water or wall behind it, so a low quantile of the box's
/// core picks the fish where a centre sample of a thin or bent fish would hit the background.
/// `q` in `[0, 1]` (0.25 is a good default). `at` reads the map at a pixel (e.g.
/// `|p| map.at(p)`). Allocation-free; `None` when nothing qualifies.
pub fn sample_box_quantile(bbox: &PixelBox, frac: f64, q: f64, at: impl Fn(Pixel) -> Option<f64>) -> Option<f64> {
    box_grid_quantile(bbox, frac, q, |_| true, 1, &at).map(|(v, _)| v)
}

/// The `q` quantile of the values at the grid points `keep` accepts, and how many there were; `None`
/// when there are none, or when `keep` turned any point away and fewer than `min_kept` are left.
fn box_grid_quantile(
    bbox: &PixelBox,
    frac: f64,
    q: f64,
    keep: impl Fn(Pixel) -> bool,
    min_kept: usize,
    at: &impl Fn(Pixel) -> Option<f64>,
) -> Option<(f64, usize)> {
    if !bbox.is_valid() {
        return None;
    }
    const G: usize = 9;
    let c = bbox.center();
    let (hw, hh) = (0.5 * bbox.w * frac.clamp(0.0, 1.0), 0.5 * bbox.h * frac.clamp(0.0, 1.0));
    let mut buf = [0f64; G * G];
    let (mut n, mut turned_away) = (0, false);
    for j in 0..G {
        let v = c.v - hh + 2.0 * hh * j as f64 / (G - 1) as f64;
        for i in 0..G {
            let u = c.u - hw + 2.0 * hw * i as f64 / (G - 1) as f64;
            let p = Pixel::new(u, v);
            if !keep(p) {
                turned_away = true;
                continue;
            }
            if let Some(val) = at(p).filter(|x| x.is_finite()) {
                buf[n] = val;
                n += 1;
            }
        }
    }
    if n == 0 || (turned_away && n < min_kept) {
        return None;
    }
    let vals = &mut buf[..n];
    vals.sort_unstable_by(|a, b| a.total_cmp(b));
    let pos = q.clamp(0.0, 1.0) * (n - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some((vals[lo] + (vals[hi] - vals[lo]) * (pos - lo as f64), n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_ignores_an_outlier_pixel_and_nan() {
        let mut data = vec![1.0f32; 25];
        data[12] = 100.0; // the centre pixel is fouled
        data[0] = f32::NAN;
        let map = RelativeMap::new(&data, 5, 5).unwrap();
        assert_eq!(map.at(Pixel::new(2.5, 2.5)), Some(100.0));
        assert_eq!(sample_median(&map, Pixel::new(2.5, 2.5), 1, |_| true), Some(1.0));
        assert_eq!(sample_median(&map, Pixel::new(2.5, 2.5), 0, |_| true), Some(100.0));
        assert_eq!(sample_median(&map, Pixel::new(5.5, 2.5), 1, |_| true), None);
        assert_eq!(sample_median(&map, Pixel::new(-0.5, 2.5), 1, |_| true), None);
        assert_eq!(sample_median(&map, Pixel::new(0.5, 0.5), 1, |v| v > 1.0), None);
        assert!(RelativeMap::new(&data, 4, 5).is_none());
    }

    #[test]
    fn box_quantile_finds_a_thin_fish_in_front_of_the_wall() {
        // 20x20 wall at 5 m with a 2-pixel-high fish at 2 m along row 9-10 (the box centre row is 10).
        let mut data = vec![5.0f32; 400];
        for x in 4..16 {
            data[8 * 20 + x] = 2.0;
            data[9 * 20 + x] = 2.0;
        }
        let map = RelativeMap::new(&data, 20, 20).unwrap();
        let bbox = crate::geometry::PixelBox::new(4.0, 6.0, 12.0, 8.0);
        assert_eq!(sample_median(&map, bbox.center(), 2, |_| true), Some(5.0));
        assert_eq!(sample_box_quantile(&bbox, 0.5, 0.25, |p| map.at(p)), Some(2.0));
        assert_eq!(sample_box_quantile(&bbox, 0.5, 1.0, |p| map.at(p)), Some(5.0));
        let bad = crate::geometry::PixelBox::new(f64::NAN, 0.0, 1.0, 1.0);
        assert_eq!(sample_box_quantile(&bad, 0.5, 0.25, |p| map.at(p)), None);
    }

    /// A 20x20 metric depth map: wall at 5 m; fish A at 3 m fills x 2..14, y 4..16; fish B at 2 m in
    /// front of it fills x 8..18, y 4..16. A's core (central half: x 5..11) is covered by B's box
    /// from x 8 on. Returns the map's data and the boxes of A and B.
    fn half_hidden_fish() -> (Vec<f32>, PixelBox, PixelBox) {
        let mut data = vec![5.0f32; 400];
        for y in 4..16 {
            for x in 2..18 {
                data[y * 20 + x] = if x >= 8 { 2.0 } else { 3.0 };
            }
        }
        (data, PixelBox::new(2.0, 4.0, 12.0, 12.0), PixelBox::new(8.0, 4.0, 10.0, 12.0))
    }

    #[test]
    fn visible_quantile_reads_the_hidden_fish_not_the_one_in_front() {
        let (data, a, b) = half_hidden_fish();
        let map = RelativeMap::new(&data, 20, 20).unwrap();
        let far = PixelBox::new(0.0, 17.0, 3.0, 3.0);
        // The plain near quarter of A's core is fish B.
        assert_eq!(sample_box_quantile(&a, 0.5, 0.25, |p| map.at(p)), Some(2.0));
        let ov = Overlaps::collect(&a, 0.5, [&b, &far]);
        assert_eq!(ov.len(), 1, "the far box does not overlap A");
        assert!(ov.covers(Pixel::new(9.0, 10.0)) && !ov.covers(Pixel::new(6.0, 10.0)));
        // 4 of 9 grid columns (36 points) are uncovered: A is read where it is seen.
        assert_eq!(sample_box_quantile_visible(&a, 0.5, 0.25, &ov, MIN_VISIBLE_POINTS, |p| map.at(p)), Some(3.0));
        // Fewer uncovered points than asked for: A counts as hidden and gets no depth.
        assert_eq!(sample_box_quantile_visible(&a, 0.5, 0.25, &ov, 37, |p| map.at(p)), None);
        assert_eq!(sample_box_quantile_visible(&a, 0.5, 0.25, &ov, 36, |p| map.at(p)), Some(3.0));
        // B in front keeps reading itself: its uncovered part is B too.
        let ov_b = Overlaps::collect(&b, 0.5, [&a]);
        assert_eq!(sample_box_quantile_visible(&b, 0.5, 0.25, &ov_b, MIN_VISIBLE_POINTS, |p| map.at(p)), Some(2.0));
        // No overlaps: the same as the plain quantile.
        let none = Overlaps::collect(&a, 0.5, []);
        assert!(none.is_empty());
        assert_eq!(
            sample_box_quantile_visible(&a, 0.5, 0.25, &none, MIN_VISIBLE_POINTS, |p| map.at(p)),
            sample_box_quantile(&a, 0.5, 0.25, |p| map.at(p))
        );
    }

    #[test]
    fn sample_fish_dispatches_on_the_mode_and_the_map_kind() {
        // The same scene as metres and as 1/depth.
        let (metres, a, b) = half_hidden_fish();
        let inverse: Vec<f32> = metres.iter().map(|d| 1.0 / d).collect();
        let (m, inv) = (RelativeMap::new(&metres, 20, 20).unwrap(), RelativeMap::new(&inverse, 20, 20).unwrap());
        let read = |how, kind, map: &RelativeMap<'_>| sample_fish(how, kind, &a, [&b], || Some(-1.0), |p| map.at(p));
        assert_eq!(read(DepthSample::Centre, MapKind::Depth, &m), Some(-1.0), "the caller's centre reader");
        assert_eq!(read(DepthSample::Box, MapKind::Depth, &m), Some(2.0));
        assert_eq!(read(DepthSample::Visible, MapKind::Depth, &m), Some(3.0));
        // Larger inverse depth is nearer: the same fish either way.
        assert_eq!(read(DepthSample::Box, MapKind::InverseDepth, &inv), Some(0.5));
        assert_eq!(
            read(DepthSample::Visible, MapKind::InverseDepth, &inv).map(|r| (1.0 / r * 1e4).round() / 1e4),
            Some(3.0)
        );
    }

    /// A 20x20 metric depth map, wall at 5 m: fish A fills x 2..7, fish B x 7..19 (rows 4..16), at
    /// `a_m` and `b_m`. A's box (x 2..14) and B's (x 7..19) cover each other's cores but for 3 of 9
    /// grid columns: 27 points each, enough for [`MIN_VISIBLE_POINTS`] but not for
    /// [`MIN_VISIBLE_POINTS_BEHIND`].
    fn overlapping_fish(a_m: f32, b_m: f32) -> (Vec<f32>, PixelBox, PixelBox) {
        let mut data = vec![5.0f32; 400];
        for y in 4..16 {
            for x in 2..19 {
                data[y * 20 + x] = if x < 7 { a_m } else { b_m };
            }
        }
        (data, PixelBox::new(2.0, 4.0, 12.0, 12.0), PixelBox::new(7.0, 4.0, 12.0, 12.0))
    }

    #[test]
    fn a_fish_seen_behind_another_needs_more_of_itself_seen() {
        // A at 3 m behind B at 2 m: A gets no depth, B keeps its own.
        let (metres, a, b) = overlapping_fish(3.0, 2.0);
        let m = RelativeMap::new(&metres, 20, 20).unwrap();
        let visible = |fish: &PixelBox, other: &PixelBox, kind, map: &RelativeMap<'_>| {
            sample_fish(DepthSample::Visible, kind, fish, [other], || None, |p| map.at(p))
        };
        let ov_a = Overlaps::collect(&a, 0.5, [&b]);
        let seen = sample_box_quantile_visible(&a, 0.5, 0.25, &ov_a, MIN_VISIBLE_POINTS, |p| m.at(p));
        assert_eq!(seen, Some(3.0), "27 points are enough when nothing says A is behind");
        assert_eq!(sample_box_quantile_visible(&a, 0.5, 0.25, &ov_a, 28, |p| m.at(p)), None, "27 points");
        assert!(behind_a_nearer_fish(MapKind::Depth, &a, 3.0, &ov_a, [&b].into_iter(), &|p| m.at(p)));
        assert_eq!(visible(&a, &b, MapKind::Depth, &m), None);
        assert_eq!(visible(&b, &a, MapKind::Depth, &m), Some(2.0));
        // The same as inverse depth (larger is nearer).
        let inverse: Vec<f32> = metres.iter().map(|d| 1.0 / d).collect();
        let inv = RelativeMap::new(&inverse, 20, 20).unwrap();
        assert_eq!(visible(&a, &b, MapKind::InverseDepth, &inv), None);
        assert_eq!(visible(&b, &a, MapKind::InverseDepth, &inv), Some(0.5));
        // A in front of B: now B is the one left out.
        let (metres, a, b) = overlapping_fish(2.0, 3.0);
        let m = RelativeMap::new(&metres, 20, 20).unwrap();
        assert_eq!(visible(&a, &b, MapKind::Depth, &m), Some(2.0));
        assert_eq!(visible(&b, &a, MapKind::Depth, &m), None);
        // Both at the same depth: neither is behind the other.
        let (metres, a, b) = overlapping_fish(2.0, 2.0);
        let m = RelativeMap::new(&metres, 20, 20).unwrap();
        assert_eq!((visible(&a, &b, MapKind::Depth, &m), visible(&b, &a, MapKind::Depth, &m)), (Some(2.0), Some(2.0)));
        // A in front (2.5 m where seen, 2 m at x 7..12, inside B's core): B is read less A's box,
        // at 3 m, so A is not taken for a fish behind B because of its own pixels.
        let (mut metres, a, b) = overlapping_fish(2.5, 3.0);
        for y in 4..16 {
            for x in 7..12 {
                metres[y * 20 + x] = 2.0;
            }
        }
        let m = RelativeMap::new(&metres, 20, 20).unwrap();
        assert_eq!(visible(&a, &b, MapKind::Depth, &m), Some(2.5));
    }

    #[test]
    fn overlaps_keep_at_most_max_overlaps_and_skip_invalid_boxes() {
        let core = PixelBox::new(0.0, 0.0, 10.0, 10.0);
        let many = [PixelBox::new(1.0, 1.0, 2.0, 2.0); MAX_OVERLAPS + 5];
        assert_eq!(Overlaps::collect(&core, 1.0, many.iter()).len(), MAX_OVERLAPS);
        // Invalid boxes: a NaN corner, a negative width reaching back over the core.
        let odd = [PixelBox::new(f64::NAN, 1.0, 2.0, 2.0), PixelBox::new(5.0, 5.0, -2.0, 2.0)];
        assert!(Overlaps::collect(&core, 1.0, odd.iter()).is_empty());
        // Only the core counts: a box over the outer ring (x 0..2) of a 10-pixel box is not kept
        // for its central half (x 2.5..7.5), but is for the whole box.
        let ring = [PixelBox::new(0.0, 0.0, 2.0, 10.0)];
        assert!(Overlaps::collect(&core, 0.5, ring.iter()).is_empty());
        assert_eq!(Overlaps::collect(&core, 1.0, ring.iter()).len(), 1);
    }

    #[test]
    fn visible_quantile_is_the_plain_one_when_nothing_covers_the_core() {
        // A fish at the right edge of a 20x20 map: 2 of the 9 grid columns of its core are inside
        // (18 points), fewer than the 30 asked for here; that only matters once a box covers it.
        let data = vec![2.0f32; 400];
        let map = RelativeMap::new(&data, 20, 20).unwrap();
        let edge = PixelBox::new(12.0, 4.0, 24.0, 12.0);
        let plain = sample_box_quantile(&edge, 0.5, 0.25, |p| map.at(p));
        assert_eq!(plain, Some(2.0));
        let far_off = PixelBox::new(0.0, 0.0, 3.0, 3.0);
        let ov = Overlaps::collect(&edge, 0.5, [&far_off]);
        assert!(ov.is_empty());
        assert_eq!(sample_box_quantile_visible(&edge, 0.5, 0.25, &ov, 30, |p| map.at(p)), plain);
        // A box covering some of its core: now too few are left.
        let cover = PixelBox::new(17.0, 4.0, 2.0, 12.0);
        let ov = Overlaps::collect(&edge, 0.5, [&cover]);
        assert_eq!(ov.len(), 1);
        assert_eq!(sample_box_quantile_visible(&edge, 0.5, 0.25, &ov, 30, |p| map.at(p)), None);
    }

    #[test]
    fn median_of_even_count_is_mean_of_middle_two() {
        let data = [1.0f32, 2.0, 3.0, 4.0];
        let map = RelativeMap::new(&data, 2, 2).unwrap();
        assert_eq!(sample_median(&map, Pixel::new(0.5, 0.5), 1, |_| true), Some(2.5));
    }
}
