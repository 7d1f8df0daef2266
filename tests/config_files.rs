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

#[test]
fn every_key_in_shipped_config_is_commented() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fme.toml");
    let text = std::fs::read_to_string(&p).expect("read");
    let lines: Vec<&str> = text.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with('[') {
            continue;
        }
        // Walk back over the keys of the same group to the comment that documents them.
        let documented =
            lines[..i].iter().rev().take_while(|p| !p.trim().is_empty()).any(|p| p.trim().starts_with('#'));
        assert!(documented, "config/fme.toml line {}: `{t}` has no comment", i + 1);
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
