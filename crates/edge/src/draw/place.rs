//! Greedy label placement: each label takes the first of its candidate positions that lies inside
//! the picture and overlaps no box already taken (other labels, the top bar, the legend); a label
//! with no free position is dropped and counted, so the picture can say how many are hidden.

/// An axis-aligned rectangle, px (x right, y down; `w`, `h` >= 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Left.
    pub x: i64,
    /// Top.
    pub y: i64,
    /// Width.
    pub w: i64,
    /// Height.
    pub h: i64,
}

impl Rect {
    /// A rectangle from its top-left corner and size.
    pub const fn new(x: i64, y: i64, w: i64, h: i64) -> Self {
        Self { x, y, w, h }
    }

    /// True when the two share any pixel.
    pub fn overlaps(&self, o: &Rect) -> bool {
        self.x < o.x + o.w && o.x < self.x + self.w && self.y < o.y + o.h && o.y < self.y + self.h
    }

    /// True when `self` lies wholly inside `o`.
    pub fn inside(&self, o: &Rect) -> bool {
        self.x >= o.x && self.y >= o.y && self.x + self.w <= o.x + o.w && self.y + self.h <= o.y + o.h
    }
}

/// Positions for a `w` x `h` label next to `anchor` (a box or a point as a 0-size box), best
/// first: above and below its left edge, then to the right and left, then the other corners.
pub fn candidates(anchor: Rect, w: i64, h: i64, gap: i64) -> [Rect; 8] {
    let (ax0, ay0, ax1, ay1) = (anchor.x, anchor.y, anchor.x + anchor.w, anchor.y + anchor.h);
    [
        Rect::new(ax0, ay0 - gap - h, w, h),
        Rect::new(ax0, ay1 + gap, w, h),
        Rect::new(ax1 + gap, ay0, w, h),
        Rect::new(ax0 - gap - w, ay0, w, h),
        Rect::new(ax1 - w, ay0 - gap - h, w, h),
        Rect::new(ax1 - w, ay1 + gap, w, h),
        Rect::new(ax1 + gap, ay1 - h, w, h),
        Rect::new(ax0 - gap - w, ay1 - h, w, h),
    ]
}

/// The taken boxes of one picture.
#[derive(Debug, Clone)]
pub struct Placer {
    bounds: Rect,
    taken: Vec<Rect>,
    /// Labels that found no free position.
    pub dropped: usize,
}

impl Placer {
    /// An empty picture of `bounds`.
    pub fn new(bounds: Rect) -> Self {
        Self { bounds, taken: Vec::new(), dropped: 0 }
    }

    /// Marks `r` taken (a bar, a legend) without checking it.
    pub fn block(&mut self, r: Rect) {
        self.taken.push(r);
    }

    /// The boxes taken so far.
    pub fn taken(&self) -> &[Rect] {
        &self.taken
    }

    /// Takes the first candidate inside the picture that overlaps nothing taken, preferring one that
    /// also keeps clear of `avoid` (the marks themselves: covering a fish is allowed, overlapping a
    /// label is not). None (and counted) when no candidate is free.
    pub fn place(&mut self, cands: &[Rect], avoid: &[Rect]) -> Option<Rect> {
        let free = |r: &&Rect| r.inside(&self.bounds) && !self.taken.iter().any(|t| t.overlaps(r));
        let best = cands
            .iter()
            .filter(free)
            .find(|r| !avoid.iter().any(|a| a.overlaps(r)))
            .or_else(|| cands.iter().find(free))
            .copied();
        match best {
            Some(r) => self.taken.push(r),
            None => self.dropped += 1,
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crowded_labels_never_overlap_and_the_rest_are_counted() {
        let mut p = Placer::new(Rect::new(0, 0, 320, 200));
        p.block(Rect::new(0, 0, 320, 20));
        // A school: 40 boxes packed into one corner, each wanting a 60x12 label.
        let boxes: Vec<Rect> = (0..40).map(|i| Rect::new(40 + (i % 8) * 12, 60 + (i / 8) * 10, 14, 10)).collect();
        let mut placed = 0;
        for b in &boxes {
            if p.place(&candidates(*b, 60, 12, 2), &boxes).is_some() {
                placed += 1;
            }
        }
        assert!(placed >= 4, "some labels placed: {placed}");
        assert_eq!(placed + p.dropped, boxes.len(), "every label placed or counted");
        let t = p.taken();
        for (i, a) in t.iter().enumerate() {
            assert!(a.inside(&Rect::new(0, 0, 320, 200)), "{a:?} inside the picture");
            for b in &t[i + 1..] {
                assert!(!a.overlaps(b), "{a:?} overlaps {b:?}");
            }
        }
    }

    #[test]
    fn a_label_moves_aside_rather_than_overlap() {
        let mut p = Placer::new(Rect::new(0, 0, 200, 200));
        let a = Rect::new(50, 50, 20, 20);
        let first = p.place(&candidates(a, 40, 10, 2), &[]).expect("free");
        assert_eq!(first, Rect::new(50, 38, 40, 10), "above the box first");
        let second = p.place(&candidates(Rect::new(55, 52, 20, 20), 40, 10, 2), &[]).expect("room below");
        assert!(!first.overlaps(&second), "{first:?} {second:?}");
        // Near the top edge the label goes below.
        let top = p.place(&candidates(Rect::new(150, 2, 20, 20), 40, 10, 2), &[]).expect("room");
        assert!(top.y > 2, "{top:?}");
    }
}
