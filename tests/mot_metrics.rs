//! MOT metrics on tiny hand-made cases with known answers.

use fme::geometry::PixelBox;
use fme::mot::MotAccumulator;

fn b(x: f64) -> PixelBox {
    PixelBox::new(x, 0.0, 10.0, 10.0)
}

#[test]
fn perfect_tracking() {
    let mut acc = MotAccumulator::new();
    for f in 0..5 {
        let x = f as f64;
        acc.update(&[(1, b(x)), (2, b(x + 100.0))], &[(7, b(x)), (8, b(x + 100.0))]);
    }
    let m = acc.metrics();
    assert_eq!((m.num_objects, m.num_matches, m.num_switches, m.num_false_positives, m.num_misses), (10, 10, 0, 0, 0));
    assert_eq!(m.mota, 1.0);
    assert_eq!(m.idf1, 1.0);
    assert_eq!(m.motp, 0.0);
    assert_eq!(m.mostly_tracked, 2);
}

#[test]
fn one_identity_switch() {
    // Object 1 is tracked by hypothesis 1 for 2 frames, then by hypothesis 2 for 2 frames.
    let mut acc = MotAccumulator::new();
    for f in 0..4 {
        let hid = if f < 2 { 1 } else { 2 };
        acc.update(&[(1, b(0.0))], &[(hid, b(0.0))]);
    }
    let m = acc.metrics();
    assert_eq!(m.num_switches, 1);
    assert_eq!(m.num_matches, 3);
    assert!((m.mota - 0.75).abs() < 1e-12); // 1 - 1/4
    // Best global id pairing covers 2 of 4 frames on each side: IDF1 = 2*2 / (4 + 4).
    assert_eq!(m.idtp, 2);
    assert!((m.idf1 - 0.5).abs() < 1e-12);
}

#[test]
fn misses_false_positives_iou_threshold_and_motp() {
    let mut acc = MotAccumulator::new();
    // Frame 1: shifted by 2 px -> IoU 80/120 = 2/3, distance 1/3: a match.
    acc.update(&[(1, b(0.0))], &[(1, b(2.0))]);
    // Frame 2: shifted by 4 px -> IoU 60/140 = 0.43 < 0.5: a miss and a false positive.
    acc.update(&[(1, b(0.0))], &[(1, b(4.0))]);
    // Frame 3: nothing tracked; an extra hypothesis far away.
    acc.update(&[(1, b(0.0))], &[(3, b(500.0))]);
    let m = acc.metrics();
    assert_eq!((m.num_matches, m.num_misses, m.num_false_positives, m.num_switches), (1, 2, 2, 0));
    assert!((m.mota - (1.0 - 4.0 / 3.0)).abs() < 1e-12);
    assert!((m.motp - 1.0 / 3.0).abs() < 1e-12);
    assert!((m.recall - 1.0 / 3.0).abs() < 1e-12);
    assert!((m.precision - 1.0 / 3.0).abs() < 1e-12);
    assert_eq!(m.mostly_lost, 0);
    assert_eq!(m.partially_tracked, 1); // 1 of 3 frames tracked
    // Exactly IoU 0.5 pairs (distance <= 0.5, motmetrics' rule): 10x10 vs 10x20 box.
    let mut acc = MotAccumulator::new();
    acc.update(&[(1, PixelBox::new(0.0, 0.0, 10.0, 10.0))], &[(1, PixelBox::new(0.0, 0.0, 10.0, 20.0))]);
    assert_eq!(acc.metrics().num_matches, 1);
}

#[test]
fn previous_correspondences_are_kept_over_a_better_fit() {
    // Object 1 was matched to hypothesis 1; next frame hypothesis 2 fits it better but 1 still
    // pairs: CLEAR MOT keeps 1 (no switch) and hypothesis 2 is a false positive.
    let mut acc = MotAccumulator::new();
    acc.update(&[(1, b(0.0))], &[(1, b(0.0))]);
    acc.update(&[(1, b(0.0))], &[(1, b(2.0)), (2, b(0.0))]);
    let m = acc.metrics();
    assert_eq!((m.num_matches, m.num_switches, m.num_false_positives), (2, 0, 1));
}

#[test]
fn fragmentation_and_assignment_maximises_matches() {
    let mut acc = MotAccumulator::new();
    // Two objects, two hypotheses; greedy on distance would pair (1,a) and leave 2 alone.
    // Object 1 at x=0, object 2 at x=4; hyp a at x=2 (pairs with both), hyp b at x=-2 (only 1).
    acc.update(&[(1, b(0.0)), (2, b(4.0))], &[(10, b(2.0)), (11, b(-2.0))]);
    let m = acc.metrics();
    assert_eq!(m.num_matches, 2, "{m:?}");
    let mut acc = MotAccumulator::new();
    for f in 0..5 {
        let hyp: Vec<(i64, PixelBox)> = if f == 2 { vec![] } else { vec![(1, b(0.0))] };
        acc.update(&[(1, b(0.0))], &hyp);
    }
    assert_eq!(acc.metrics().num_fragmentations, 1);
}

#[test]
fn hota_known_answers() {
    // Perfect tracking: HOTA = DetA = AssA = 1.
    let mut acc = MotAccumulator::new();
    for f in 0..4 {
        acc.update(&[(1, b(f as f64))], &[(5, b(f as f64))]);
    }
    let m = acc.metrics();
    assert!((m.hota - 1.0).abs() < 1e-12 && (m.deta - 1.0).abs() < 1e-12 && (m.assa - 1.0).abs() < 1e-12);
    // One object, perfect boxes, identity split in half (HOTA paper's example): DetA 1,
    // AssA = (2 * 2/4 + 2 * 2/4) / 4 = 0.5, HOTA = sqrt(0.5).
    let mut acc = MotAccumulator::new();
    for f in 0..4 {
        acc.update(&[(1, b(0.0))], &[(if f < 2 { 1 } else { 2 }, b(0.0))]);
    }
    let m = acc.metrics();
    assert!((m.deta - 1.0).abs() < 1e-12, "{m:?}");
    assert!((m.assa - 0.5).abs() < 1e-12, "{m:?}");
    assert!((m.hota - 0.5f64.sqrt()).abs() < 1e-12, "{m:?}");
    // Half the frames detected, one identity: DetA 0.5, AssA = 2 / (4 + 2 - 2) = 0.5.
    let mut acc = MotAccumulator::new();
    for f in 0..4 {
        let hyp: Vec<(i64, fme::geometry::PixelBox)> = if f < 2 { vec![(1, b(0.0))] } else { vec![] };
        acc.update(&[(1, b(0.0))], &hyp);
    }
    let m = acc.metrics();
    assert!((m.deta - 0.5).abs() < 1e-12 && (m.assa - 0.5).abs() < 1e-12, "{m:?}");
    // IoU 2/3 (2 px shift of a 10 px box): TP for alpha <= 0.65 (13 of 19 alphas).
    let mut acc = MotAccumulator::new();
    acc.update(&[(1, b(0.0))], &[(1, b(2.0))]);
    let m = acc.metrics();
    assert!((m.deta - 13.0 / 19.0).abs() < 1e-12, "{m:?}");
}
