//! The tracker on the recorded synthetic swarm `tests/data/swarm20` (20 fish, 120 frames, with
//! ground truth): detections from its ground truth with seeded noise, as `fme tune` makes them.

use fme::cli::tune::load_sequence;
use fme::track::TrackerConfig;
use fme::tune::{DetNoise, evaluate, synth_detections};
use std::path::Path;

#[test]
fn default_beats_sort_on_the_recorded_swarm() {
    let seq = load_sequence(Path::new("tests/data/swarm20"), 0.1).expect("recorded sequence loads");
    assert_eq!(seq.frames, 120);
    assert!(seq.gt.iter().all(|g| g.depth.is_some_and(|z| z > 0.0)), "depth from gt/world.csv + meta.json");
    for (noise, every) in [
        (DetNoise::default(), 1),
        (DetNoise { miss: 0.15, jitter: 0.08, fp_per_frame: 2.0, ..DetNoise::default() }, 1),
        (DetNoise { every: 3, ..DetNoise::default() }, 3),
    ] {
        let dets = synth_detections(&seq, &noise, 5);
        let d = evaluate(TrackerConfig::default_preset(), &seq, &dets, every);
        let s = evaluate(TrackerConfig::sort(), &seq, &dets, every);
        eprintln!(
            "{noise:?}: default IDF1 {:.3} MOTA {:.3} | sort IDF1 {:.3} MOTA {:.3}",
            d.idf1, d.mota, s.idf1, s.mota
        );
        assert!(d.idf1 > s.idf1, "{noise:?}: IDF1 default {} vs sort {}", d.idf1, s.idf1);
        assert!(d.mota > s.mota, "{noise:?}: MOTA default {} vs sort {}", d.mota, s.mota);
    }
}
