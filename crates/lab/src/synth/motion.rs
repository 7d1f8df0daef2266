//! Motion presets: centre paths and analytic velocities for every fish at every frame.
//!
//! - `swarm` / `feeding`: Couzin-style zones (repulsion, orientation, attraction; Couzin et al. 2002)
//!   on top of the one-way circular milling of caged salmon (Johansson et al. 2014), speeds of
//!   0.3-1.5 body lengths/s that rise and fall in phases, individual bursts. Integrated with small
//!   sub-steps; the recorded velocity is the integrator's state, so finite differences of the
//!   recorded positions match it to second order.
//! - `single`: one fish on a random smooth path (sum of sinusoids), velocity its exact derivative.
//! - `postproc-suite`: the paper's 18 single-fish scenes (sec. 4.4), exact constant-acceleration paths.

use super::fish::{Cohort, FishBody, FishState, tail_beat_hz};
use super::scene::Pond;
use crate::rng::Rng;
use nalgebra::Vector3;
use std::f64::consts::{PI, TAU};

/// Mean fish length of the presets, metres (farmed salmon in a research pond).
pub const MEAN_LENGTH_M: f64 = 0.35;

/// Every fish of a sequence and its state at every frame.
#[derive(Debug, Clone)]
pub struct Motion {
    /// One body per fish; fish `i` has id `i + 1`.
    pub bodies: Vec<FishBody>,
    /// `states[frame][fish]`, frame 0-based.
    pub states: Vec<Vec<FishState>>,
}

/// Speed envelope of a preset, in body lengths per second, as a function of time.
#[derive(Debug, Clone, Copy)]
pub struct Activity {
    phase: [f64; 3],
    /// Start, full-on duration and decay time constant of a feeding burst (seconds), if any.
    feeding: Option<(f64, f64, f64)>,
}

impl Activity {
    /// Slow and fast phases several times a minute (periods 17 s and 7.3 s).
    pub fn swarm(rng: &mut Rng) -> Self {
        Self { phase: [rng.range(0.0, TAU), rng.range(0.0, TAU), rng.range(0.0, TAU)], feeding: None }
    }

    /// As `swarm`, plus a sharp rise at 30 % of the sequence, held for 20 %, then settling.
    pub fn feeding(rng: &mut Rng, duration: f64) -> Self {
        let mut a = Self::swarm(rng);
        a.feeding = Some((0.3 * duration, 0.2 * duration, (0.12 * duration).max(0.5)));
        a
    }

    /// Swarm speed at time `t`, body lengths per second.
    pub fn body_lengths_per_s(&self, t: f64) -> f64 {
        let base = 0.9
            + 0.42 * (TAU * t / 17.0 + self.phase[0]).sin()
            + 0.18 * (TAU * t / 7.3 + self.phase[1]).sin()
            + 0.06 * (TAU * t / 2.9 + self.phase[2]).sin();
        let base = base.clamp(0.3, 1.5);
        match self.feeding {
            None => base,
            Some((t0, hold, tau)) => {
                let rise = 1.0;
                let env = if t < t0 {
                    0.0
                } else if t < t0 + rise {
                    let x = (t - t0) / rise;
                    x * x * (3.0 - 2.0 * x)
                } else if t < t0 + rise + hold {
                    1.0
                } else {
                    (-(t - t0 - rise - hold) / tau).exp()
                };
                base * (1.0 + 1.2 * env)
            }
        }
    }
}

/// Sub-steps per frame of the swarm integrator.
const SUBSTEPS: usize = 8;

/// Per-fish constants of the swarm model.
struct Agent {
    radius: f64,
    depth: f64,
    pace: f64,
    wander: [f64; 4],
    bursts: Vec<f64>,
}

/// The `swarm` and `feeding` presets.
pub fn swarm(
    n: usize,
    frames: usize,
    fps: f64,
    pond: &Pond,
    activity: &Activity,
    cohort: Cohort,
    rng: &mut Rng,
) -> Motion {
    let bodies: Vec<FishBody> = (0..n).map(|_| FishBody::random(rng, cohort)).collect();
    let centre = pond.mill_center();
    let duration = frames as f64 / fps;
    let ring_max = (centre.x.min(pond.size.x - centre.x).min(centre.y).min(pond.size.y - centre.y) - 0.45).max(0.5);
    let agents: Vec<Agent> = (0..n)
        .map(|_| {
            // Own stream, so the sequence length does not change what the main stream draws next:
            // a short run is then an exact prefix of a longer one.
            let mut brng = Rng::new(rng.next_u64());
            let mut bursts = Vec::new();
            let mut t = brng.range(0.0, 15.0);
            while t < duration {
                bursts.push(t);
                t += brng.range(6.0, 26.0);
            }
            Agent {
                radius: rng.range(0.5, 0.9) * ring_max,
                depth: pond.size.z * rng.range(0.28, 0.62),
                pace: rng.range(0.8, 1.2),
                wander: [rng.range(0.0, TAU), rng.range(0.0, TAU), rng.range(0.12, 0.3), rng.range(0.0, TAU)],
                bursts,
            }
        })
        .collect();
    let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(n);
    let mut vel: Vec<Vector3<f64>> = Vec::with_capacity(n);
    for (a, b) in agents.iter().zip(&bodies) {
        let ang = rng.range(0.0, TAU);
        let p = Vector3::new(centre.x + a.radius * ang.cos(), centre.y + a.radius * ang.sin(), a.depth);
        let tangent = Vector3::new(-ang.sin(), ang.cos(), 0.0);
        pos.push(p);
        vel.push(tangent * activity.body_lengths_per_s(0.0) * b.length * a.pace);
    }
    let dt = 1.0 / (fps * SUBSTEPS as f64);
    let mut phase: Vec<f64> = (0..n).map(|_| rng.range(0.0, TAU)).collect();
    let mut states = Vec::with_capacity(frames);
    let mut acc = vec![Vector3::zeros(); n];
    for frame in 0..frames {
        states.push(
            (0..n)
                .map(|i| FishState {
                    position: pos[i],
                    velocity: vel[i],
                    heading: vel[i].try_normalize(1e-9).unwrap_or_else(Vector3::y),
                    tail_phase: phase[i],
                })
                .collect(),
        );
        for sub in 0..SUBSTEPS {
            let t = (frame * SUBSTEPS + sub) as f64 * dt;
            let bl = activity.body_lengths_per_s(t);
            for (i, a) in acc.iter_mut().enumerate() {
                *a = steer(i, t, bl, &pos, &vel, &bodies, &agents, pond, &centre);
            }
            for i in 0..n {
                vel[i] += acc[i] * dt;
                pos[i] += vel[i] * dt;
                phase[i] += TAU * tail_beat_hz(vel[i].norm(), bodies[i].length) * dt;
            }
        }
    }
    Motion { bodies, states }
}

/// Acceleration of fish `i`: towards a desired velocity from milling, schooling zones, walls, bursts.
#[allow(clippy::too_many_arguments)]
fn steer(
    i: usize,
    t: f64,
    bl: f64,
    pos: &[Vector3<f64>],
    vel: &[Vector3<f64>],
    bodies: &[FishBody],
    agents: &[Agent],
    pond: &Pond,
    centre: &Vector3<f64>,
) -> Vector3<f64> {
    let p = pos[i];
    let a = &agents[i];
    let l = bodies[i].length;
    // Milling: counter-clockwise seen from above, towards the fish's own ring radius and depth.
    let r = Vector3::new(p.x - centre.x, p.y - centre.y, 0.0);
    let rho = r.norm().max(1e-6);
    let radial = r / rho;
    let tangent = Vector3::new(-radial.y, radial.x, 0.0);
    let mut mill = tangent + radial * (1.2 * (a.radius - rho)) + Vector3::z() * (1.0 * (a.depth - p.z));
    // Wander: slow individual meandering.
    let w = a.wander;
    mill += Vector3::new((0.31 * t + w[0]).sin(), (0.23 * t + w[1]).sin(), 0.4 * (0.17 * t + w[3]).sin()) * w[2];
    // Couzin zones in body lengths: repulsion 1, orientation 3, attraction 7.
    let (mut rep, mut align, mut attract) = (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
    let mut n_rep = 0;
    for j in 0..pos.len() {
        if j == i {
            continue;
        }
        let d = pos[j] - p;
        let dist2 = d.norm_squared();
        if dist2 < (1.0 * l) * (1.0 * l) {
            rep -= d / dist2.sqrt().max(1e-6);
            n_rep += 1;
        } else if dist2 < (3.0 * l) * (3.0 * l) {
            align += vel[j].try_normalize(1e-9).unwrap_or_else(Vector3::zeros);
        } else if dist2 < (10.0 * l) * (10.0 * l) {
            attract += d / dist2.sqrt();
        }
    }
    let mut dir = mill * 1.0;
    if n_rep > 0 {
        dir += rep.try_normalize(1e-9).unwrap_or_else(Vector3::zeros) * 1.6;
    } else {
        dir += align.try_normalize(1e-9).unwrap_or_else(Vector3::zeros) * 0.5
            + attract.try_normalize(1e-9).unwrap_or_else(Vector3::zeros) * 0.7;
    }
    // Walls, surface, floor and the camera corner push fish back well before they reach them.
    let margin = 0.55;
    let s = pond.size;
    let push = |d: f64| if d < margin { 4.0 * (margin - d) / margin } else { 0.0 };
    dir += Vector3::new(push(p.x) - push(s.x - p.x), push(p.y - 0.4) - push(s.y - p.y), push(p.z) - push(s.z - p.z));
    // Keep mostly horizontal: fish pitch little.
    let h = (dir.x * dir.x + dir.y * dir.y).sqrt();
    dir.z = dir.z.clamp(-0.35 * h - 0.05, 0.35 * h + 0.05);
    let dir = dir.try_normalize(1e-9).unwrap_or(tangent);
    // Bursts: a smooth 0.9 s speed-up to about twice the pace.
    let mut burst = 0.0;
    for &b in &a.bursts {
        let x = (t - b) / 0.9;
        if (0.0..1.0).contains(&x) {
            burst = (PI * x).sin().powi(2);
        }
    }
    let speed = bl * l * a.pace * (1.0 + 0.9 * burst);
    let desired = dir * speed;
    let acc = (desired - vel[i]) / 0.45;
    let max_acc = 1.5 + 2.5 * burst;
    if acc.norm() > max_acc { acc.normalize() * max_acc } else { acc }
}

/// Sets tail phases by integrating the Strouhal tail-beat frequency along the given states.
fn integrate_tail(states: &mut [Vec<FishState>], bodies: &[FishBody], fps: f64, rng: &mut Rng) {
    let mut phase: Vec<f64> = bodies.iter().map(|_| rng.range(0.0, TAU)).collect();
    for frame in states.iter_mut() {
        for (i, s) in frame.iter_mut().enumerate() {
            s.tail_phase = phase[i];
            phase[i] += TAU * tail_beat_hz(s.velocity.norm(), bodies[i].length) / fps;
        }
    }
}

/// Heading from velocity, keeping the previous one where the fish almost stops.
fn headed(p: Vector3<f64>, v: Vector3<f64>, prev: Option<&FishState>) -> FishState {
    let heading = v.try_normalize(1e-6).or(prev.map(|s| s.heading)).unwrap_or_else(Vector3::x);
    FishState { position: p, velocity: v, heading, tail_phase: 0.0 }
}

/// The `single` preset: one fish on a smooth random 3D path (two sinusoids per axis).
pub fn single(frames: usize, fps: f64, pond: &Pond, cohort: Cohort, rng: &mut Rng) -> Motion {
    let body = FishBody::random(rng, cohort);
    let c = pond.mill_center();
    let s = pond.size;
    // Amplitudes per axis (two terms) within the pond, away from the camera wall.
    let amp = [
        [0.3 * (s.x * 0.5 - 0.6), 0.2 * (s.x * 0.5 - 0.6)],
        [0.3 * (s.y * 0.5 - 0.7), 0.2 * (s.y * 0.5 - 0.7)],
        [0.25 * (s.z * 0.5 - 0.5), 0.15 * (s.z * 0.5 - 0.5)],
    ];
    let mut terms = [[(0.0, 0.0, 0.0); 2]; 3];
    for (axis, t) in terms.iter_mut().enumerate() {
        for (k, term) in t.iter_mut().enumerate() {
            let period = rng.range(16.0, 32.0) / (k as f64 + 1.0);
            *term = (amp[axis][k] * rng.range(0.8, 1.25), TAU / period, rng.range(0.0, TAU));
        }
    }
    let mut states: Vec<Vec<FishState>> = Vec::with_capacity(frames);
    for f in 0..frames {
        let t = f as f64 / fps;
        let mut p = c;
        let mut v = Vector3::zeros();
        for axis in 0..3 {
            for &(a, w, ph) in &terms[axis] {
                p[axis] += a * (w * t + ph).sin();
                v[axis] += a * w * (w * t + ph).cos();
            }
        }
        let prev = states.last().map(|s| &s[0]);
        states.push(vec![headed(p, v, prev)]);
    }
    let bodies = vec![body];
    integrate_tail(&mut states, &bodies, fps, rng);
    Motion { bodies, states }
}

/// Speed profile of a post-processing scene (paper sec. 4.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeedProfile {
    /// Accelerating, 0.3 to 1.8 body lengths/s.
    Acc,
    /// Decelerating, 1.8 to 0.3 body lengths/s.
    Dec,
    /// Uniform, 1 body length/s.
    Unif,
}

/// Trajectory of a post-processing scene, directions in the paper's axes (x right, y up, z away
/// from the camera).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Path {
    /// Along a coordinate axis.
    Axis([f64; 3]),
    /// Along a coordinate-plane diagonal.
    Plane([f64; 3]),
    /// A spatial turn-around: a half circle in a tilted plane.
    TurnAround,
}

/// One of the paper's 18 post-processing scenes.
#[derive(Debug, Clone, PartialEq)]
pub struct SuiteScene {
    /// Folder name, e.g. `acc-ca-x` or `unif-sta-occ`.
    pub name: String,
    /// Speed profile.
    pub profile: SpeedProfile,
    /// Trajectory.
    pub path: Path,
    /// Whether a second fish passes between the camera and the first one half-way through.
    pub occluded: bool,
}

/// The 18 scenes: 3 speed profiles x (axis, plane diagonal, turn-around) x (clear, occluded). Each
/// profile takes a different axis and plane, so all three axes and planes are covered.
pub fn suite_scenes() -> Vec<SuiteScene> {
    let profiles = [(SpeedProfile::Acc, "acc"), (SpeedProfile::Dec, "dec"), (SpeedProfile::Unif, "unif")];
    let axes = [("x", [1.0, 0.0, 0.0]), ("y", [0.0, 1.0, 0.0]), ("z", [0.0, 0.0, 1.0])];
    let planes = [("xy", [1.0, 1.0, 0.0]), ("xz", [1.0, 0.0, 1.0]), ("yz", [0.0, 1.0, 1.0])];
    let mut out = Vec::new();
    for occluded in [false, true] {
        let suffix = if occluded { "-occ" } else { "" };
        for (k, &(profile, pname)) in profiles.iter().enumerate() {
            let paths = [
                (format!("ca-{}", axes[k].0), Path::Axis(axes[k].1)),
                (format!("cp-{}", planes[k].0), Path::Plane(planes[k].1)),
                ("sta".to_string(), Path::TurnAround),
            ];
            for (tname, path) in paths {
                out.push(SuiteScene { name: format!("{pname}-{tname}{suffix}"), profile, path, occluded });
            }
        }
    }
    out
}

/// Paper axes (x right, y up, z away from the camera) to world (x right, y away, z up).
fn paper_to_world(d: [f64; 3]) -> Vector3<f64> {
    Vector3::new(d[0], d[2], d[1])
}

/// One post-processing scene: fish 1 on the scene's path; with occlusion, fish 2 crosses in front.
pub fn suite(
    scene: &SuiteScene,
    frames: usize,
    fps: f64,
    pond: &Pond,
    eye: &Vector3<f64>,
    cohort: Cohort,
    rng: &mut Rng,
) -> Motion {
    let mut bodies = vec![FishBody::random(rng, cohort)];
    let l = bodies[0].length;
    let duration = (frames.max(2) - 1) as f64 / fps;
    let (v0, v1) = match scene.profile {
        SpeedProfile::Acc => (0.3 * l, 1.8 * l),
        SpeedProfile::Dec => (1.8 * l, 0.3 * l),
        SpeedProfile::Unif => (l, l),
    };
    // Keep the whole path within 2.2 m so it stays in the pond whatever the duration.
    let dist = 0.5 * (v0 + v1) * duration;
    let k = (2.2 / dist.max(1e-9)).min(1.0);
    let (v0, a) = (v0 * k, (v1 - v0) * k / duration.max(1e-9));
    let s_of = |t: f64| (v0 * t + 0.5 * a * t * t, v0 + a * t);
    let total = s_of(duration).0;
    let c = Vector3::new(pond.size.x * 0.5, pond.size.y * 0.55, pond.size.z * 0.45);
    let pose = |t: f64| -> (Vector3<f64>, Vector3<f64>) {
        let (s, ds) = s_of(t);
        match scene.path {
            Path::Axis(d) | Path::Plane(d) => {
                let dir = paper_to_world(d).normalize();
                (c + dir * (s - 0.5 * total), dir * ds)
            }
            Path::TurnAround => {
                let r = total / PI;
                let e1 = Vector3::x();
                let e2 = Vector3::new(0.0, 1.0, 0.6).normalize();
                let th = s / r;
                let p = c + (e1 * -th.cos() + e2 * th.sin()) * r - e2 * (0.5 * r);
                (p, (e1 * th.sin() + e2 * th.cos()) * ds)
            }
        }
    };
    let mid = 0.5 * duration;
    let occluder = if scene.occluded {
        bodies.push(FishBody::random(rng, cohort));
        let (p_mid, _) = pose(mid);
        let q = eye + (p_mid - eye) * 0.55;
        // Cross perpendicular to the line of sight, opposite to the fish where it moves sideways.
        let sight = (p_mid - eye).normalize();
        let across = Vector3::z().cross(&sight).normalize();
        Some((q, across * (-bodies[1].length)))
    } else {
        None
    };
    let mut states: Vec<Vec<FishState>> = Vec::with_capacity(frames);
    for f in 0..frames {
        let t = f as f64 / fps;
        let (p, v) = pose(t);
        let mut row = vec![headed(p, v, states.last().map(|s| &s[0]))];
        if let Some((q, u)) = occluder {
            row.push(headed(q + u * (t - mid), u, None));
        }
        states.push(row);
    }
    integrate_tail(&mut states, &bodies, fps, rng);
    Motion { bodies, states }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eighteen_uniquely_named_scenes() {
        let s = suite_scenes();
        assert_eq!(s.len(), 18);
        let mut names: Vec<_> = s.iter().map(|x| x.name.clone()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), 18);
        assert!(names.contains(&"unif-ca-z-occ".to_string()));
    }

    #[test]
    fn swarm_speed_varies_and_stays_in_the_pond() {
        let pond = Pond::default();
        let mut rng = Rng::new(3);
        let act = Activity::swarm(&mut rng);
        let fps = 10.0;
        let m = swarm(20, 600, fps, &pond, &act, Cohort::default(), &mut rng);
        let means: Vec<f64> = m
            .states
            .iter()
            .map(|f| f.iter().zip(&m.bodies).map(|(s, b)| s.velocity.norm() / b.length).sum::<f64>() / 20.0)
            .collect();
        let lo = means.iter().cloned().fold(f64::MAX, f64::min);
        let hi = means.iter().cloned().fold(f64::MIN, f64::max);
        assert!(lo < 0.7 && hi > 1.1 && lo > 0.15 && hi < 2.5, "mean speed range {lo}..{hi} BL/s");
        for f in &m.states {
            for s in f {
                let p = s.position;
                assert!(p.x > 0.15 && p.x < 5.85 && p.y > 0.3 && p.y < 3.85 && p.z > 0.15 && p.z < 2.85, "{p:?}");
            }
        }
    }

    #[test]
    fn feeding_activity_rises_sharply_and_settles() {
        let mut rng = Rng::new(9);
        let d = 60.0;
        let a = Activity::feeding(&mut rng, d);
        let mean = |t0: f64, t1: f64| {
            (0..100).map(|k| a.body_lengths_per_s(t0 + (t1 - t0) * k as f64 / 100.0)).sum::<f64>() / 100.0
        };
        let (before, during, after) = (mean(0.0, 0.3 * d), mean(0.3 * d + 1.0, 0.5 * d), mean(0.9 * d, d));
        assert!(during > 1.8 * before, "{before} -> {during}");
        assert!(after < 0.75 * during, "{during} -> {after}");
        assert!(a.body_lengths_per_s(0.3 * d + 1.0) / a.body_lengths_per_s(0.3 * d - 0.01) > 1.6, "not sharp");
    }
}
