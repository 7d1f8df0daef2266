//! The Prometheus text itself, without a server: label values spelled as on MQTT, rates as
//! counters, and latency buckets fine enough that `histogram_quantile` agrees with the console.

use fme::output::bank::RegisterBank;
use fme::output::metrics::{LATENCY_BOUNDS_S, Scrape, render};
use fme::status::Shared;
use std::time::Duration;

/// The exposition of a daemon whose latency histogram holds `latencies_ms`.
fn text(latencies_ms: &[f64]) -> String {
    let shared = Shared::new(String::new(), 4);
    shared.with_health(|h| latencies_ms.iter().for_each(|&ms| h.latency.record(ms)));
    render(&Scrape::take(&shared, &RegisterBank::new(), Duration::from_secs(5)))
}

/// The cumulative buckets (upper bound s, count) of the latency histogram in `text`.
fn buckets(text: &str) -> Vec<(f64, f64)> {
    let prefix = "fme_frame_to_register_latency_seconds_bucket{le=\"";
    text.lines()
        .filter_map(|l| l.strip_prefix(prefix))
        .map(|l| {
            let (le, rest) = l.split_once("\"} ").expect("a bucket line");
            let le = if le == "+Inf" { f64::INFINITY } else { le.parse().expect("le") };
            (le, rest.parse().expect("count"))
        })
        .collect()
}

/// `histogram_quantile(q, ...)` as Prometheus computes it (promql `bucketQuantile`): the rank
/// q x count, the first bucket whose cumulative count reaches it, linear interpolation inside it
/// from the previous bound (0 for the first); a rank in the `+Inf` bucket answers the highest
/// finite bound.
fn histogram_quantile(q: f64, b: &[(f64, f64)]) -> f64 {
    let total = b[b.len() - 1].1;
    let rank = q * total;
    let i = b.iter().position(|&(_, n)| n >= rank).expect("the +Inf bucket holds every sample");
    if b[i].0.is_infinite() {
        return b[i - 1].0;
    }
    let (lo, below) = if i == 0 { (0.0, 0.0) } else { b[i - 1] };
    let (hi, n) = b[i];
    lo + (hi - lo) * (rank - below) / (n - below)
}

#[test]
fn histogram_quantile_p99_is_within_20_percent_of_the_console_p99() {
    // Whole milliseconds, each bound at most 1.2 x the previous from 5 ms on.
    assert!(LATENCY_BOUNDS_S.windows(2).all(|w| w[1] <= w[0] * 1.2 + 1e-12), "{LATENCY_BOUNDS_S:?}");
    assert!(LATENCY_BOUNDS_S.iter().all(|b| ((b * 1000.0).round() - b * 1000.0).abs() < 1e-9));
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut worst = (0.0, 0.0, 0.0);
    let mut c = 5.5;
    while c < 990.0 {
        // Latencies cluster around the inference time: tight, tight with a slow tail, and spread.
        let tight: Vec<f64> = (0..1000).map(|_| c + rnd() * 0.8).collect();
        let tail: Vec<f64> = (0..1000).map(|i| if i % 100 < 3 { (c * 1.15).min(999.0) } else { c * 0.7 }).collect();
        let spread: Vec<f64> = (0..1000).map(|_| c * (0.2 + 0.8 * rnd())).collect();
        for lat in [tight, tail, spread] {
            let t = text(&lat);
            let shared = Shared::new(String::new(), 4);
            shared.with_health(|h| lat.iter().for_each(|&ms| h.latency.record(ms)));
            let console = shared.health().latency.quantile_ms(0.99).expect("samples");
            if console <= 5.0 {
                continue;
            }
            let prom = histogram_quantile(0.99, &buckets(&t)) * 1000.0;
            let err = (prom - console).abs() / console;
            if err > worst.0 {
                worst = (err, console, prom);
            }
        }
        c *= 1.07;
    }
    assert!(
        worst.0 <= 0.2,
        "p99: console {:.1} ms, histogram_quantile {:.1} ms ({:.0} % off)",
        worst.1,
        worst.2,
        worst.0 * 100.0
    );
}

#[test]
fn label_values_are_spelled_as_on_mqtt() {
    let t = text(&[]);
    let names: Vec<&str> = t
        .lines()
        .filter_map(|l| l.strip_prefix("fme_status_bit{name=\""))
        .map(|l| l.split('"').next().unwrap_or(""))
        .collect();
    // The keys of the `status` object of an MQTT `activity` message, in order.
    let mut json = String::new();
    fme::output::mqtt::activity_json("b", 1, &fme::output::Update::default(), &mut json);
    let status = json.split("\"status\":{").nth(1).and_then(|s| s.split('}').next()).unwrap_or("");
    let mqtt: Vec<&str> = status.split(',').filter_map(|kv| kv.split('"').nth(1)).collect();
    assert_eq!(names, mqtt);
    assert_eq!(mqtt.len(), 11, "{json}");
    for l in t.lines().filter(|l| !l.starts_with('#') && l.contains('{')) {
        let labels = &l[l.find('{').unwrap_or(0)..l.rfind('}').unwrap_or(0)];
        assert!(!labels.contains('-'), "one spelling, with underscores as MQTT: {l}");
    }
    assert!(t.contains("fme_mqtt_link{state=\"auth_failed\"}"), "{t}");
}

#[test]
fn rates_are_counters_and_only_speeds_are_per_second_gauges() {
    let t = text(&[]);
    let families: Vec<(&str, &str)> =
        t.lines().filter_map(|l| l.strip_prefix("# TYPE ")).filter_map(|l| l.split_once(' ')).collect();
    let per_second: Vec<&str> = families.iter().filter(|(n, _)| n.ends_with("_per_second")).map(|(n, _)| *n).collect();
    assert_eq!(
        per_second,
        [
            "fme_activity_mean_meters_per_second",
            "fme_activity_smoothed_meters_per_second",
            "fme_activity_ci95_half_width_meters_per_second",
            "fme_activity_mean_body_lengths_per_second",
        ],
        "a rate of events is a counter; these are speeds"
    );
    for name in ["fme_detector_runs_total", "fme_depth_runs_total", "fme_frames_captured_total"] {
        assert!(families.contains(&(name, "counter")), "{name}");
    }
}
