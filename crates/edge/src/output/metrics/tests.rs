use super::*;
use crate::output::StatusBits;
use fme_core::pipeline::{ActivitySample, QualityFlags};
use fme_core::units::{MetresPerSecond, Seconds};

fn snapshot() -> Scrape {
    let shared = Shared::new(String::new(), 4);
    let bank = RegisterBank::new();
    shared.with_health(|h| {
        h.frames_captured = 120;
        h.frames_processed = 118;
        h.last_sample = Some(ActivitySample {
            timestamp: Seconds(4.0),
            mean: MetresPerSecond(0.25),
            mean_body_lengths: 1.25,
            smoothed: MetresPerSecond(0.2),
            ci95_half: MetresPerSecond(0.03),
            fish: 17,
            latency: Seconds(0.0),
            flags: QualityFlags::default(),
            scale: fme_core::pipeline::ScaleSource::References,
        });
        h.last_sample_at = Some(Instant::now());
        h.networks.detector = Some(fme_core::pipeline::Network {
            path: "models/fish_det_int8.onnx".into(),
            form: fme_core::infer::ModelForm::Int8Qdq,
            backend: fme_core::infer::Backend::DEFAULT,
        });
        for ms in [0.5, 3.0, 7.0, 40.0, 2000.0] {
            h.latency.record(ms);
        }
    });
    let u = Update {
        status: StatusBits::RUNNING | StatusBits::CAMERA_OK | StatusBits::STALE,
        fault: crate::status::FaultCode::Depth,
        feeding: true,
        ..Default::default()
    };
    bank.publish_update(&u, crate::config::WordOrder::HighFirst);
    Scrape::take(&shared, &bank, Duration::from_secs(5))
}

/// The samples of `text` as (name with labels, value), checking each line's grammar on the way.
fn samples(text: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') {
            let mut w = line.splitn(4, ' ');
            let (_, kw, name) = (w.next(), w.next(), w.next().unwrap_or(""));
            assert!(matches!(kw, Some("HELP") | Some("TYPE")), "{line}");
            assert!(valid_metric_name(name), "{line}");
            continue;
        }
        let (key, value) = line.rsplit_once(' ').unwrap_or(("", ""));
        let name = key.split('{').next().unwrap_or("");
        assert!(valid_metric_name(name), "{line}");
        assert!(value == "NaN" || value == "+Inf" || value.parse::<f64>().is_ok(), "{line}");
        out.push((key.to_string(), value.to_string()));
    }
    out
}

fn value(text: &str, key: &str) -> String {
    samples(text).into_iter().find(|(k, _)| k == key).map(|(_, v)| v).unwrap_or_else(|| panic!("no {key}"))
}

#[test]
fn escapes_label_values_and_help() {
    let mut e = Exposition::new();
    e.info("x_info", "a \\ b\nc \"q\"", &[("path", "C:\\dir \"quoted\"\nnext")]);
    let t = e.finish();
    assert_eq!(
        t,
        "# HELP x_info a \\\\ b\\nc \"q\"\n# TYPE x_info gauge\nx_info{path=\"C:\\\\dir \\\"quoted\\\"\\nnext\"} 1\n"
    );
    let parsed = openmetrics_parser::prometheus::parse_prometheus(&t).expect("parses");
    assert_eq!(parsed.families.len(), 1);
}

#[test]
fn special_values_are_written_as_go_parses_them() {
    let mut e = Exposition::new();
    e.gauge("a", "h", f64::NAN);
    e.gauge("b", "h", f64::INFINITY);
    e.gauge("c", "h", f64::NEG_INFINITY);
    e.gauge("d", "h", 0.1 + 0.2);
    e.counter("e_total", "h", u64::from(u32::MAX) + 1);
    let t = e.finish();
    for (k, v) in [("a", "NaN"), ("b", "+Inf"), ("c", "-Inf"), ("d", "0.30000000000000004"), ("e_total", "4294967296")]
    {
        assert_eq!(value(&t, k), v, "{k}");
    }
}

#[test]
fn histogram_is_cumulative_and_ends_with_inf_equal_to_count() {
    let mut e = Exposition::new();
    // A decreasing count and one above the total are repaired, not written.
    e.histogram("lat_seconds", "h", &[(0.1, 2), (0.5, 1), (1.0, 9)], 5, 1.5);
    let t = e.finish();
    let s = samples(&t);
    let buckets: Vec<&str> = s.iter().filter(|(k, _)| k.contains("_bucket")).map(|(_, v)| v.as_str()).collect();
    assert_eq!(buckets, ["2", "2", "5", "5"]);
    assert_eq!(value(&t, "lat_seconds_bucket{le=\"+Inf\"}"), "5");
    assert_eq!(value(&t, "lat_seconds_bucket{le=\"0.1\"}"), "2");
    assert_eq!(value(&t, "lat_seconds_bucket{le=\"1\"}"), "5");
    assert_eq!(value(&t, "lat_seconds_sum"), "1.5");
    assert_eq!(value(&t, "lat_seconds_count"), "5");
    openmetrics_parser::prometheus::parse_prometheus(&t).expect("parses");
}

#[test]
fn the_parser_used_as_oracle_rejects_broken_expositions() {
    let parse = |t: &str| openmetrics_parser::prometheus::parse_prometheus(t).is_ok();
    let ok = "# HELP h_seconds h\n# TYPE h_seconds histogram\nh_seconds_bucket{le=\"1\"} 1\nh_seconds_bucket{le=\"+Inf\"} 2\nh_seconds_sum 3\nh_seconds_count 2\n";
    assert!(parse(ok));
    assert!(!parse(&ok.replace("{le=\"1\"} 1", "{le=\"1\"} 3")), "buckets not cumulative");
    assert!(!parse(&ok.replace("h_seconds_bucket{le=\"+Inf\"} 2\n", "")), "no +Inf bucket");
    assert!(!parse("# TYPE g gauge\ng{name=\"a\\q\"} 1\n"), "bad escape in a label value");
    assert!(!parse("# TYPE g gauge\ng 1 2 3\n"), "garbage after the value");
}

#[test]
fn every_family_once_with_valid_names_and_a_strict_parser_accepts_it() {
    let snap = snapshot();
    let t = render(&snap);
    let mut families = Vec::new();
    for line in t.lines().filter(|l| l.starts_with("# TYPE ")) {
        let name = line.split(' ').nth(2).unwrap_or("").to_string();
        assert!(!families.contains(&name), "{name} twice");
        families.push(name);
    }
    assert!(families.len() >= 50, "{} families", families.len());
    assert!(families.iter().all(|f| f.starts_with("fme_")), "{families:?}");
    let parsed = openmetrics_parser::prometheus::parse_prometheus(&t).unwrap_or_else(|e| panic!("{e:?}\n{t}"));
    assert_eq!(parsed.families.len(), families.len());
    assert_eq!(value(&t, "fme_fish"), "17");
    assert_eq!(value(&t, "fme_activity_mean_meters_per_second"), "0.25");
    assert_eq!(value(&t, "fme_frames_captured_total"), "120");
    assert_eq!(value(&t, "fme_status_bit{name=\"camera_ok\"}"), "1");
    assert_eq!(value(&t, "fme_status_bit{name=\"stale\"}"), "1");
    assert_eq!(value(&t, "fme_status_bit{name=\"detector_ok\"}"), "0");
    assert_eq!(value(&t, "fme_status_word"), "19");
    assert_eq!(value(&t, "fme_fault_code"), "3");
    assert_eq!(value(&t, "fme_feeding_recommended"), "1");
    assert_eq!(value(&t, "fme_activity_age_seconds").parse::<f64>().map(|a| a < 5.0), Ok(true));
    assert_eq!(
        value(
            &t,
            &format!(
                "fme_build_info{{version=\"{}\",register_map=\"0.1\",backend=\"{}\",detector=\"int8-qdq\",depth=\"none\"}}",
                env!("CARGO_PKG_VERSION"),
                fme_core::infer::Backend::DEFAULT.name()
            )
        ),
        "1"
    );
    // Latencies 0.5, 3, 7, 40, 2000 ms.
    let l = "fme_frame_to_register_latency_seconds";
    for (le, n) in [("0.005", "2"), ("0.01", "3"), ("0.05", "4"), ("1", "4"), ("+Inf", "5")] {
        assert_eq!(value(&t, &format!("{l}_bucket{{le=\"{le}\"}}")), n, "le {le}");
    }
    assert_eq!(value(&t, &format!("{l}_count")), "5");
    assert_eq!(value(&t, &format!("{l}_sum")), "2.0505");
}

#[test]
fn a_stale_value_is_nan_and_no_fish() {
    let mut snap = snapshot();
    snap.health.last_sample_at = snap.now.checked_sub(Duration::from_secs(6));
    let t = render(&snap);
    assert_eq!(value(&t, "fme_activity_mean_meters_per_second"), "NaN");
    assert_eq!(value(&t, "fme_activity_smoothed_meters_per_second"), "NaN");
    assert_eq!(value(&t, "fme_fish"), "0");
    snap.health.last_sample_at = None;
    assert_eq!(value(&render(&snap), "fme_activity_age_seconds"), "+Inf");
}
