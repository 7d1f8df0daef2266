//! The recorded swarm under `tests/data/swarm20` loads with the reader, is self-consistent, and is
//! what its `COMMAND` produces with the current generator (checked on the first frames: a shorter
//! run of the same command is an exact prefix of the longer one).

use fme::sequence::Sequence;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/swarm20")
}

#[test]
fn recorded_swarm_loads_and_is_consistent() {
    let seq = Sequence::open(data()).unwrap();
    assert_eq!((seq.len(), seq.info.im_width, seq.info.im_height), (120, 640, 384));
    assert_eq!(seq.meta.as_ref().expect("meta.json").fish, Some(20));
    assert_eq!(seq.meta.as_ref().expect("meta.json").preset, "swarm");
    assert_eq!(seq.world.len(), 120 * 20);
    assert!(seq.has_depth && seq.depth_paths().len() == 120);
    let world: BTreeMap<(u32, u32), _> = seq.world.iter().map(|r| ((r.frame, r.id), r)).collect();
    for g in &seq.gt {
        let w = world[&(g.frame, g.id)];
        assert!(g.bbox.contains(seq.camera.expect("camera").world_to_pixel(&w.position).unwrap()));
    }
    let depth = seq.read_depth(60).unwrap();
    assert!(depth.mm.iter().all(|&v| v > 0), "the closed pond gives depth everywhere");
}

#[test]
fn command_file_reproduces_the_first_frames() {
    let text = std::fs::read_to_string(data().join("COMMAND")).unwrap();
    let words: Vec<&str> = text.split_whitespace().collect();
    assert_eq!(&words[..2], &["fme", "synth"], "{text}");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("again");
    let mut args: Vec<String> = Vec::new();
    let mut it = words[2..].iter();
    while let Some(&w) = it.next() {
        args.push(w.to_string());
        match w {
            "--out" => {
                it.next();
                args.push(out.to_string_lossy().into_owned());
            }
            "--frames" => {
                it.next();
                args.push("3".into());
            }
            _ => {}
        }
    }
    let r = Command::new(env!("CARGO_BIN_EXE_fme")).arg("synth").args(&args).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    for f in ["img1/000001.jpg", "img1/000003.jpg", "depth/000002.png"] {
        assert!(std::fs::read(out.join(f)).unwrap() == std::fs::read(data().join(f)).unwrap(), "{f} differs");
    }
    let short = Sequence::open(&out).unwrap();
    let long = Sequence::open(data()).unwrap();
    let prefix: Vec<_> = long.gt.iter().filter(|g| g.frame <= 3).cloned().collect();
    assert_eq!(short.gt, prefix);
}
