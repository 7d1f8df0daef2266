//! The sequence writer and reader agree, and bad sequences are rejected with the file at fault.

use fme::geometry::{Camera, Intrinsics, PixelBox, Pose, WorldPoint};
use fme::sequence::{
    CameraMeta, DepthMap, GeneratorMeta, GtBox, Meta, ReferenceObject, SeqInfo, Sequence, SequenceWriter, StagedDir,
    WaterMeta, WorldRow, read_depth_png, write_depth_png,
};
use fme::units::Metres;
use nalgebra::Vector3;

const W: u32 = 32;
const H: u32 = 24;
const N: u32 = 3;

fn camera() -> Camera {
    let intrinsics = Intrinsics::from_hfov(W, H, 70.0).unwrap();
    let pose = Pose::look_at(WorldPoint::new(3.0, -0.3, 1.5), WorldPoint::new(3.0, 3.0, 1.2), Vector3::z()).unwrap();
    Camera { intrinsics, pose }
}

fn meta() -> Meta {
    Meta {
        fps: 30.0,
        width: W,
        height: H,
        frames: N,
        seed: 7,
        preset: "test".into(),
        generator: GeneratorMeta { name: "test".into(), version: "0".into() },
        camera: CameraMeta::from_camera(&camera()),
        water: WaterMeta { kind: "3C".into(), attenuation_per_m: [0.342, 0.198, 0.223], backscatter: [0.1, 0.4, 0.4] },
        reference_objects: vec![ReferenceObject {
            id: 1,
            size_m: 0.1,
            center_w: [3.0, 3.0, 0.05],
            front_face_center_w: [3.0, 2.95, 0.05],
        }],
        layout: Some("F".into()),
        pond_size_m: Some([6.0, 4.0, 3.0]),
        fish: Some(1),
    }
}

fn info() -> SeqInfo {
    SeqInfo {
        name: "tiny".into(),
        im_dir: "img1".into(),
        frame_rate: 30.0,
        seq_length: N,
        im_width: W,
        im_height: H,
        im_ext: ".jpg".into(),
    }
}

fn rows() -> (Vec<GtBox>, Vec<WorldRow>) {
    let mut gt = Vec::new();
    let mut world = Vec::new();
    for f in 1..=N {
        let x = f64::from(f);
        gt.push(GtBox { frame: f, id: 1, bbox: PixelBox::new(x, 2.25, 10.5, 4.0), visibility: 0.75 });
        world.push(WorldRow {
            frame: f,
            id: 1,
            position: WorldPoint::new(3.0 + 0.01 * x, 2.0, 1.25),
            velocity: Vector3::new(0.3, 0.0, -0.125),
            length: Metres(0.35),
            visibility: 0.75,
        });
    }
    (gt, world)
}

fn write_sequence(target: &std::path::Path) {
    let stage = StagedDir::create(target, false).unwrap();
    let w = SequenceWriter::new(stage.path()).unwrap();
    for f in 1..=N {
        let img = image::RgbImage::from_pixel(W, H, image::Rgb([10, 80 + f as u8, 90]));
        w.write_frame(f, &img, 90).unwrap();
        let mut d = DepthMap::new(W, H);
        d.mm[5] = 1234 + f as u16;
        w.write_depth(f, &d).unwrap();
    }
    let (gt, world) = rows();
    w.finish(&info(), &meta(), &gt, &world).unwrap();
    stage.commit().unwrap();
}

#[test]
fn written_sequence_loads_back_identically() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("seq");
    write_sequence(&target);
    let seq = Sequence::open(&target).unwrap();
    assert_eq!(seq.info, info());
    // serde_json (without its `float_roundtrip` feature) may move the last bit of a float.
    let mut want = meta();
    let (a, b) = (&seq.meta.as_ref().expect("meta.json").camera, &want.camera);
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * (1.0 + y.abs());
    assert!(close(a.fx, b.fx) && close(a.fy, b.fy) && close(a.cx, b.cx) && close(a.cy, b.cy));
    for i in 0..3 {
        assert!(close(a.world_to_camera.translation[i], b.world_to_camera.translation[i]));
        for j in 0..3 {
            assert!(close(a.world_to_camera.rotation[i][j], b.world_to_camera.rotation[i][j]));
        }
    }
    want.camera = a.clone();
    assert_eq!(seq.meta.as_ref(), Some(&want));
    let (gt, world) = rows();
    assert_eq!(seq.gt, gt);
    assert_eq!(seq.world, world);
    let p = WorldPoint::new(3.1, 2.0, 1.0);
    let (u, v) = (seq.camera.expect("camera").world_to_pixel(&p).unwrap(), camera().world_to_pixel(&p).unwrap());
    assert!((u.u - v.u).abs() < 1e-9 && (u.v - v.v).abs() < 1e-9);
    assert_eq!(seq.frame_paths().len(), N as usize);
    let d = seq.read_depth(2).unwrap();
    assert_eq!(d.get(5, 0), Some(Metres(1.236)));
    assert_eq!(d.get(6, 0), None);
    assert!((seq.timestamp(4).0 - 0.1).abs() < 1e-12);
    // Nothing but the sequence is left next to it (the staging folder was renamed).
    let names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, vec![std::ffi::OsString::from("seq")]);
}

#[test]
fn depth_png_round_trips_all_values() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("d.png");
    let mut d = DepthMap::new(300, 250);
    for (i, v) in d.mm.iter_mut().enumerate() {
        *v = (i * 7 % 65536) as u16;
    }
    write_depth_png(&p, &d).unwrap();
    assert_eq!(read_depth_png(&p).unwrap(), d);
    assert_eq!(DepthMap::encode(1.2344), 1234);
    assert_eq!(DepthMap::encode(-1.0), 0);
    assert_eq!(DepthMap::encode(f64::NAN), 0);
}

#[test]
fn reader_names_the_file_at_fault() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("seq");
    write_sequence(&target);

    std::fs::write(target.join("gt/gt.txt"), "1,1,1,2,3,4,1,1,1\n2,1,1,2,3,oops,1,1,1\n").unwrap();
    let err = Sequence::open(&target).unwrap_err().to_string();
    assert!(err.contains("gt.txt:2:"), "{err}");

    let (gt, _) = rows();
    fme::sequence::write_gt(&target.join("gt/gt.txt"), &gt).unwrap();
    std::fs::remove_file(target.join("img1/000002.jpg")).unwrap();
    let err = Sequence::open(&target).unwrap_err().to_string();
    assert!(err.contains("000002.jpg") && err.contains("missing"), "{err}");

    write_sequence(&tmp.path().join("seq2"));
    let mut m = meta();
    m.frames = 9;
    m.write(&tmp.path().join("seq2/meta.json")).unwrap();
    let err = Sequence::open(tmp.path().join("seq2")).unwrap_err().to_string();
    assert!(err.contains("meta.json") && err.contains("disagree"), "{err}");

    std::fs::write(tmp.path().join("seq2/meta.json"), "{\"fps\": 30}").unwrap();
    let err = Sequence::open(tmp.path().join("seq2")).unwrap_err().to_string();
    assert!(err.contains("meta.json") && err.contains("missing field"), "{err}");
}

/// What a real recording has opens: a plain MOTChallenge folder (no meta.json, no depth/, no
/// world.csv), then with a calibration as `fme calibrate` writes it (camera, references, size; no
/// fps, frames, generator or water), whose frame rate comes from seqinfo.ini.
#[test]
fn a_plain_motchallenge_folder_and_a_calibration_only_meta_json_open() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seq");
    write_sequence(&dir);
    for p in ["meta.json", "gt/world.csv"] {
        std::fs::remove_file(dir.join(p)).unwrap();
    }
    std::fs::remove_dir_all(dir.join("depth")).unwrap();
    // Images beyond seqLength are not part of the sequence.
    std::fs::copy(dir.join("img1/000001.jpg"), dir.join("img1/000004.jpg")).unwrap();
    let seq = Sequence::open(&dir).unwrap();
    assert!(seq.meta.is_none() && seq.camera.is_none() && seq.reference_objects().is_empty());
    assert!(seq.has_gt && !seq.has_depth && seq.world.is_empty());
    assert_eq!((seq.len(), seq.frame_paths().len(), seq.gt.len()), (N, N as usize, N as usize));
    assert!((seq.timestamp(3).0 - 2.0 / 30.0).abs() < 1e-12);

    let calib = serde_json::json!({
        "width": W, "height": H,
        "camera": CameraMeta::from_camera(&camera()),
        "reference_objects": meta().reference_objects,
        "calibrate": {"rms_px": 0.3},
    });
    std::fs::write(dir.join("meta.json"), calib.to_string()).unwrap();
    std::fs::remove_file(dir.join("gt/gt.txt")).unwrap();
    let seq = Sequence::open(&dir).unwrap();
    let m = seq.meta.as_ref().expect("meta.json");
    assert_eq!((m.fps, m.width, m.height, m.frames), (30.0, W, H, N));
    assert_eq!(m.reference_objects.len(), 1);
    assert!(seq.camera.is_some() && !seq.has_gt && seq.gt.is_empty());
    // A stated size that disagrees with seqinfo.ini is still an error naming meta.json.
    let wrong = serde_json::json!({"width": W + 1, "camera": CameraMeta::from_camera(&camera())});
    std::fs::write(dir.join("meta.json"), wrong.to_string()).unwrap();
    let err = Sequence::open(&dir).unwrap_err().to_string();
    assert!(err.contains("meta.json") && err.contains("disagree"), "{err}");
}

#[test]
fn staging_refuses_non_empty_folders_and_cleans_up() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("seq");
    write_sequence(&target);
    let err = StagedDir::create(&target, false).unwrap_err().to_string();
    assert!(err.contains("not empty"), "{err}");
    // With force an earlier sequence may be replaced.
    drop(StagedDir::create(&target, true).unwrap());
    // A folder that is not fme output is never replaced.
    let other = tmp.path().join("home");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("notes.txt"), "keep me").unwrap();
    assert!(StagedDir::create(&other, true).unwrap_err().to_string().contains("refusing"));
    // An abandoned stage leaves nothing behind; the old sequence is untouched.
    {
        let stage = StagedDir::create(&target, true).unwrap();
        std::fs::write(stage.path().join("x"), "half").unwrap();
    }
    let mut names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    names.sort();
    assert_eq!(names, vec![std::ffi::OsString::from("home"), std::ffi::OsString::from("seq")]);
    assert!(Sequence::open(&target).is_ok());
}
