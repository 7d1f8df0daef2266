//! Tracker behaviour: lost-track recovery, detection every k-th frame, low-score second stage,
//! SORT output rule.

use fme::geometry::PixelBox;
use fme::track::{Detection, Tracker, TrackerConfig};
use fme::units::Seconds;

fn moving(t: f64, x0: f64, vx: f64, score: f64) -> Detection {
    Detection::new(PixelBox::new(x0 + vx * t, 100.0, 40.0, 40.0), score)
}

#[test]
fn default_recovers_a_track_after_a_gap_sort_does_not() {
    // One fish crosses at 120 px/s; the detector misses it for 10 frames (1/3 s).
    let run = |cfg: TrackerConfig| {
        let mut tr = Tracker::new(cfg);
        let mut ids = Vec::new();
        for k in 0..60 {
            let t = k as f64 / 30.0;
            let dets: Vec<Detection> = if (20..30).contains(&k) { vec![] } else { vec![moving(t, 0.0, 120.0, 0.9)] };
            for o in tr.update(Seconds(t), &dets).expect("ok") {
                ids.push((k, o.id));
            }
        }
        ids
    };
    let d = run(TrackerConfig::default_preset());
    assert!(d.iter().all(|&(_, id)| id == 1), "default must keep one identity: {d:?}");
    assert!(d.iter().any(|&(k, _)| k == 30), "recovered on the first frame back");
    let s = run(TrackerConfig::sort());
    assert!(s.iter().any(|&(_, id)| id != 1), "SORT starts a new identity after the gap: {s:?}");
    assert!(!s.iter().any(|&(k, _)| k == 30), "SORT needs min_hits again before reporting");
}

#[test]
fn lost_tracks_expire_after_max_lost() {
    let mut cfg = TrackerConfig::default_preset();
    cfg.max_age_s = 0.2;
    let mut tr = Tracker::new(cfg);
    let mut last = 0;
    for k in 0..40 {
        let t = k as f64 / 30.0;
        let dets: Vec<Detection> = if (10..25).contains(&k) { vec![] } else { vec![moving(t, 0.0, 30.0, 0.9)] };
        if let Some(o) = tr.update(Seconds(t), &dets).expect("ok").first() {
            last = o.id;
        }
        if (17..25).contains(&k) {
            assert_eq!(tr.live_tracks(), 0, "frame {k}: expired after 0.2 s");
        }
    }
    assert_eq!(last, 2, "a new identity after expiry");
}

#[test]
fn detection_every_third_frame_keeps_identities_of_fast_crossing_fish() {
    // Two fish on crossing paths, 300 px/s, boxes 40 px: between detections (0.1 s) they move 30 px.
    for k_det in [1usize, 3] {
        let mut tr = Tracker::new(TrackerConfig::default_preset());
        let mut seen = std::collections::BTreeSet::new();
        for f in (0..90).step_by(k_det) {
            let t = f as f64 / 30.0;
            let a = Detection::new(PixelBox::new(300.0 * t, 100.0 + 40.0 * t, 40.0, 40.0), 0.9);
            let b = Detection::new(PixelBox::new(900.0 - 300.0 * t, 100.0 + 40.0 * t, 40.0, 40.0), 0.9);
            for o in tr.update(Seconds(t), &[a, b]).expect("ok") {
                // Identity 1 is fish a (left to right); its box must stay on a's side of b.
                // (Skip the frames where the two boxes nearly coincide: no side to tell.)
                if (a.bbox.x - b.bbox.x).abs() < 20.0 {
                    continue;
                }
                let is_a = (o.bbox.x - a.bbox.x).abs() < (o.bbox.x - b.bbox.x).abs();
                seen.insert((o.id, is_a));
            }
        }
        assert_eq!(seen.len(), 2, "every {k_det}: two identities, each on its own fish: {seen:?}");
        let ids: std::collections::HashSet<u32> = seen.iter().map(|&(id, _)| id).collect();
        assert_eq!(ids.len(), 2, "every {k_det}: one id per fish, not one id on both: {seen:?}");
    }
}

#[test]
fn low_score_detections_extend_tracks_but_do_not_start_them() {
    let mut tr = Tracker::new(TrackerConfig::default_preset());
    let mut reported = 0;
    for k in 0..30 {
        let t = k as f64 / 30.0;
        // Occluded from frame 10 on: score drops to 0.3 (below track_threshold 0.5).
        let s = if k < 10 { 0.9 } else { 0.3 };
        let clutter = Detection::new(PixelBox::new(500.0, 500.0, 40.0, 40.0), 0.3);
        let out = tr.update(Seconds(t), &[moving(t, 0.0, 60.0, s), clutter]).expect("ok");
        reported += out.len();
        assert!(out.iter().all(|o| o.id == 1), "frame {k}: {out:?}");
    }
    assert_eq!(reported, 29);
}

#[test]
fn sort_output_rule_warm_up_and_min_hits() {
    let mut tr = Tracker::new(TrackerConfig::sort());
    let mut counts = Vec::new();
    for k in 0..6 {
        let mut dets = vec![moving(k as f64, 0.0, 5.0, 0.9)];
        if k >= 3 {
            dets.push(moving(k as f64, 400.0, 5.0, 0.9)); // appears after the warm-up
        }
        counts.push(tr.update(Seconds(k as f64), &dets).expect("ok").len());
    }
    // Frames 1-3 (warm-up): everything matched is reported. The second object appears at frame 4
    // and needs three consecutive hits after its creation: reported from frame 7 on, not here.
    assert_eq!(counts, vec![1, 1, 1, 1, 1, 1]);
    counts.clear();
    for k in 6..8 {
        let dets = [moving(k as f64, 0.0, 5.0, 0.9), moving(k as f64, 400.0, 5.0, 0.9)];
        counts.push(tr.update(Seconds(k as f64), &dets).expect("ok").len());
    }
    assert_eq!(counts, vec![2, 2]);
}

#[test]
fn confirmed_tracks_follow_predictions_between_detections() {
    let mut tr = Tracker::new(TrackerConfig::default_preset());
    for k in 0..10 {
        let t = k as f64 / 30.0;
        tr.update(Seconds(t), &[moving(t, 0.0, 90.0, 0.9)]).expect("ok");
    }
    let at_update = tr.confirmed().next().expect("one track");
    // No detection for the next frame: predict only; the box moves on by ~3 px, outputs() stays.
    tr.predict(Seconds(10.0 / 30.0)).expect("ok");
    let predicted = tr.confirmed().next().expect("one track");
    assert_eq!(predicted.id, at_update.id);
    assert!((predicted.bbox.x - at_update.bbox.x - 3.0).abs() < 0.5, "{} -> {}", at_update.bbox.x, predicted.bbox.x);
    assert!(predicted.age.get() > at_update.age.get());
    assert_eq!(tr.outputs()[0].bbox, at_update.bbox);
}
