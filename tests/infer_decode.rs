//! Pure tests of the inference stage (no ONNX Runtime): letterbox round trips, YOLO decoding with
//! NMS, and the reduced-rate scheduler on real, jittery timestamps.

use fme::geometry::PixelBox;
use fme::infer::{InferSchedule, Letterbox, RateScheduler, decode_yolo, nms};
use fme::units::Seconds;

#[test]
fn letterbox_round_trip_for_common_frame_sizes() {
    let frames = [(1920, 1080), (1280, 720), (640, 480), (720, 1280), (333, 777), (64, 64)];
    let nets = [(640, 640), (320, 320), (320, 256), (96, 64)];
    for &src in &frames {
        for &dst in &nets {
            let lb = Letterbox::new(src, dst);
            assert!(lb.inner.0 <= dst.0 && lb.inner.1 <= dst.1, "{lb:?}");
            assert!(lb.pad.0 + lb.inner.0 <= dst.0 && lb.pad.1 + lb.inner.1 <= dst.1, "{lb:?}");
            // One side is filled (up to rounding) and the image is centred within a pixel.
            assert!(lb.inner.0 + 1 >= dst.0 || lb.inner.1 + 1 >= dst.1, "{lb:?}");
            let right = dst.0 - lb.inner.0 - lb.pad.0;
            let bottom = dst.1 - lb.inner.1 - lb.pad.1;
            assert!(right.abs_diff(lb.pad.0) <= 1 && bottom.abs_diff(lb.pad.1) <= 1, "{lb:?}");
            let b = PixelBox::new(src.0 as f64 * 0.3, src.1 as f64 * 0.4, src.0 as f64 * 0.2, src.1 as f64 * 0.1);
            let (cx, cy, w, h) = lb.to_input(&b);
            let back = lb.to_frame(cx, cy, w, h);
            let tol = 1e-3 * src.0.max(src.1) as f64;
            assert!(
                (back.x - b.x).abs() < tol
                    && (back.y - b.y).abs() < tol
                    && (back.w - b.w).abs() < tol
                    && (back.h - b.h).abs() < tol,
                "{src:?}->{dst:?}: {b:?} vs {back:?}"
            );
        }
    }
}

#[test]
fn boxes_in_the_padding_are_clipped_to_the_frame() {
    let lb = Letterbox::new((1280, 720), (640, 640)); // pad top 140
    let b = lb.to_frame(320.0, 100.0, 100.0, 100.0); // input y 50..150: mostly in the top pad
    assert_eq!(b.y, 0.0);
    assert!((b.h - 20.0).abs() < 1e-9, "{b:?}"); // (150 - 140) / 0.5
}

#[test]
fn decode_and_nms_on_a_crowded_one_class_head() {
    // 50 fish on a 10x5 grid, each predicted by 3 jittered anchors with decreasing scores, plus
    // 500 background anchors below the threshold: NMS must leave exactly one box per fish.
    let lb = Letterbox::new((640, 320), (640, 320));
    let n = 50 * 3 + 500;
    let mut out = vec![0f32; 5 * n];
    let mut j = 0;
    for fish in 0..50 {
        let (cx, cy) = (32.0 + 64.0 * (fish % 10) as f32, 32.0 + 64.0 * (fish / 10) as f32);
        for k in 0..3 {
            let jit = k as f32 * 1.5;
            for (r, v) in [cx + jit, cy - jit, 40.0, 30.0, 0.9 - 0.1 * k as f32].into_iter().enumerate() {
                out[r * n + j] = v;
            }
            j += 1;
        }
    }
    for b in j..n {
        for (r, v) in [100.0, 100.0, 20.0, 20.0, 0.1].into_iter().enumerate() {
            out[r * n + b] = v;
        }
    }
    let mut dets = Vec::new();
    decode_yolo(&out, 1, n, 0.25, &lb, &mut dets);
    assert_eq!(dets.len(), 150);
    nms(&mut dets, 0.5, false, 3000, 300);
    assert_eq!(dets.len(), 50);
    assert!(dets.iter().all(|d| (d.score - 0.9).abs() < 1e-6));
    for (a, da) in dets.iter().enumerate() {
        for db in &dets[a + 1..] {
            assert!(da.bbox.iou(&db.bbox) < 0.5);
        }
    }
}

#[test]
fn scheduler_rate_holds_for_non_multiple_frame_rates() {
    // 25 fps camera, detection at 10 Hz: runs every 2 or 3 frames, 10 per second on average.
    let mut s = RateScheduler::new(10.0);
    let fired: Vec<f64> = (0..250).map(|i| i as f64 / 25.0).filter(|t| s.due(Seconds(*t))).collect();
    assert_eq!(fired.len(), 100);
    for w in fired.windows(2) {
        let dt = w[1] - w[0];
        assert!((0.08 - 1e-9..=0.12 + 1e-9).contains(&dt), "gap {dt}");
    }
}

#[test]
fn scheduler_tolerates_jitter_and_recovers_from_gaps_and_restarts() {
    // 30 fps with +-3 ms timestamp jitter, 10 Hz: still every third frame (no drift, no skip).
    let mut s = RateScheduler::new(10.0);
    let jitter = [0.0, 0.003, -0.002, 0.001, -0.003, 0.002];
    let fired: Vec<usize> = (0..60)
        .filter(|&i| s.due(Seconds(i as f64 / 30.0 + jitter[i % jitter.len()] * (i > 0) as u8 as f64)))
        .collect();
    assert_eq!(fired.len(), 20, "{fired:?}");

    // A 2 s gap (camera stalled): the next frame runs, the schedule restarts from it.
    let mut s = RateScheduler::new(5.0);
    assert!(s.due(Seconds(0.0)));
    assert!(!s.due(Seconds(0.1)));
    assert!(s.due(Seconds(2.0)));
    assert!(!s.due(Seconds(2.15)));
    assert!(s.due(Seconds(2.2)));
    // Time going backwards (camera restarted its clock): run now and restart.
    assert!(s.due(Seconds(0.05)));
    assert!(!s.due(Seconds(0.1)));
    // Non-finite timestamps never run.
    assert!(!s.due(Seconds(f64::NAN)));
}

#[test]
fn detection_and_depth_run_at_their_own_rates() {
    let mut plan = InferSchedule::new(10.0, 2.0);
    let (mut det, mut dep) = (0, 0);
    for i in 0..300 {
        let p = plan.plan(Seconds(i as f64 / 30.0));
        det += p.detect as usize;
        dep += p.depth as usize;
        if p.depth {
            assert_eq!(i % 15, 0);
        }
    }
    assert_eq!((det, dep), (100, 20));
}
