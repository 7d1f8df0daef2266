//! `make install` (scripts/install.sh) into a DESTDIR: the layout the systemd unit expects, an
//! installed executable that finds its models and checks its config from anywhere, and a second
//! install that keeps a commissioned box's config.

use std::path::Path;
use std::process::{Command, Output};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const PREFIX: &str = "/opt/fme-test";

fn install(destdir: &Path, board: &str) -> Output {
    Command::new("bash")
        .arg(Path::new(ROOT).join("scripts/install.sh"))
        .arg(env!("CARGO_BIN_EXE_fme"))
        .env("PREFIX", PREFIX)
        .env("DESTDIR", destdir)
        .env("BOARD", board)
        .output()
        .expect("bash runs")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn install_lays_out_binary_models_library_unit_docs_and_config() {
    let dest = tempfile::tempdir().expect("temp dir");
    let o = install(dest.path(), "");
    assert!(o.status.success(), "install failed: {}", text(&o));
    let d = dest.path().join(PREFIX.trim_start_matches('/'));
    for f in [
        "bin/fme",
        "share/fme/models/fish_det_int8.onnx",
        "share/fme/models/fish_det_fp32.onnx",
        "share/fme/models/fish_depth_int8.onnx",
        "share/fme/models/fish_depth_fp32.onnx",
        "lib/fme/libonnxruntime.so",
        "lib/systemd/system/fme.service",
        "share/doc/fme/README.md",
        "share/doc/fme/docs/deployment.md",
        "share/doc/fme/docs/plc-integration.md",
    ] {
        assert!(d.join(f).is_file(), "{f} not installed");
    }
    assert!(dest.path().join("etc/fme/fme.toml").is_file());

    // The unit points at what was installed, not at /usr/local.
    let unit = std::fs::read_to_string(d.join("lib/systemd/system/fme.service")).expect("unit");
    assert!(unit.contains(&format!("ExecStart={PREFIX}/bin/fme run --config /etc/fme/fme.toml")), "{unit}");
    assert!(unit.contains(&format!("ORT_DYLIB_PATH={PREFIX}/lib/fme/libonnxruntime.so")), "{unit}");
    assert!(unit.contains(&format!("Documentation=file://{PREFIX}/share/doc/fme/README.md")), "{unit}");
    assert!(!unit.contains("/usr/local"), "a path left at /usr/local: {unit}");

    // Stripped: no symbol table left.
    let nm = Command::new("nm").arg(d.join("bin/fme")).output().expect("nm runs");
    assert!(text(&nm).contains("no symbols"), "not stripped: {}", text(&nm).lines().next().unwrap_or(""));

    // The installed executable, run from an empty directory, finds the models beside its prefix and
    // passes `config check` on the installed config (which checks every file the config names).
    let cwd = tempfile::tempdir().expect("temp dir");
    let check = Command::new(d.join("bin/fme"))
        .args(["config", "check"])
        .arg(dest.path().join("etc/fme/fme.toml"))
        .current_dir(cwd.path())
        .env("ORT_DYLIB_PATH", d.join("lib/fme/libonnxruntime.so"))
        .output()
        .expect("installed fme runs");
    assert!(check.status.success(), "config check of the installed box failed: {}", text(&check));
}

#[test]
fn a_second_install_keeps_the_commissioned_config_and_a_bad_board_is_named() {
    let dest = tempfile::tempdir().expect("temp dir");
    let etc = dest.path().join("etc/fme/fme.toml");
    std::fs::create_dir_all(etc.parent().expect("parent")).expect("mkdir");
    std::fs::write(&etc, "# commissioned\n").expect("write");
    let o = install(dest.path(), "raspberry-pi-5");
    assert!(o.status.success(), "install failed: {}", text(&o));
    assert_eq!(std::fs::read_to_string(&etc).expect("read"), "# commissioned\n");
    assert!(text(&o).contains("exists: kept"), "{}", text(&o));

    let bad = install(dest.path(), "raspberry-pi-9");
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad));
    assert!(text(&bad).contains("BOARD=raspberry-pi-9"), "{}", text(&bad));
}
