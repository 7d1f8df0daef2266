use super::*;
use crate::output::StatusBits;
use crate::status::FaultCode;
use fme_core::pipeline::ScaleSource;

fn row(fault: u16, feeding: bool) -> Update {
    Update {
        unix_ms: 4_102_444_800_000 + 1234, // 2100-01-01T00:00:01.234Z
        mean_mps: 0.1234,
        smoothed_mps: f64::NAN,
        ci95_half_mps: 0.01,
        fish: 7,
        mean_bls: 0.5,
        status: StatusBits::RUNNING | StatusBits::TELEMETRY_FAULT,
        fault: FaultCode::from_code(fault).expect("a known code"),
        feeding,
        scale: ScaleSource::References,
        ..Update::default()
    }
}

/// `u` with the scale source `scale`.
fn at(u: Update, scale: ScaleSource) -> Update {
    Update { scale, ..u }
}

#[test]
fn topics_under_prefix_and_box() {
    let t = Topics::new("fme", "cage7");
    assert_eq!(t.activity, "fme/cage7/activity");
    assert_eq!(t.status, "fme/cage7/status");
    assert_eq!(t.event, "fme/cage7/event");
    assert_eq!(t.config, "fme/cage7/config");
}

#[test]
fn box_id_defaults_to_host_name() {
    let mut c = MqttConfig::default();
    assert_eq!(box_id(&c), host_name());
    assert!(!box_id(&c).is_empty());
    c.box_id = "cage 7/a".into();
    assert_eq!(box_id(&c), "cage_7_a");
}

#[test]
fn activity_json_parses_with_every_field() {
    let mut s = String::new();
    activity_json("cage\"7", 42, &row(1, true), &mut s);
    let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
    assert_eq!(v["time"], "2100-01-01T00:00:01.234Z");
    assert_eq!(v["box_id"], "cage\"7");
    assert_eq!(v["seq"], 42);
    assert_eq!(v["mean_mps"], 0.1234);
    assert!(v["smoothed_mps"].is_null(), "NaN is null: {s}");
    assert_eq!(v["n_fish"], 7);
    assert_eq!(v["status"]["running"], true);
    assert_eq!(v["status"]["telemetry_fault"], true);
    assert_eq!(v["status"]["stale"], false);
    assert_eq!(v["status"].as_object().map(|o| o.len()), Some(11));
    assert_eq!(v["status"]["unlike_fish"], false);
    assert_eq!(v["status_bits"], u64::from((StatusBits::RUNNING | StatusBits::TELEMETRY_FAULT).bits()));
    assert_eq!(v["fault"], "camera");
    assert_eq!(v["fault_code"], 1);
    assert_eq!(v["feeding"], true);
}

#[test]
fn event_json_parses() {
    for kind in [
        EventKind::FeedingOn,
        EventKind::FaultRaised(FaultCode::PipelineStalled),
        EventKind::FaultCleared(FaultCode::PipelineStalled),
        EventKind::ScaleSource { from: ScaleSource::References, to: ScaleSource::Fish },
    ] {
        let mut s = String::new();
        event_json("b", &row(0, true), kind, &mut s);
        let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
        assert_eq!(v["event"], kind.name());
        assert_eq!(v["box_id"], "b");
    }
    let mut s = String::new();
    event_json(
        "b",
        &row(0, false),
        EventKind::ScaleSource { from: ScaleSource::Fish, to: ScaleSource::References },
        &mut s,
    );
    let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
    assert_eq!((v["from"].as_str(), v["to"].as_str()), (Some("fish"), Some("references")));
}

#[test]
fn config_json_has_no_password_only_its_file() {
    let mut c = Config::default();
    c.output.mqtt.username = "box".into();
    c.output.mqtt.password_file = "/etc/fme/mqtt.pass".into();
    let j = config_json("b", &c);
    let v: serde_json::Value = serde_json::from_str(&j).expect(&j);
    assert_eq!(v["config"]["output"]["mqtt"]["password_file"], "/etc/fme/mqtt.pass");
    assert!(v["config"]["output"]["mqtt"].get("password").is_none());
    assert_eq!(v["build"], fme_core::infer::backend::BUILD);
}

#[test]
fn config_json_names_each_configured_networks_form() {
    let models = std::path::Path::new(fme_core::REPO_DIR).join("models");
    let mut c = Config::default();
    c.detector.model = models.join("fish_det_int8.onnx");
    c.depth.model = models.join("fish_depth_fp32.onnx");
    let v: serde_json::Value = serde_json::from_str(&config_json("b", &c)).expect("json");
    assert_eq!((v["detector_form"].as_str(), v["depth_form"].as_str()), (Some("int8-qdq"), Some("fp32")));
    c.detector.model = "/no/such/model.onnx".into();
    let v: serde_json::Value = serde_json::from_str(&config_json("b", &c)).expect("json");
    assert_eq!(v["detector_form"], "unreadable");
}

#[test]
fn events_on_changes_only() {
    let mut t = EventTracker::default();
    assert!(t.update(&at(row(0, false), ScaleSource::None)).is_empty(), "baseline");
    assert_eq!(t.update(&at(row(0, true), ScaleSource::References))[..], [EventKind::FeedingOn]);
    assert!(t.update(&at(row(0, true), ScaleSource::References)).is_empty());
    assert_eq!(
        t.update(&at(row(1, true), ScaleSource::Fish))[..],
        [
            EventKind::ScaleSource { from: ScaleSource::References, to: ScaleSource::Fish },
            EventKind::FaultRaised(FaultCode::Camera)
        ]
    );
    assert_eq!(
        t.update(&at(row(4, false), ScaleSource::None))[..],
        [
            EventKind::FaultCleared(FaultCode::Camera),
            EventKind::FaultRaised(FaultCode::PipelineStalled),
            EventKind::FeedingOff
        ]
    );
    assert!(t.update(&at(row(6, false), ScaleSource::Fish)).is_empty(), "the stop makes no events");
    let mut t = EventTracker::default();
    assert_eq!(
        t.update(&at(row(1, false), ScaleSource::None))[..],
        [EventKind::FaultRaised(FaultCode::Camera)],
        "fault at start"
    );
}

#[test]
fn unlike_fish_is_an_event_when_raised_and_when_cleared() {
    let mut t = EventTracker::default();
    let flagged = |fault| Update { status: row(0, false).status | StatusBits::UNLIKE_FISH, ..row(fault, false) };
    assert!(t.update(&at(row(0, false), ScaleSource::References)).is_empty());
    assert_eq!(
        t.update(&at(flagged(7), ScaleSource::References))[..],
        [EventKind::FaultRaised(FaultCode::UnlikeFish), EventKind::UnlikeFish(true)]
    );
    assert!(t.update(&at(flagged(7), ScaleSource::References)).is_empty(), "no event while it stays raised");
    // Under a more severe fault the bit still says it, and its clearing is an event of its own.
    assert_eq!(
        t.update(&at(flagged(1), ScaleSource::References))[..],
        [EventKind::FaultCleared(FaultCode::UnlikeFish), EventKind::FaultRaised(FaultCode::Camera)]
    );
    assert_eq!(t.update(&at(row(1, false), ScaleSource::References))[..], [EventKind::UnlikeFish(false)]);
    let mut s = String::new();
    event_json("b", &flagged(7), EventKind::UnlikeFish(true), &mut s);
    let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
    assert_eq!(v["event"], "unlike_fish_raised");
    assert_eq!(v["unlike_fish"], true);
    assert_eq!(v["n_fish"], 7);
}

#[test]
fn queue_drops_oldest_and_requeues_in_front() {
    let a = |seq| Item::Activity { seq, update: row(0, false) };
    let mut q = Queue::new(3);
    for s in 1..=5 {
        q.push(Queued { item: a(s), waited: false });
    }
    assert_eq!((q.len(), q.dropped), (3, 2));
    let seq = |m: Option<Queued>| match m.map(|m| m.item) {
        Some(Item::Activity { seq, .. }) => Some(seq),
        _ => None,
    };
    assert_eq!(seq(q.pop()), Some(3));
    // Two unacknowledged messages go back in front; one fits (the newer one), one is dropped.
    q.requeue_front([a(1), a(2)].into_iter());
    assert_eq!((q.len(), q.dropped), (3, 3));
    let order: Vec<_> = std::iter::from_fn(|| q.pop()).map(|m| (seq(Some(m)), m.waited)).collect();
    assert_eq!(order, vec![(Some(2), true), (Some(4), false), (Some(5), false)]);
    assert!(q.is_empty());
}
