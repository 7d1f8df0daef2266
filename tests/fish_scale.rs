//! `depth.scale`: the fish as the ruler (docs/pipeline.md, "The fish as the ruler"). The fish fit
//! recovers the metric scale on a scene without reference objects, `auto` turns to the fish when the
//! references are hidden, and the new keys validate. Relative depth is the ground truth's, turned
//! into an affine inverse depth (`--depth relative-gt`): no network is needed.

use fme::config::Config;
use fme::eval::{DepthChoice, EvalOptions, evaluate};
use fme::metric::DepthScale;
use fme::sequence::Sequence;
use fme::synth::fish::Cohort;
use fme::synth::{Layout, Preset, SynthConfig, generate};
use fme::units::Metres;

/// A 320 x 192 swarm of 20 fish, cohort 0.35 m +- 10 %, rendered into `dir`.
fn scene(dir: &tempfile::TempDir, frames: u32, seed: u64, layout: Layout) -> Sequence {
    let out = dir.path().join("seq");
    let cfg = SynthConfig {
        preset: Preset::Swarm,
        fish: 20,
        frames,
        seed,
        width: 320,
        height: 192,
        layout,
        cohort: Cohort { mean_length_m: 0.35, length_cv: 0.1 },
        ..SynthConfig::default()
    };
    generate(&cfg, &out, false, &|_| {}).unwrap();
    Sequence::open(&out).unwrap()
}

fn opts() -> EvalOptions {
    EvalOptions { depth: DepthChoice::RelativeGt, ..Default::default() }
}

#[test]
fn the_fish_fit_recovers_the_scale_without_references() {
    let dir = tempfile::tempdir().unwrap();
    let seq = scene(&dir, 150, 31, Layout::None);
    assert!(seq.meta.as_ref().expect("meta.json").reference_objects.is_empty());
    let r = evaluate(&seq, &Config::default(), &opts()).unwrap();
    assert_eq!(r.scale_source, "fish");
    assert_eq!(r.references_visible, 0);
    // The scale within 10 % (the cohort's lengths spread 10 %; the fit pools 20 fish).
    let ratio = r.mean_est_mps / r.mean_true_mps;
    assert!((ratio - 1.0).abs() < 0.1, "est {} true {}", r.mean_est_mps, r.mean_true_mps);
    assert!(r.speed_distcorr > 0.8, "distcorr {}", r.speed_distcorr);
    // Body lengths per second are scored against each fish's own length.
    assert!(r.bls_rmse.is_some_and(|e| e < 0.25), "{:?}", r.bls_rmse);
    // A configured length 10 % long scales the speed by 10 %; body lengths/s stay.
    let mut long = Config::default();
    long.motion.body_length_m = Metres(0.385);
    let l = evaluate(&seq, &long, &opts()).unwrap();
    let k = l.mean_est_mps / r.mean_est_mps;
    assert!((k - 1.1).abs() < 0.03, "speed ratio {k}");
    // `references` on a scene without any: no fit, nothing to score.
    let mut refs = Config::default();
    refs.depth.scale = DepthScale::References;
    assert!(evaluate(&seq, &refs, &opts()).is_err());
}

#[test]
fn a_long_scene_without_references_keeps_its_scale() {
    // 30 s without references: the fish's lengths measured through the fish fit's own depths read
    // long as the fit settles (+22 % on this scene before each fish was taken at the ruler length).
    let dir = tempfile::tempdir().unwrap();
    let seq = scene(&dir, 900, 33, Layout::None);
    let r = evaluate(&seq, &Config::default(), &opts()).unwrap();
    assert_eq!(r.scale_source, "fish");
    let ratio = r.mean_est_mps / r.mean_true_mps;
    assert!((ratio - 1.0).abs() < 0.06, "est {} true {}", r.mean_est_mps, r.mean_true_mps);
    assert!(r.speed_distcorr > 0.9, "distcorr {}", r.speed_distcorr);
}

#[test]
fn auto_turns_to_the_fish_when_the_references_are_hidden() {
    let seq = Sequence::open(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/swarm20")).unwrap();
    let cfg = Config::default();
    let clean = evaluate(&seq, &cfg, &opts()).unwrap();
    assert_eq!(clean.scale_source, "references");
    // 8 of the 10 references hidden after 1 s: too few for `auto`, which takes the fish (with the
    // two left); `references` goes on with two.
    let hidden = EvalOptions { hide_refs: Some((8, 1.0)), ..opts() };
    let auto = evaluate(&seq, &cfg, &hidden).unwrap();
    assert_eq!(auto.scale_source, "fish");
    assert!(auto.frames + 5 >= clean.frames, "{} vs {} frames", auto.frames, clean.frames);
    assert!(
        (auto.mean_est_mps - clean.mean_est_mps).abs() < 0.1 * clean.mean_est_mps,
        "{} vs {}",
        auto.mean_est_mps,
        clean.mean_est_mps
    );
    // All hidden: `references` keeps its last fit, `auto` fits on the fish alone.
    let all = EvalOptions { hide_refs: Some((10, 1.0)), ..opts() };
    assert_eq!(evaluate(&seq, &cfg, &all).unwrap().scale_source, "fish");
}

#[test]
fn auto_carries_the_references_scale_over_to_the_fish() {
    // While the references set the scale, `auto` measures the fish's length under their fit
    // (`depth.learn_fish_length`); when 8 of 10 are hidden, the fish fit goes on with that length, so
    // a configured length 10 % long costs (almost) nothing. Without the measured length it costs 10 %.
    let dir = tempfile::tempdir().unwrap();
    let seq = scene(&dir, 300, 32, Layout::F);
    let mut cfg = Config::default();
    cfg.motion.body_length_m = Metres(0.385);
    let clean = evaluate(&seq, &cfg, &opts()).unwrap();
    assert_eq!(clean.scale_source, "references");
    let hidden = EvalOptions { hide_refs: Some((8, 5.0)), ..opts() };
    let learned = evaluate(&seq, &cfg, &hidden).unwrap();
    assert_eq!(learned.scale_source, "fish");
    let mut fixed = cfg.clone();
    fixed.depth.learn_fish_length = false;
    let configured = evaluate(&seq, &fixed, &hidden).unwrap();
    assert_eq!(configured.scale_source, "fish");
    let shift = |r: &fme::eval::EvalReport| r.mean_est_mps / clean.mean_est_mps - 1.0;
    assert!(shift(&learned).abs() < 0.03, "learned: {:+.3}", shift(&learned));
    assert!(
        shift(&configured) > shift(&learned) + 0.02,
        "configured {:+.3}, learned {:+.3}",
        shift(&configured),
        shift(&learned)
    );
}

#[test]
fn the_scale_keys_validate() {
    let mut c = Config::default();
    assert_eq!(c.depth.scale, DepthScale::Auto);
    assert!((c.motion.body_length_cv - 0.1).abs() < 1e-12);
    c.depth.scale = DepthScale::Fish;
    assert!(c.validate().is_ok());
    c.motion.body_length_m = Metres(0.0);
    assert_eq!(c.validate().unwrap_err().key, "depth.scale");
    let mut c = Config::default();
    c.motion.body_length_cv = 0.9;
    assert_eq!(c.validate().unwrap_err().key, "motion.body_length_cv");
    let text = "[depth]\nscale = \"ruler\"\n";
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    std::fs::write(&p, text).unwrap();
    let e = Config::load_with(Some(&p), &[]).unwrap_err().to_string();
    assert!(e.contains("scale"), "{e}");
}

#[test]
fn eval_names_a_bad_refs_at_option() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_fme"))
        .args(["eval", "--sequence", concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/swarm20"), "--move-refs", "8"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--move-refs \"8\": expected N@T"), "{out:?}");
}
