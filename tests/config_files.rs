//! The shipped configuration files: `config/fme.toml` documents exactly the built-in defaults, every
//! key in it carries a comment, and every board profile is a valid configuration.

use fme::config::Config;
use std::path::Path;

#[test]
fn shipped_config_equals_defaults() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fme.toml");
    let c = Config::load(&p).expect("config/fme.toml must load");
    assert_eq!(c, Config::default(), "config/fme.toml must document the built-in defaults");
}

/// config/fme.toml with the `[tracker]` section's commented-out keys (the preset's values, shown for
/// reference) written in.
fn shipped_with_commented_keys() -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fme.toml");
    let text = std::fs::read_to_string(&p).expect("read");
    let (mut in_tracker, mut in_model) = (false, false);
    let mut out = String::new();
    for l in text.lines() {
        if l.starts_with('[') {
            in_tracker = l.starts_with("[tracker");
            in_model = l == "[detector]" || l == "[depth]";
        }
        let key_like =
            |t: &str| t.split_once(" = ").is_some_and(|(k, _)| k.chars().all(|c| c.is_ascii_lowercase() || c == '_'));
        // The model keys are commented out so that each build's own default applies (int8 with
        // ONNX Runtime, fp32 in the static binary); the commented value is the ONNX Runtime one.
        let model_key = |t: &str| t.starts_with("model = ");
        match l.strip_prefix("# ") {
            Some(t) if in_tracker && (key_like(t) || t == "[tracker.noise]") => out.push_str(t),
            Some(t) if in_model && model_key(t) => out.push_str(t),
            _ => out.push_str(l),
        }
        out.push('\n');
    }
    out
}

/// Every key of the built-in defaults is written in config/fme.toml (the tracker's as commented-out
/// preset values, the models as commented-out paths), none left to be discovered; those commented values are the defaults; and
/// `fme config show` prints a config that reads back equal.
#[test]
fn shipped_config_spells_out_every_key() {
    fn keys(t: &toml::Table, prefix: &str, out: &mut Vec<String>) {
        for (k, v) in t {
            match v {
                toml::Value::Table(sub) => keys(sub, &format!("{prefix}{k}."), out),
                _ => out.push(format!("{prefix}{k}")),
            }
        }
    }
    let shown = Config::default().to_toml();
    let defaults: toml::Table = toml::from_str(&shown).expect("config show is TOML");
    let spelled = shipped_with_commented_keys();
    let file: toml::Table = toml::from_str(&spelled).expect("TOML");
    let (mut want, mut have) = (Vec::new(), Vec::new());
    keys(&defaults, "", &mut want);
    keys(&file, "", &mut have);
    let missing: Vec<&String> = want.iter().filter(|k| !have.contains(k)).collect();
    assert!(missing.is_empty(), "config/fme.toml lacks {missing:?}");
    assert!(want.len() > 100, "{} keys", want.len());
    assert_eq!(Config::parse(&spelled, Path::new("spelled.toml")).expect("loads"), Config::default());
    assert_eq!(Config::parse(&shown, Path::new("shown.toml")).expect("reads back"), Config::default());
}

/// A copy of config/fme.toml with only the preset changed gets that preset's settings.
#[test]
fn changing_the_preset_in_the_shipped_file_takes_effect() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fme.toml");
    let text = std::fs::read_to_string(&p).expect("read").replace("preset = \"default\"", "preset = \"sort\"");
    let c = Config::parse(&text, Path::new("copy.toml")).expect("loads");
    assert_eq!(c.tracker, fme::track::TrackerConfig::sort());
}

#[test]
fn every_key_in_shipped_config_is_commented() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fme.toml");
    let text = std::fs::read_to_string(&p).expect("read");
    let lines: Vec<&str> = text.lines().collect();
    let is_key = |t: &str| !t.is_empty() && !t.starts_with('#') && !t.starts_with('[');
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim();
        if !is_key(t) {
            continue;
        }
        // Walk back over the keys of the same group: the first line above them that is not a key
        // must be the comment that documents them.
        let above = lines[..i].iter().rev().map(|p| p.trim()).find(|p| !is_key(p));
        assert!(above.is_some_and(|p| p.starts_with('#')), "config/fme.toml line {}: `{t}` has no comment", i + 1);
    }
}

#[test]
fn board_profiles_are_valid_configs() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("boards");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).expect("boards/") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "toml") {
            Config::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 4, "at least four board profiles, found {n}");
}

/// `fme config check` warns, without failing, while a server listening beyond loopback has an
/// empty allow list (the board profiles ship it empty for the installer to fill in).
#[test]
fn config_check_warns_about_servers_open_to_every_address() {
    let dir = tempfile::tempdir().expect("tempdir");
    let check = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("write");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_fme"))
            .args(["config", "check"])
            .arg(&p)
            .output()
            .expect("run fme");
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let open = check("open.toml", "[output.modbus]\nlisten = \"0.0.0.0:502\"\nallow = []\n");
    assert!(open.contains("warning: key `output.modbus.allow`"), "{open}");
    let listed = check("listed.toml", "[output.modbus]\nlisten = \"0.0.0.0:502\"\nallow = [\"192.168.1.20\"]\n");
    assert!(!listed.contains("warning"), "{listed}");
    let local = check("local.toml", "[output.metrics]\nlisten = \"127.0.0.1:9464\"\n");
    assert!(!local.contains("warning"), "{local}");
}

/// `fme config check`: the shipped file passes; each broken file exits 2 with a message naming the
/// file, the line and the key, also inside inline tables and dotted keys.
#[test]
fn config_check_names_file_line_and_key() {
    let fme = || std::process::Command::new(env!("CARGO_BIN_EXE_fme"));
    let ok = fme().args(["config", "check", "config/fme.toml"]).current_dir(env!("CARGO_MANIFEST_DIR")).output();
    let ok = ok.expect("run fme");
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let dir = tempfile::tempdir().expect("tempdir");
    let cases: &[(&str, usize, &str)] = &[
        ("[detector]\nrate_hz = 10.0\nconfdence = 0.3\n", 3, "detector.confdence"),
        ("[depth]\n\nrate_hz = \"fast\"\n", 3, "depth.rate_hz"),
        ("[output.modbus]\nmode = \"udp\"\n", 2, "output.modbus.mode"),
        ("[detector]\nconfidence = 1.5\n", 2, "detector.confidence"),
        (
            "# inline\n\ntracker = { preset = \"sort\", iou_treshold = 0.3 }\n[source]\nfps = 30\n",
            3,
            "tracker.iou_treshold",
        ),
        ("[source]\nfps = 30\n[motion]\nmin_fish = 3\nspeed_span_s = -1.0\n", 5, "motion.speed_span_s"),
        ("# a comment\n[sourcee]\npath = \"x\"\n", 2, "sourcee"),
        ("[source\npath = \"x\"\n", 1, "source"),
        ("\n[tracker]\npreset = \"bytetrack\"\n", 3, "tracker.preset"),
        ("[feeding]\non_above_mps = 0.1\noff_below_mps = 0.2\n", 3, "feeding.off_below_mps"),
        ("[postprocess]\ndepth_smoothing_s = -1.0\n", 2, "postprocess.depth_smoothing_s"),
        ("[tracker]\nmin_hits = 2\niou_threshold = 1.5\n", 3, "tracker.iou_threshold"),
        ("[output]\nmodbus.max_connections = 0\n", 2, "output.modbus.max_connections"),
    ];
    for (i, (text, line, key)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("broken{i}.toml"));
        std::fs::write(&p, text).expect("write");
        let out = fme().args(["config", "check"]).arg(&p).output().expect("run fme");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "case {i}: {err}");
        let want = format!("broken{i}.toml:{line}: key `{key}`");
        assert!(err.contains(&want), "case {i}: want {want:?} in {err}");
    }
    let out = fme().args(["config", "check"]).arg(dir.path().join("none.toml")).output().expect("run fme");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("none.toml"));
}

/// `fme config check` checks the files a config names (exists, readable, parses), so a passing check
/// means `fme run` does not stop at start for one: exit 2 naming the key and the file.
#[test]
fn config_check_checks_the_files_it_names() {
    let fme = || {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_fme"));
        c.current_dir(env!("CARGO_MANIFEST_DIR"));
        c
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path().display();
    for (name, text) in [("bad.json", "{"), ("corrupt.onnx", "not an onnx model"), ("ca.pem", "no certificate")] {
        std::fs::write(dir.path().join(name), text).expect("write");
    }
    let seq = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/swarm20");
    let good =
        format!("[source]\npath = \"{}\"\n[camera]\ncalibration = \"{}/meta.json\"\n", seq.display(), seq.display());
    let cases = [
        (format!("[camera]\ncalibration = \"{d}/missing.json\"\n"), "camera.calibration", "missing.json"),
        (format!("[camera]\ncalibration = \"{d}/bad.json\"\n"), "camera.calibration", "bad.json"),
        (format!("[detector]\nmodel = \"{d}/corrupt.onnx\"\n"), "detector.model", "not an ONNX model"),
        (format!("[depth]\nmodel = \"{d}/missing.onnx\"\n"), "depth.model", "missing.onnx"),
        (format!("[output.mqtt]\ntls = true\nca_file = \"{d}/ca.pem\"\n"), "output.mqtt.ca_file", "ca.pem"),
        (
            format!("[output.mqtt]\nusername = \"u\"\npassword_file = \"{d}/none\"\n"),
            "output.mqtt.password_file",
            "none",
        ),
        (format!("[source]\npath = \"{d}/no-such-recording\"\n"), "source.path", "no-such-recording"),
    ];
    for (i, (text, key, file)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("files{i}.toml"));
        std::fs::write(&p, text).expect("write");
        let out = fme().args(["config", "check"]).arg(&p).output().expect("run fme");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "case {i}: {err}");
        assert!(err.contains(&format!("key `{key}`")) && err.contains(file), "case {i}: {err}");
    }
    let p = dir.path().join("good.toml");
    std::fs::write(&p, good).expect("write");
    let out = fme().args(["config", "check"]).arg(&p).output().expect("run fme");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `fme config show` prints the effective config with `--set` overrides; a bad `--set` is named.
#[test]
fn config_show_applies_overrides() {
    let fme = || std::process::Command::new(env!("CARGO_BIN_EXE_fme"));
    let out = fme()
        .args(["config", "show", "--set", "detector.rate_hz=30", "--set", "source.path=/dev/video2"])
        .output()
        .expect("run fme");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let shown = String::from_utf8_lossy(&out.stdout);
    let c = Config::parse(&shown, Path::new("shown")).expect("shown config reads back");
    assert_eq!((c.detector.rate_hz, c.source.path.to_str()), (30.0, Some("/dev/video2")));
    assert_eq!(
        Config { detector: Config::default().detector, source: Config::default().source, ..c },
        Config::default()
    );
    let out = fme().args(["config", "show", "--set", "detector.rate_hz=fast"]).output().expect("run fme");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--set detector.rate_hz=fast") && err.contains("detector.rate_hz"), "{err}");
}
