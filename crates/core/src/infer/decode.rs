//! Decoding of the Ultralytics YOLOv8/YOLO11 detection head output and non-maximum suppression,
//! both in place in caller-owned buffers (no allocation once the buffers have grown).
//!
//! Output layout `[1, 4 + nc, N]`: rows 0-3 are `cx, cy, w, h` in letterboxed input pixels, rows
//! `4..4+nc` the per-class scores (already sigmoided; no objectness, no NMS in the graph).

use super::letterbox::Letterbox;
pub use crate::detection::Detection;

/// Decodes a `[4 + nc, n]` row-major head output (batch dimension stripped) into `out` (cleared
/// first): one candidate per anchor whose best class score is at least `conf`, its box mapped back
/// through the letterbox `lb` but not yet clipped (run [`nms`], then [`clip_to_frame`]).
/// Non-finite or empty boxes are dropped.
pub fn decode_yolo(output: &[f32], nc: usize, n: usize, conf: f32, lb: &Letterbox, out: &mut Vec<Detection>) {
    out.clear();
    if nc == 0 || output.len() < (4 + nc) * n {
        return;
    }
    let row = |r: usize| &output[r * n..(r + 1) * n];
    let (cx, cy, w, h) = (row(0), row(1), row(2), row(3));
    for j in 0..n {
        let mut best = f32::NEG_INFINITY;
        let mut class = 0usize;
        for c in 0..nc {
            let s = output[(4 + c) * n + j];
            if s > best {
                best = s;
                class = c;
            }
        }
        if best.is_nan() || best < conf {
            continue;
        }
        if !(cx[j].is_finite() && cy[j].is_finite() && w[j] > 0.0 && h[j] > 0.0 && w[j].is_finite() && h[j].is_finite())
        {
            continue;
        }
        let bbox = lb.to_frame_unclipped(cx[j], cy[j], w[j], h[j]);
        out.push(Detection { bbox, score: f64::from(best), class: class as u16, depth: None });
    }
}

/// Greedy non-maximum suppression in place: sorts `dets` by descending score, keeps at most
/// `max_candidates` of them, then drops every box whose IoU with a higher-scoring kept box of the
/// same class (any class when `agnostic`) exceeds `iou`; at most `max_det` survive. Same rule as
/// Ultralytics' `non_max_suppression` (torchvision `nms` with class offsets).
pub fn nms(dets: &mut Vec<Detection>, iou: f64, agnostic: bool, max_candidates: usize, max_det: usize) {
    dets.sort_unstable_by(|a, b| b.score.total_cmp(&a.score));
    dets.truncate(max_candidates);
    let mut kept = 0usize;
    for i in 0..dets.len() {
        if kept >= max_det {
            break;
        }
        let d = dets[i];
        let suppressed = dets[..kept].iter().any(|k| (agnostic || k.class == d.class) && k.bbox.iou(&d.bbox) > iou);
        if !suppressed {
            dets[kept] = d;
            kept += 1;
        }
    }
    dets.truncate(kept);
}

/// Clips every box to the frame of `lb` and drops boxes left empty (entirely in the padding or
/// outside the frame). Order is kept.
pub fn clip_to_frame(dets: &mut Vec<Detection>, lb: &Letterbox) {
    dets.retain_mut(|d| {
        d.bbox = lb.clip(&d.bbox);
        d.bbox.w > 0.0 && d.bbox.h > 0.0
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PixelBox;

    fn det(x: f64, score: f64, class: u16) -> Detection {
        Detection { class, ..Detection::new(PixelBox::new(x, 0.0, 10.0, 10.0), score) }
    }

    #[test]
    fn nms_keeps_best_of_overlapping_same_class() {
        let mut d = vec![det(1.0, 0.6, 0), det(0.0, 0.9, 0), det(50.0, 0.5, 0), det(0.5, 0.8, 1)];
        nms(&mut d, 0.5, false, 100, 100);
        assert_eq!(d.len(), 3);
        assert_eq!(d[0].score, 0.9);
        assert_eq!(d[1].class, 1); // other class survives class-aware NMS
        let mut d2 = vec![det(1.0, 0.6, 0), det(0.0, 0.9, 0), det(50.0, 0.5, 0), det(0.5, 0.8, 1)];
        nms(&mut d2, 0.5, true, 100, 100);
        assert_eq!(d2.len(), 2);
    }

    #[test]
    fn nms_respects_limits() {
        let mut d: Vec<_> = (0..10).map(|i| det(i as f64 * 20.0, i as f64 / 10.0, 0)).collect();
        nms(&mut d, 0.5, false, 5, 3);
        assert_eq!(d.iter().map(|d| d.score).collect::<Vec<_>>(), vec![0.9, 0.8, 0.7]);
    }

    #[test]
    fn decode_picks_best_class_and_unletterboxes() {
        // Two anchors, two classes. Identity letterbox 100x100.
        let lb = Letterbox::new((100, 100), (100, 100));
        #[rustfmt::skip]
        let out = [
            50.0, 10.0, // cx
            50.0, 10.0, // cy
            20.0, 4.0,  // w
            10.0, 4.0,  // h
            0.1, 0.2,   // class 0
            0.7, 0.1,   // class 1
        ];
        let mut v = Vec::new();
        decode_yolo(&out, 2, 2, 0.25, &lb, &mut v);
        clip_to_frame(&mut v, &lb);
        assert_eq!(v.len(), 1);
        assert_eq!(v[0].class, 1);
        assert_eq!(v[0].bbox, PixelBox::new(40.0, 45.0, 20.0, 10.0));
    }
}
