//! `fme synth` rejects bad input with a message naming the problem and leaves nothing half-written.

use std::path::Path;
use std::process::{Command, Output};

fn fme(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fme")).arg("synth").args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn bad_arguments_exit_non_zero_naming_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("seq");
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["--preset", "swarm", "--out", o, "--k1", "-0.2"], "--k1 -0.2"),
        (&["--preset", "shoal", "--out", o], "shoal"),
        (&["--preset", "swarm", "--out", o, "--frames", "0"], "--frames"),
        (&["--preset", "swarm", "--out", o, "--fish", "201"], "--fish 201"),
        (&["--preset", "swarm", "--out", o, "--water", "12C"], "12C"),
        (&["--preset", "swarm", "--out", o, "--layout", "Z"], "Z"),
    ];
    for (args, needle) in cases {
        let r = fme(args);
        assert!(!r.status.success(), "{args:?} succeeded");
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", stderr(&r));
        assert!(stderr(&r).contains(needle), "{args:?}: {}", stderr(&r));
    }
    assert!(entries(tmp.path()).is_empty(), "bad arguments left {:?}", entries(tmp.path()));
}

#[test]
fn output_folder_rules() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("seq");
    let o = out.to_str().unwrap();
    let small = ["--preset", "single", "--out", o, "--frames", "2", "--width", "64", "--height", "48"];
    let r = fme(&small);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(String::from_utf8_lossy(&r.stdout).contains(o));
    let first = std::fs::read(out.join("gt/world.csv")).unwrap();

    // An existing sequence is not replaced without --force, and stays intact.
    let r = fme(&small);
    assert_eq!(r.status.code(), Some(1));
    assert!(stderr(&r).contains("not empty") && stderr(&r).contains("--force"), "{}", stderr(&r));
    assert_eq!(std::fs::read(out.join("gt/world.csv")).unwrap(), first);

    // With --force it is replaced (here by a different seed).
    let mut forced = small.to_vec();
    forced.extend(["--force", "--seed", "9"]);
    let r = fme(&forced);
    assert!(r.status.success(), "{}", stderr(&r));
    assert_ne!(std::fs::read(out.join("gt/world.csv")).unwrap(), first);
    assert_eq!(entries(tmp.path()), vec!["seq".to_string()], "staging folder left behind");

    // A folder that is not fme output is never replaced, even with --force.
    let mine = tmp.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("thesis.txt"), "precious").unwrap();
    let r = fme(&["--preset", "single", "--out", mine.to_str().unwrap(), "--frames", "1", "--force"]);
    assert!(!r.status.success() && stderr(&r).contains("refusing"), "{}", stderr(&r));
    assert_eq!(entries(&mine), vec!["thesis.txt".to_string()]);

    // An output below a regular file cannot be created: the error names the path.
    let file = tmp.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let below = file.join("seq");
    let r = fme(&["--preset", "single", "--out", below.to_str().unwrap(), "--frames", "1"]);
    assert_eq!(r.status.code(), Some(1));
    assert!(stderr(&r).contains(file.to_str().unwrap()), "{}", stderr(&r));
}
