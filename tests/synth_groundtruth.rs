//! Ground truth written by `fme synth` is exact and self-consistent, checked against the geometry.

use fme::geometry::{Pixel, WorldPoint};
use fme::rng::Rng;
use fme::sequence::Sequence;
use fme::synth::fish::FishShape;
use fme::synth::motion::{self, Activity};
use fme::synth::render::{FrameBuffers, Renderer};
use fme::synth::scene::{self, Layout, Pond};
use fme::synth::{Preset, SynthConfig, WaterType, generate};
use std::collections::BTreeMap;
use std::path::Path;

fn cfg(preset: Preset, fish: usize, frames: u32, w: u32, h: u32) -> SynthConfig {
    SynthConfig {
        preset,
        fish,
        frames,
        seed: 11,
        fps: 30.0,
        width: w,
        height: h,
        water: WaterType::C3,
        layout: Layout::F,
        k1: 0.0,
        cohort: fme::synth::fish::Cohort::default(),
    }
}

fn swarm(dir: &Path) -> Sequence {
    generate(&cfg(Preset::Swarm, 40, 24, 320, 192), dir, false, &|_| {}).unwrap();
    Sequence::open(dir).unwrap()
}

#[test]
fn swarm_ground_truth_is_self_consistent() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = swarm(&tmp.path().join("swarm"));
    assert_eq!(seq.len(), 24);
    assert_eq!(seq.meta.as_ref().expect("meta.json").reference_objects.len(), 10);
    assert_eq!(seq.meta.as_ref().expect("meta.json").fish, Some(40));
    assert_eq!(seq.world.len(), 24 * 40);
    assert!(!seq.gt.is_empty());

    let world: BTreeMap<(u32, u32), _> = seq.world.iter().map(|r| ((r.frame, r.id), r)).collect();
    // The body centre of every fish in the image projects inside its amodal box.
    for g in &seq.gt {
        let w = world[&(g.frame, g.id)];
        let px = seq.camera.expect("camera").world_to_pixel(&w.position).unwrap();
        assert!(g.bbox.contains(px), "frame {} fish {}: centre {px:?} outside {:?}", g.frame, g.id, g.bbox);
        assert!((w.visibility - g.visibility).abs() < 1e-4);
        assert!(g.bbox.w > 1.0 && g.bbox.h > 1.0);
    }
    // Occlusions happen, and most fish are seen.
    assert!(seq.gt.iter().any(|g| g.visibility < 0.9), "no occlusion at all in a 40-fish swarm");
    assert!(seq.gt.iter().filter(|g| g.visibility > 0.99).count() > seq.gt.len() / 3);

    // Central finite differences of the positions match the recorded velocities.
    let dt = 1.0 / seq.meta.as_ref().expect("meta.json").fps;
    let mut worst: f64 = 0.0;
    for f in 2..seq.len() {
        for id in 1..=40 {
            let (a, b, c) = (world[&(f - 1, id)], world[&(f, id)], world[&(f + 1, id)]);
            let fd = (c.position.0 - a.position.0) / (2.0 * dt);
            let err = (fd - b.velocity).norm();
            assert!(err < 0.01 + 0.03 * b.velocity.norm(), "frame {f} fish {id}: fd {fd:?} vs v {:?}", b.velocity);
            worst = worst.max(err);
        }
    }
    assert!(worst > 0.0);

    // Fully visible fish: the depth pixel under the projected centre is the fish's near surface,
    // between the centre's depth minus half a body length and the centre's depth.
    let mut checked = 0;
    for f in [1, 12, 24] {
        let depth = seq.read_depth(f).unwrap();
        for g in seq.gt_of_frame(f).filter(|g| g.visibility == 1.0) {
            let w = world[&(f, g.id)];
            let px = seq.camera.expect("camera").world_to_pixel(&w.position).unwrap();
            if px.u < 0.0 || px.v < 0.0 {
                continue;
            }
            let Some(d) = depth.get(px.u as u32, px.v as u32) else { continue };
            let zc = seq.camera.expect("camera").pose.to_camera(&w.position).depth().0;
            assert!(
                d.0 <= zc + 0.001 && d.0 >= zc - 0.5 * w.length.0,
                "frame {f} fish {}: depth {d} vs centre {zc}",
                g.id
            );
            checked += 1;
        }
    }
    assert!(checked > 10, "only {checked} fully visible fish checked");
}

#[test]
fn distorted_camera_keeps_centres_inside_boxes() {
    let tmp = tempfile::tempdir().unwrap();
    let mut c = cfg(Preset::Swarm, 40, 4, 320, 192);
    c.k1 = -0.06;
    generate(&c, &tmp.path().join("d"), false, &|_| {}).unwrap();
    let seq = Sequence::open(tmp.path().join("d")).unwrap();
    assert_eq!(seq.camera.expect("camera").intrinsics.distortion[0], -0.06);
    c.k1 = -0.2;
    let err = generate(&c, &tmp.path().join("e"), false, &|_| {}).unwrap_err().to_string();
    assert!(err.contains("--k1"), "{err}");
    let world: BTreeMap<(u32, u32), _> = seq.world.iter().map(|r| ((r.frame, r.id), r)).collect();
    for g in &seq.gt {
        let px = seq.camera.expect("camera").world_to_pixel(&world[&(g.frame, g.id)].position).unwrap();
        assert!(g.bbox.contains(px), "centre {px:?} outside {:?}", g.bbox);
    }
}

#[test]
fn reference_cube_front_faces_match_the_depth_map() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = swarm(&tmp.path().join("swarm"));
    let depth = seq.read_depth(1).unwrap();
    let mut matched = 0;
    let eye = seq.camera.expect("camera").pose.camera_center().0;
    for c in &seq.meta.as_ref().expect("meta.json").reference_objects {
        let f = c.front_face_center();
        let px = seq.camera.expect("camera").world_to_pixel(&f).unwrap();
        let (i, j) = (px.u.floor(), px.v.floor());
        // Camera z where the ray through that pixel's centre meets the plane of the front face.
        let ray = seq.camera.expect("camera").pose.rotation.transpose()
            * seq.camera.expect("camera").intrinsics.ray(Pixel::new(i + 0.5, j + 0.5));
        let axis = (0..3).find(|&a| (c.front_face_center_w[a] - c.center_w[a]).abs() > 1e-9).unwrap();
        let z = (c.front_face_center_w[axis] - eye[axis]) / ray[axis];
        let hit = eye + ray * z;
        assert!((hit - f.0).norm() < 0.05, "cube {}: pixel ray leaves the face", c.id);
        // A fish may swim in front of a cube: only pixels showing the cube count (and they must agree).
        if let Some(d) = depth.get(i as u32, j as u32)
            && (d.0 - z).abs() < 0.05
        {
            assert!((d.0 - z).abs() < 0.0006, "cube {}: depth {} vs front face {z}", c.id, d.0);
            matched += 1;
        }
    }
    assert!(matched >= 7, "only {matched} of 10 cube faces seen in the depth map");
}

#[test]
fn every_fish_pixel_of_the_depth_map_lies_on_that_fish_and_inside_its_box() {
    for k1 in [0.0, -0.06] {
        check_fish_pixels(k1);
    }
}

fn check_fish_pixels(k1: f64) {
    let pond = Pond::default();
    let (w, h) = (320, 192);
    let mut camera = scene::default_camera(&pond, w, h).unwrap();
    camera.intrinsics.distortion[0] = k1;
    let cubes = scene::reference_cubes(Layout::F, &pond, &camera);
    let r = Renderer::new(camera, w, h, pond, WaterType::C3, &cubes, 5);
    let mut rng = Rng::new(5);
    let act = Activity::swarm(&mut rng);
    let m = motion::swarm(30, 3, 30.0, &pond, &act, fme::synth::fish::Cohort::default(), &mut rng);
    let mut buf = FrameBuffers::new(w, h);
    let px = r.render(3, 2.0 / 30.0, &m.bodies, &m.states[2], &mut buf);
    let depth = buf.depth_map(w, h);
    let shapes: Vec<FishShape> = m.bodies.iter().zip(&m.states[2]).map(|(b, s)| FishShape::new(b, s)).collect();
    let mut counted = vec![0u32; shapes.len()];
    for j in 0..h {
        for i in 0..w {
            let id = buf.ids[(j * w + i) as usize];
            if id == 0 {
                continue;
            }
            let k = id as usize - 1;
            counted[k] += 1;
            let centre = Pixel::new(f64::from(i) + 0.5, f64::from(j) + 0.5);
            let b = px[k].bbox;
            assert!(
                centre.u >= b.x - 0.01
                    && centre.u <= b.right() + 0.01
                    && centre.v >= b.y - 0.01
                    && centre.v <= b.bottom() + 0.01,
                "k1 {k1}: pixel ({i},{j}) of fish {id} outside its box {b:?}"
            );
            let d = depth.get(i, j).unwrap();
            let p = camera.pixel_to_world(centre, d).unwrap();
            let s = &shapes[k];
            let on_part = s.parts.iter().any(|e| {
                let q = e.axes.transpose() * (p.0 - e.center);
                (q.component_div(&e.radii).norm() - 1.0).abs() < 0.1
            });
            let on_fin = s.fins.iter().any(|t| {
                let n = (t.v[1] - t.v[0]).cross(&(t.v[2] - t.v[0])).normalize();
                (p.0 - t.v[0]).dot(&n).abs() < 0.003
            });
            assert!(on_part || on_fin, "k1 {k1}: pixel ({i},{j}) of fish {id} at {p:?} is on none of its surfaces");
            assert!(p.distance(&WorldPoint(m.states[2][k].position)).0 <= 0.5 * m.bodies[k].length + 0.01);
        }
    }
    for (k, f) in px.iter().enumerate() {
        assert_eq!(f.visible, counted[k], "fish {}", k + 1);
        assert!(f.visible <= f.alone);
    }
    assert!(counted.iter().filter(|&&c| c > 0).count() > 10);
}

#[test]
fn same_arguments_give_identical_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let c = cfg(Preset::Feeding, 12, 5, 160, 96);
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    generate(&c, &a, false, &|_| {}).unwrap();
    generate(&c, &b, false, &|_| {}).unwrap();
    let mut files = Vec::new();
    for sub in ["img1", "depth"] {
        for e in std::fs::read_dir(a.join(sub)).unwrap() {
            files.push(Path::new(sub).join(e.unwrap().file_name()));
        }
    }
    files.extend(["gt/gt.txt", "gt/world.csv", "meta.json"].map(Into::into));
    assert_eq!(files.len(), 13);
    for f in &files {
        let (x, y) = (std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap());
        assert!(x == y, "{} differs", f.display());
    }
    // seqinfo differs only by name (the folder name).
    let mut other = c;
    other.seed = 12;
    let d = tmp.path().join("d");
    generate(&other, &d, false, &|_| {}).unwrap();
    assert_ne!(std::fs::read(a.join("gt/world.csv")).unwrap(), std::fs::read(d.join("gt/world.csv")).unwrap());
}

#[test]
fn postproc_suite_has_eighteen_scenes_and_occluded_ones_are_occluded() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("suite");
    let s = generate(&cfg(Preset::PostprocSuite, 1, 30, 160, 96), &out, false, &|_| {}).unwrap();
    assert_eq!(s.sequences.len(), 18);
    let names = std::fs::read_to_string(out.join("scenes.txt")).unwrap();
    assert_eq!(names.lines().count(), 18);
    for name in names.lines() {
        let seq = Sequence::open(out.join(name)).unwrap();
        let fish1: Vec<f64> = seq.world.iter().filter(|r| r.id == 1).map(|r| r.visibility).collect();
        assert_eq!(fish1.len(), 30);
        let min = fish1.iter().cloned().fold(1.0, f64::min);
        if name.ends_with("-occ") {
            assert_eq!(seq.meta.as_ref().expect("meta.json").fish, Some(2));
            assert!(min < 0.6, "{name}: fish 1 never hidden (min visibility {min})");
        } else {
            assert_eq!(seq.meta.as_ref().expect("meta.json").fish, Some(1));
            assert!(min > 0.99, "{name}: single fish not fully visible (min {min})");
        }
        // Speed follows the profile: accelerating scenes end faster than they start.
        let speed: Vec<f64> = seq.world.iter().filter(|r| r.id == 1).map(|r| r.velocity.norm()).collect();
        let (first, last) = (speed[0], speed[29]);
        if name.starts_with("acc") {
            assert!(last > 2.0 * first, "{name}");
        } else if name.starts_with("dec") {
            assert!(first > 2.0 * last, "{name}");
        } else {
            assert!((first - last).abs() < 1e-9, "{name}");
        }
    }
}
