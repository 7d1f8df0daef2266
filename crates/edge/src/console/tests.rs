use super::*;

fn shared() -> (Shared, RegisterBank) {
    (Shared::new("[source]\npath = \"x\"\n".into(), 50), RegisterBank::new())
}

fn run(input: &[u8]) -> String {
    let s = shared();
    let mut sess = Session::default();
    let mut out = String::new();
    sess.feed(input, &s.0, &s.1, &mut out);
    out
}

#[test]
fn mqtt_shows_link_queue_drops_and_last_publish() {
    let out = run(b"mqtt\r\nmqtt now\r\n");
    assert!(out.contains("mqtt disabled (output.mqtt.enabled = false)\r\nOK"), "{out}");
    assert!(out.contains("ERR `mqtt` takes no argument"), "{out}");
    let m = crate::status::MqttHealth {
        link: crate::status::MqttLink::Connected,
        broker: "broker.farm:1883".into(),
        queued: 3,
        dropped: 7,
        last_publish_unix_ms: Some(4_102_444_800_000),
        ..Default::default()
    };
    let t = mqtt_text(&m, 4_102_444_802_500);
    for want in ["link connected", "queued 3", "dropped 7", "last-publish 2100-01-01T00:00:00.000Z (2.5 s ago)"] {
        assert!(t.contains(want), "{want}: {t}");
    }
    assert!(run(b"help\r\n").contains("mqtt "), "in help");
}

#[test]
fn commands_case_insensitive() {
    let out = run(b"HeLp\r\nVERSION\n");
    assert!(out.contains("stream on|off"));
    assert!(out.contains(concat!("fme ", env!("CARGO_PKG_VERSION"))));
    assert_eq!(out.matches("OK\r\n").count(), 2);
}

#[test]
fn errors_for_garbage() {
    assert!(run(b"frobnicate\n").starts_with("ERR unknown command `frobnicate`"));
    assert!(run(b"status now\n").starts_with("ERR `status` takes no argument"));
    assert!(run(b"stream maybe\n").starts_with("ERR usage: stream on|off"));
    assert!(run(b"log -3\n").starts_with("ERR usage: log"));
    assert_eq!(run(b"\x00\x01\xff\n"), "ERR binary input ignored\r\n");
    let long = vec![b'a'; 500];
    let out = run(&[long.as_slice(), b"\nversion\n"].concat());
    assert!(out.starts_with("ERR line too long"), "{out}");
    assert_eq!(out.matches("ERR").count(), 1);
    assert!(out.ends_with("OK\r\n"));
    assert_eq!(run(b"\r\n\r\n   \n"), "");
}

#[test]
fn snap_and_record_save_go_through_the_mailbox() {
    let s = shared();
    let mut sess = Session::default();
    let mut out = String::new();
    sess.feed(
        b"record save storm
",
        &s.0,
        &s.1,
        &mut out,
    );
    assert!(out.starts_with("ERR no black box"), "{out}");
    assert_eq!(s.0.requests.take_save(), None);
    s.0.with_health(|h| h.record.active = true);
    out.clear();
    sess.feed(
        b"SNAP
record save Storm
record save
record save a b
record
",
        &s.0,
        &s.1,
        &mut out,
    );
    assert!(s.0.requests.take_snapshot());
    assert_eq!(s.0.requests.take_save().as_deref(), Some("manual"), "the latest request wins");
    assert!(out.contains("ERR usage: record save [label]"), "{out}");
    assert!(out.contains("ring on") && out.contains("disk ok"), "{out}");
    sess.feed(
        b"record save storm
",
        &s.0,
        &s.1,
        &mut out,
    );
    assert_eq!(s.0.requests.take_save().as_deref(), Some("storm"));
}

#[test]
fn stream_and_config() {
    let s = shared();
    let mut sess = Session::default();
    let mut out = String::new();
    sess.feed(b"stream on\n", &s.0, &s.1, &mut out);
    assert!(sess.stream);
    sess.feed(b"Stream OFF\nconfig\n", &s.0, &s.1, &mut out);
    assert!(!sess.stream);
    assert!(out.contains("path = \"x\""));
}

#[test]
fn echo_in_order_with_replies() {
    let s = shared();
    let mut sess = Session { echo: true, ..Session::default() };
    let mut out = String::new();
    sess.feed(b"vex\x7frsion\r\nhelp\x00\r\n", &s.0, &s.1, &mut out);
    assert!(out.starts_with("vex\x08 \x08rsion\r\nfme "), "{out:?}");
    assert!(out.contains("OK\r\nhelp\r\nERR binary input ignored\r\n"), "{out:?}");
}

#[test]
fn partial_input_is_available_for_redraw() {
    let s = shared();
    let mut sess = Session { echo: true, ..Session::default() };
    let mut out = String::new();
    sess.feed(b"stat", &s.0, &s.1, &mut out);
    assert_eq!(sess.partial_echo(), Some("stat"));
    sess.feed(b"us\r", &s.0, &s.1, &mut out);
    assert_eq!(sess.partial_echo(), None);
    sess.feed(b"\x01", &s.0, &s.1, &mut out);
    assert_eq!(sess.partial_echo(), None, "binary input is not redrawn");
}

#[test]
fn an_over_long_line_gets_its_error_on_its_own_line_with_echo() {
    let s = shared();
    let mut sess = Session { echo: true, ..Session::default() };
    let mut out = String::new();
    sess.feed(&[b'a'; 100], &s.0, &s.1, &mut out);
    sess.feed(b"\r\nversion\r\n", &s.0, &s.1, &mut out);
    let lines: Vec<&str> = out.split("\r\n").collect();
    assert_eq!(lines[0], "a".repeat(MAX_LINE), "the echo stops at the limit");
    assert!(lines[1].starts_with("ERR line too long"), "{out:?}");
    assert!(out.ends_with("OK\r\n"));
    let mut quiet = Session::default();
    let mut out = String::new();
    quiet.feed(&[b'a'; 100], &s.0, &s.1, &mut out);
    assert!(out.starts_with("ERR line too long"), "no echo, no extra line: {out:?}");
}

#[test]
fn history_hourly_summary_from_the_files() {
    let s = shared();
    assert!(run(b"history\n").starts_with("ERR history is off"), "no directory: off");
    let dir = tempfile::tempdir().expect("tempdir");
    let now = crate::history::now_unix_ms();
    let mut w = crate::history::DayWriter::new(dir.path(), 30, 0.0);
    // One row a second for the last 10 minutes: 0.1 m/s, feeding for all of them.
    for i in 0..600 {
        let r = crate::history::HistoryRow {
            unix_ms: now - (600 - i) * 1000,
            activity_mps: 0.1,
            smoothed_mps: 0.1,
            ci95_mps: 0.01,
            n_fish: 5,
            bls: 0.3,
            status: 1,
            fault: 0,
            feeding: true,
            scale: fme_core::pipeline::ScaleSource::References,
            unlike_fish: false,
        };
        w.write(&r).expect("write");
    }
    s.0.history.set_dir(dir.path());
    let mut sess = Session::default();
    let mut out = String::new();
    sess.command("history 2", &s.0, &s.1, &mut out);
    let lines: Vec<&str> = out.split("\r\n").filter(|l| !l.is_empty()).collect();
    assert!((3..=4).contains(&lines.len()), "header, the one or two hours with rows, OK: {out}");
    assert!(lines[0].starts_with("hour (UTC)"), "{out}");
    assert_eq!(lines[lines.len() - 1], "OK");
    let rows: u32 = lines[1..lines.len() - 1]
        .iter()
        .map(|l| l.split_whitespace().nth(2).and_then(|n| n.parse::<u32>().ok()).unwrap_or(0))
        .sum();
    assert_eq!(rows, 600, "{out}");
    assert!(lines[lines.len() - 2].contains(" 0.100 "), "{out}");
    let mut out = String::new();
    sess.command("history 0", &s.0, &s.1, &mut out);
    assert!(out.starts_with("ERR usage: history"), "{out}");
    let mut out = String::new();
    sess.command("status", &s.0, &s.1, &mut out);
    assert!(out.contains(&format!("history on {}", dir.path().display())), "{out}");
}

#[test]
fn backspace_and_crlf() {
    assert!(run(b"versiom\x08n\r\n").contains("fme "));
}
