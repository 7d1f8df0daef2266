//! Procedural fish: a spindle body (ellipsoid), a peduncle and forked caudal fin that beat around a
//! pivot, and a dorsal fin. Ground truth is the body centre, the midpoint between snout and tail
//! tip of the unbent fish, which moves on the smooth centre path; tail beat and head recoil never
//! reach the position or velocity labels (research note sec. 3).

use crate::rng::Rng;
use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

/// Peak tail angle, radians: the tail tip (0.28 L behind the pivot) then swings 0.1 L either side,
/// a peak-to-peak amplitude of 0.2 body lengths (research note sec. 3).
pub const TAIL_ANGLE: f64 = 0.365;
/// Head recoil (yaw of the body opposite to the tail), radians.
pub const RECOIL_ANGLE: f64 = 0.05;
/// Strouhal-based tail-beat frequency factor: f = 1.5 U / L (St = 0.3 with 0.2 L amplitude).
pub const TAIL_BEAT_PER_BL: f64 = 1.5;
/// Slowest tail beat, Hz (fish never hold the tail still while swimming).
pub const MIN_TAIL_BEAT_HZ: f64 = 1.2;

/// Appearance and size of one fish, fixed for the sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FishBody {
    /// Snout-to-tail-tip length, metres.
    pub length: f64,
    /// Colour of the back (R, G, B in `[0, 1]`).
    pub back: [f64; 3],
    /// Colour of the flanks.
    pub flank: [f64; 3],
    /// Colour of the belly.
    pub belly: [f64; 3],
    /// Seed of the spot pattern.
    pub pattern: u64,
}

/// The lengths of a cohort of fish (`fme synth --fish-length --fish-length-cv`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cohort {
    /// Mean snout-to-tail-tip length, m.
    pub mean_length_m: f64,
    /// Standard deviation of the lengths over the mean.
    pub length_cv: f64,
}

impl Default for Cohort {
    /// Salmon of 0.35 m, sd 12 %.
    fn default() -> Self {
        Self { mean_length_m: super::motion::MEAN_LENGTH_M, length_cv: 0.12 }
    }
}

impl FishBody {
    /// A salmon-like fish with length drawn from `cohort` (normal, clamped to 0.6-1.5 times the
    /// mean), colours varied slightly.
    pub fn random(rng: &mut Rng, cohort: Cohort) -> Self {
        let mean_length = cohort.mean_length_m;
        let length =
            (mean_length * (1.0 + cohort.length_cv * rng.normal())).clamp(mean_length * 0.6, mean_length * 1.5);
        let k = rng.range(0.85, 1.15);
        let tint = rng.range(-0.04, 0.04);
        Self {
            length,
            back: [0.13 * k, (0.19 + tint) * k, 0.22 * k],
            flank: [0.62 * k, 0.66 * k, (0.68 - tint) * k],
            belly: [0.86, 0.86, 0.84],
            pattern: rng.next_u64(),
        }
    }
}

/// Kinematic state of a fish at one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FishState {
    /// Body centre, world frame, metres.
    pub position: Vector3<f64>,
    /// Velocity of the body centre, world frame, m/s (analytic).
    pub velocity: Vector3<f64>,
    /// Unit heading (snout direction), world frame.
    pub heading: Vector3<f64>,
    /// Tail-beat phase, radians.
    pub tail_phase: f64,
}

/// Tail-beat frequency (Hz) at a speed, from the Strouhal number (research note sec. 3).
pub fn tail_beat_hz(speed: f64, length: f64) -> f64 {
    (TAIL_BEAT_PER_BL * speed / length).max(MIN_TAIL_BEAT_HZ)
}

/// An ellipsoid in the world frame: points `center + axes * diag(radii) * s` with `|s| = 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Centre, world frame.
    pub center: Vector3<f64>,
    /// Columns: the ellipsoid's local x (forward), y (left), z (up) axes in the world frame.
    pub axes: Matrix3<f64>,
    /// Semi-axes along local x, y, z, metres.
    pub radii: Vector3<f64>,
}

/// A flat fin triangle in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    /// Corners, world frame.
    pub v: [Vector3<f64>; 3],
}

/// Index of the body ellipsoid in [`FishShape::parts`].
pub const PART_BODY: usize = 0;
/// Index of the peduncle ellipsoid in [`FishShape::parts`].
pub const PART_PEDUNCLE: usize = 1;

/// The posed surfaces of a fish at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FishShape {
    /// Body and peduncle.
    pub parts: [Ellipsoid; 2],
    /// Upper and lower caudal lobes, dorsal fin.
    pub fins: [Triangle; 3],
}

/// Body frame (columns forward, left, up) for a heading; up stays as close to world up as the
/// heading allows (fish do not roll).
pub fn body_frame(heading: &Vector3<f64>) -> Matrix3<f64> {
    let f = heading.try_normalize(1e-12).unwrap_or_else(Vector3::x);
    let left = Vector3::z().cross(&f).try_normalize(1e-6).unwrap_or_else(|| f.cross(&Vector3::x()).normalize());
    let up = f.cross(&left);
    Matrix3::from_columns(&[f, left, up])
}

impl FishShape {
    /// Poses a fish: body bent by the tail angle `TAIL_ANGLE sin(phase)` about a pivot 0.22 L behind
    /// the centre, head yawed the other way by the recoil.
    pub fn new(body: &FishBody, state: &FishState) -> Self {
        let l = body.length;
        let frame = body_frame(&state.heading);
        let up = Unit::new_unchecked(frame.column(2).into_owned());
        let beat = state.tail_phase.sin();
        let head = Rotation3::from_axis_angle(&up, -RECOIL_ANGLE * beat).into_inner() * frame;
        let tail = Rotation3::from_axis_angle(&up, TAIL_ANGLE * beat).into_inner() * frame;
        let c = state.position;
        let at = |m: &Matrix3<f64>, origin: Vector3<f64>, x: f64, z: f64| origin + m * Vector3::new(x * l, 0.0, z * l);
        let pivot = at(&frame, c, -0.22, 0.0);
        let parts = [
            Ellipsoid { center: at(&head, c, 0.12, 0.0), axes: head, radii: Vector3::new(0.38, 0.06, 0.1) * l },
            Ellipsoid { center: at(&tail, pivot, -0.1, 0.0), axes: tail, radii: Vector3::new(0.14, 0.03, 0.045) * l },
        ];
        let fins = [
            Triangle {
                v: [at(&tail, pivot, -0.18, 0.03), at(&tail, pivot, -0.28, 0.11), at(&tail, pivot, -0.23, 0.0)],
            },
            Triangle {
                v: [at(&tail, pivot, -0.18, -0.03), at(&tail, pivot, -0.28, -0.11), at(&tail, pivot, -0.23, 0.0)],
            },
            Triangle { v: [at(&head, c, 0.08, 0.085), at(&head, c, -0.08, 0.07), at(&head, c, -0.06, 0.15)] },
        ];
        Self { parts, fins }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tail_tip_swings_about_a_tenth_of_the_length_and_centre_stays_inside() {
        let body = FishBody { length: 0.4, back: [0.0; 3], flank: [0.0; 3], belly: [0.0; 3], pattern: 0 };
        let mut st = FishState {
            position: Vector3::new(1.0, 2.0, 1.0),
            velocity: Vector3::new(0.3, 0.0, 0.0),
            heading: Vector3::x(),
            tail_phase: std::f64::consts::FRAC_PI_2,
        };
        let s = FishShape::new(&body, &st);
        let tip = s.fins[0].v[1];
        assert!(((tip.y - st.position.y).abs() / 0.4 - 0.1).abs() < 0.01, "{tip:?}");
        // Snout and tail tip are half a length from the centre when the tail is straight.
        st.tail_phase = 0.0;
        let s = FishShape::new(&body, &st);
        let b = s.parts[PART_BODY];
        assert!(((b.center.x + b.radii.x) - 1.2).abs() < 1e-12);
        assert!((s.fins[0].v[1].x - 0.8).abs() < 1e-12);
        // The centre is inside the body ellipsoid.
        let d = b.axes.transpose() * (st.position - b.center);
        assert!(d.component_div(&b.radii).norm() < 1.0);
        assert!((tail_beat_hz(0.4, 0.4) - 1.5).abs() < 1e-12 && tail_beat_hz(0.0, 0.4) == MIN_TAIL_BEAT_HZ);
    }
}
