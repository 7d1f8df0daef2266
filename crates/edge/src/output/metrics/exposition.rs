//! The Prometheus text format (0.0.4) as written: `# HELP` / `# TYPE` per family, escaped label
//! values and HELP text, floats as Go parses them, cumulative histograms.

use std::fmt::Write as _;

/// Kind of a metric family (`# TYPE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Counter,
    Gauge,
    Histogram,
}

/// A Prometheus text-format (0.0.4) document under construction: one family per call, each with its
/// `# HELP` and `# TYPE` lines. Names are checked in debug builds (and by the tests over the whole
/// output); a value is written as Go's `strconv.FormatFloat` would parse it back.
#[derive(Debug, Default)]
pub struct Exposition {
    out: String,
    #[cfg(debug_assertions)]
    names: Vec<String>,
}

/// Whether `s` is a valid metric name (`[a-zA-Z_:][a-zA-Z0-9_:]*`).
pub fn valid_metric_name(s: &str) -> bool {
    let mut c = s.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_' || f == ':')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_' || x == ':')
}

/// Whether `s` is a valid label name (`[a-zA-Z_][a-zA-Z0-9_]*`, not starting with `__`).
pub fn valid_label_name(s: &str) -> bool {
    let mut c = s.chars();
    !s.starts_with("__")
        && c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

/// Appends `v` as the text format writes a sample value.
fn push_value(out: &mut String, v: f64) {
    if v.is_nan() {
        out.push_str("NaN");
    } else if v.is_infinite() {
        out.push_str(if v > 0.0 { "+Inf" } else { "-Inf" });
    } else {
        let _ = write!(out, "{v}");
    }
}

/// Appends a label value with `\`, `"` and newline escaped.
fn push_label_value(out: &mut String, v: &str) {
    for c in v.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
}

/// Appends HELP text with `\` and newline escaped.
fn push_help(out: &mut String, v: &str) {
    for c in v.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
}

impl Exposition {
    /// An empty document.
    pub fn new() -> Self {
        Self { out: String::with_capacity(16 * 1024), ..Self::default() }
    }

    fn header(&mut self, name: &str, kind: Kind, help: &str) {
        debug_assert!(valid_metric_name(name), "bad metric name {name:?}");
        debug_assert!(kind != Kind::Counter || name.ends_with("_total"), "counter {name} must end in _total");
        #[cfg(debug_assertions)]
        {
            debug_assert!(!self.names.iter().any(|n| n == name), "family {name} written twice");
            self.names.push(name.to_string());
        }
        let kind = match kind {
            Kind::Counter => "counter",
            Kind::Gauge => "gauge",
            Kind::Histogram => "histogram",
        };
        let _ = write!(self.out, "# HELP {name} ");
        push_help(&mut self.out, help);
        let _ = write!(self.out, "\n# TYPE {name} {kind}\n");
    }

    fn sample(&mut self, name: &str, suffix: &str, labels: &[(&str, &str)], value: f64) {
        self.out.push_str(name);
        self.out.push_str(suffix);
        if !labels.is_empty() {
            self.out.push('{');
            for (i, (k, v)) in labels.iter().enumerate() {
                debug_assert!(valid_label_name(k), "bad label name {k:?}");
                if i > 0 {
                    self.out.push(',');
                }
                self.out.push_str(k);
                self.out.push_str("=\"");
                push_label_value(&mut self.out, v);
                self.out.push('"');
            }
            self.out.push('}');
        }
        self.out.push(' ');
        push_value(&mut self.out, value);
        self.out.push('\n');
    }

    /// A gauge without labels.
    pub fn gauge(&mut self, name: &str, help: &str, v: f64) {
        self.header(name, Kind::Gauge, help);
        self.sample(name, "", &[], v);
    }

    /// A gauge with one label: one sample per `(label value, value)`.
    pub fn gauge_by(&mut self, name: &str, help: &str, label: &str, items: &[(&str, f64)]) {
        self.header(name, Kind::Gauge, help);
        for (l, v) in items {
            self.sample(name, "", &[(label, l)], *v);
        }
    }

    /// An info gauge: one sample of value 1 carrying `labels`.
    pub fn info(&mut self, name: &str, help: &str, labels: &[(&str, &str)]) {
        self.header(name, Kind::Gauge, help);
        self.sample(name, "", labels, 1.0);
    }

    /// A counter without labels (`name` ends in `_total`).
    pub fn counter(&mut self, name: &str, help: &str, v: u64) {
        self.header(name, Kind::Counter, help);
        self.sample(name, "", &[], v as f64);
    }

    /// A counter with one label: one sample per `(label value, value)`.
    pub fn counter_by(&mut self, name: &str, help: &str, label: &str, items: &[(&str, u64)]) {
        self.header(name, Kind::Counter, help);
        for (l, v) in items {
            self.sample(name, "", &[(label, l)], *v as f64);
        }
    }

    /// A histogram: `buckets` are `(upper bound, samples <= bound)` in increasing bound order,
    /// cumulative; a `+Inf` bucket equal to `count` is added unless the last bound is `+Inf` (then
    /// its count must be `count`). Counts are made non-decreasing and capped at `count`, so the
    /// output is a valid histogram whatever the input.
    pub fn histogram(&mut self, name: &str, help: &str, buckets: &[(f64, u64)], count: u64, sum: f64) {
        self.header(name, Kind::Histogram, help);
        let mut prev = 0u64;
        let mut le = String::with_capacity(16);
        for &(bound, n) in buckets.iter().filter(|(b, _)| b.is_finite()) {
            let n = n.clamp(prev, count);
            prev = n;
            le.clear();
            push_value(&mut le, bound);
            self.sample(name, "_bucket", &[("le", &le)], n as f64);
        }
        self.sample(name, "_bucket", &[("le", "+Inf")], count as f64);
        self.sample(name, "_sum", &[], sum);
        self.sample(name, "_count", &[], count as f64);
    }

    /// The document.
    pub fn finish(self) -> String {
        self.out
    }
}
