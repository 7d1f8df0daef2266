//! The JSON payloads of the `activity`, `event` and `config` topics (schemas in docs/mqtt.md), made
//! from the published update (pure).

use super::events::EventKind;
use crate::config::Config;
use crate::history::format_time;
use crate::output::Update;
use std::fmt::Write as _;

fn push_num(out: &mut String, key: &str, v: f64, decimals: usize) {
    if v.is_finite() {
        let _ = write!(out, "\"{key}\":{v:.decimals$},");
    } else {
        let _ = write!(out, "\"{key}\":null,");
    }
}

fn push_str(out: &mut String, key: &str, v: &str) {
    let _ = write!(out, "\"{key}\":");
    json_string(v, out);
    out.push(',');
}

/// Appends `s` as a JSON string literal.
pub fn json_string(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// Appends the `activity` JSON of update `u` (schema in docs/mqtt.md).
pub fn activity_json(box_id: &str, seq: u64, u: &Update, out: &mut String) {
    out.push('{');
    out.push_str("\"time\":\"");
    format_time(u.unix_ms, out);
    out.push_str("\",");
    push_str(out, "box_id", box_id);
    let _ = write!(out, "\"seq\":{seq},");
    push_num(out, "mean_mps", u.mean_mps, 4);
    push_num(out, "smoothed_mps", u.smoothed_mps, 4);
    push_num(out, "ci95_mps", u.ci95_half_mps, 4);
    let _ = write!(out, "\"n_fish\":{},", u.fish);
    push_num(out, "bls", u.mean_bls, 3);
    out.push_str("\"status\":{");
    for (i, (name, on)) in u.status.named().enumerate() {
        let _ = write!(out, "{}\"{name}\":{on}", if i > 0 { "," } else { "" });
    }
    let _ = write!(out, "}},\"status_bits\":{},", u.status.bits());
    push_str(out, "fault", u.fault.name());
    let _ = write!(out, "\"fault_code\":{},\"feeding\":{}}}", u.fault as u16, u.feeding);
}

/// Appends the `event` JSON of `kind` at the time of update `u` (schema in docs/mqtt.md).
pub fn event_json(box_id: &str, u: &Update, kind: EventKind, out: &mut String) {
    out.push('{');
    out.push_str("\"time\":\"");
    format_time(u.unix_ms, out);
    out.push_str("\",");
    push_str(out, "box_id", box_id);
    push_str(out, "event", kind.name());
    match kind {
        EventKind::FeedingOn | EventKind::FeedingOff => {
            let _ = write!(out, "\"feeding\":{},", u.feeding);
            push_num(out, "smoothed_mps", u.smoothed_mps, 4);
        }
        EventKind::FaultRaised(c) | EventKind::FaultCleared(c) => {
            push_str(out, "fault", c.name());
            let _ = write!(out, "\"fault_code\":{},", c as u16);
        }
        EventKind::UnlikeFish(raised) => {
            let _ = write!(out, "\"unlike_fish\":{raised},\"n_fish\":{},", u.fish);
            push_num(out, "mean_mps", u.mean_mps, 4);
        }
        EventKind::ScaleSource { from, to } => {
            push_str(out, "from", from.name());
            push_str(out, "to", to.name());
        }
    }
    out.pop(); // the last ','
    out.push('}');
}

/// The retained `config` JSON: box id, fme version, the build (backend, default model form), the
/// configured networks' numeric forms and the effective configuration (it holds no secret: the
/// password is only named by its file, `output.mqtt.password_file`).
pub fn config_json(box_id: &str, cfg: &Config) -> String {
    let mut out = String::from("{");
    push_str(&mut out, "box_id", box_id);
    push_str(&mut out, "version", env!("CARGO_PKG_VERSION"));
    push_str(&mut out, "build", fme_core::infer::backend::BUILD);
    for (key, model) in [("detector_form", &cfg.detector.model), ("depth_form", &cfg.depth.model)] {
        let form = fme_core::infer::ModelForm::of_file(model);
        push_str(&mut out, key, form.as_ref().map_or("unreadable", |f| f.name()));
    }
    match serde_json::to_string(cfg) {
        Ok(c) => {
            let _ = write!(out, "\"config\":{c}}}");
        }
        Err(e) => {
            // A value JSON cannot hold (a non-finite float): the TOML text instead.
            let _ = write!(out, "\"config_error\":");
            json_string(&e.to_string(), &mut out);
            out.push_str(",\"config_toml\":");
            json_string(&cfg.to_toml(), &mut out);
            out.push('}');
        }
    }
    out
}
