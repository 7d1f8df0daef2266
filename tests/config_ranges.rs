//! Every numeric key of the configuration, fed 0, negative, tiny, huge, infinite and NaN values
//! through the same `--set` path the command line uses: either validation refuses the value and
//! names the key, or the daemon's timers and the per-frame stages build from it and run without a
//! panic. The keys are read from the serialized default configuration, so a key added later is
//! covered without touching this test.

use fme::config::Config;
use fme::geometry::{Camera, Intrinsics, PixelBox, Pose, WorldPoint};
use fme::infer::InferSchedule;
use fme::motion::{ActivityEstimator, Observation};
use fme::output::bank::RegisterBank;
use fme::output::feeding::FeedingRule;
use fme::service::publish::Publisher;
use fme::service::timing::Timing;
use fme::status::Shared;
use fme::track::{Detection, Tracker};
use fme::units::{Metres, Seconds};
use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

const FLOATS: &[&str] = &["0", "0.0", "-1", "-1.0", "1e-300", "1e300", "inf", "-inf", "nan"];
const INTEGERS: &[&str] = &["4294967295", "9223372036854775807"];

/// (dotted key, is an integer, is an array) of every numeric leaf of `v`.
fn numeric_leaves(prefix: &str, v: &toml::Value, out: &mut Vec<(String, bool, bool)>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                numeric_leaves(&key, v, out);
            }
        }
        toml::Value::Integer(_) => out.push((prefix.to_string(), true, false)),
        toml::Value::Float(_) => out.push((prefix.to_string(), false, false)),
        toml::Value::Array(a) if !a.is_empty() && a.iter().all(|x| x.is_float() || x.is_integer()) => {
            out.push((prefix.to_string(), a[0].is_integer(), true));
        }
        _ => {}
    }
}

fn camera() -> Camera {
    let k = Intrinsics::from_hfov(640, 384, 80.0).expect("intrinsics");
    let pose = Pose::look_at(WorldPoint::new(3.0, -0.5, 1.5), WorldPoint::new(3.0, 3.0, 1.2), nalgebra::Vector3::z())
        .expect("pose");
    Camera { intrinsics: k, pose }
}

/// What `fme run` builds from a configuration before and while it processes frames, without the
/// networks: the timers, the publisher, the schedules, the tracker, the speed estimator and the
/// feeding rule, each run for a few frames.
fn build_and_run(cfg: &Config) -> Result<(), String> {
    let timing = Timing::from_config(cfg).map_err(|e| e.to_string())?;
    let shared = Shared::new(String::new(), cfg.console.log_lines);
    let mut publisher = Publisher::new(cfg, &timing, Arc::new(RegisterBank::new()));
    let mut health = shared.health();
    let _ = publisher.update(&health, false, 0, Instant::now(), false);
    health.last_sample_at = Some(Instant::now());
    let _ = publisher.update(&health, true, 0, Instant::now() + Duration::from_secs(1), false);
    let _ = publisher.publish(&shared, Instant::now(), false);
    let mut schedule = InferSchedule::new(cfg.detector.rate_hz, cfg.depth.rate_hz);
    let mut tracker = Tracker::new(cfg.tracker);
    let mut est = ActivityEstimator::new(camera(), cfg.motion, cfg.postprocess);
    let mut feeding = FeedingRule::new(cfg.feeding.clone());
    for i in 0..40 {
        let t = Seconds(f64::from(i) / 30.0);
        let _ = schedule.plan(t);
        let x = 100.0 + 3.0 * f64::from(i);
        let dets = [Detection::new(PixelBox::new(x, 150.0, 60.0, 25.0), 0.9)];
        let tracks = tracker.update(t, &dets).map_err(|e| e.to_string())?;
        let obs: Vec<Observation> =
            tracks.iter().map(|o| Observation { id: o.id, bbox: o.bbox, depth: Some(Metres(2.0)) }).collect();
        let s = est.update(t, &obs);
        let _ = feeding.update(t.get(), s.smoothed.map(|v| v.get()));
    }
    Ok(())
}

#[test]
fn every_numeric_key_is_refused_by_name_or_runs_without_panic() {
    let defaults: toml::Value = toml::from_str(&Config::default().to_toml()).expect("the defaults read back");
    let mut leaves = Vec::new();
    numeric_leaves("", &defaults, &mut leaves);
    assert!(leaves.len() > 80, "only {} numeric keys found", leaves.len());
    let mut accepted = Vec::new();
    for (key, integer, array) in &leaves {
        let extra: &[&str] = if *integer { INTEGERS } else { &[] };
        for v in FLOATS.iter().chain(extra) {
            let value = if *array { format!("[{v}, {v}, {v}]") } else { (*v).to_string() };
            let set = format!("{key}={value}");
            match Config::load_with(None, std::slice::from_ref(&set)) {
                Err(e) => {
                    let msg = e.to_string();
                    assert!(msg.contains(key.as_str()), "--set {set}: refused without naming the key: {msg}");
                }
                Ok((cfg, _)) => {
                    let run = std::panic::catch_unwind(|| build_and_run(&cfg));
                    match run {
                        Ok(Ok(())) => accepted.push(set),
                        Ok(Err(e)) => panic!("--set {set}: accepted by validation but the daemon refuses it: {e}"),
                        Err(_) => panic!("--set {set}: accepted by validation but building or running panicked"),
                    }
                }
            }
        }
    }
    // The check must be able to see both outcomes.
    assert!(accepted.iter().any(|s| s == "record.freeze_min_gap_s=0"), "{accepted:?}");
    for refused in ["output.stale_after_s=1e300", "output.rate_hz=1e-300", "service.live_view_s=inf"] {
        assert!(!accepted.iter().any(|s| s == refused), "{refused} was accepted");
    }
}

#[test]
fn the_issue_values_are_refused_naming_the_key() {
    for (set, key) in [
        ("output.stale_after_s=1e20", "output.stale_after_s"),
        ("output.rate_hz=1e-20", "output.rate_hz"),
        ("service.stall_after_s=1e20", "service.stall_after_s"),
        ("service.live_view_s=inf", "service.live_view_s"),
        ("record.freeze_min_gap_s=1e20", "record.freeze_min_gap_s"),
    ] {
        let e = Config::load_with(None, &[set.to_string()]).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains(&format!("key `{key}`")) && e.contains("must be"), "{set}: {e:?}");
    }
}

#[test]
fn run_exits_2_naming_the_key() {
    let out = Command::new(env!("CARGO_BIN_EXE_fme"))
        .args(["run", "--source", "tests/data/swarm20", "--set", "output.stale_after_s=1e20"])
        .args(["--set", "output.modbus.mode=off", "--max-frames", "5"])
        .output()
        .expect("runs fme");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("output.stale_after_s"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}
