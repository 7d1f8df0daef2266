//! The static scene: pond box, camera, and the reference cubes of layouts A to F.

use fme_core::geometry::{Camera, GeometryError, Intrinsics, Pose, WorldPoint};
use fme_edge::sequence::ReferenceObject;
use nalgebra::Vector3;

/// Edge length of the reference cubes (paper sec. 4.3.2).
pub const CUBE_SIZE_M: f64 = 0.1;

/// The pond (or net-cage section): an axis-aligned box `[0, size]` in the world frame, z up, the
/// water surface at `z = size.z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pond {
    /// Extent along world x, y, z in metres.
    pub size: Vector3<f64>,
}

impl Default for Pond {
    fn default() -> Self {
        Self { size: Vector3::new(6.0, 4.0, 3.0) }
    }
}

impl Pond {
    /// Centre of the circular milling motion (horizontal), a little away from the camera wall.
    pub fn mill_center(&self) -> Vector3<f64> {
        Vector3::new(self.size.x * 0.5, self.size.y * 0.55, self.size.z * 0.45)
    }
}

/// Horizontal field of view of the default camera, degrees (a wide underwater action-camera lens).
pub const DEFAULT_HFOV_DEG: f64 = 100.0;

/// The fixed camera: near the middle of the `y = 0` wall, half-way down, looking along +y and a
/// little down so that floor, far wall and both side walls are in view.
pub fn default_camera(pond: &Pond, width: u32, height: u32) -> Result<Camera, GeometryError> {
    let intrinsics = Intrinsics::from_hfov(width, height, DEFAULT_HFOV_DEG)?;
    let eye = WorldPoint::new(pond.size.x * 0.5, 0.05, pond.size.z * 0.5);
    let target = WorldPoint::new(pond.size.x * 0.5, pond.size.y, pond.size.z * 0.5 - 1.0);
    let pose =
        Pose::look_at(eye, target, Vector3::z()).ok_or(GeometryError::BadIntrinsics("degenerate camera pose"))?;
    Ok(Camera { intrinsics, pose })
}

/// Reference-object layouts of the paper (Fig. 7, Table 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Layout {
    /// 3 cubes, all near the far wall (little depth spread).
    #[value(name = "A")]
    A,
    /// 5 cubes.
    #[value(name = "B")]
    B,
    /// 6 cubes.
    #[value(name = "C")]
    C,
    /// 8 cubes.
    #[value(name = "D")]
    D,
    /// 10 cubes spread over floor and walls.
    #[value(name = "E")]
    E,
    /// E with each cube nudged, for a more complete depth range (the paper's choice; default).
    #[value(name = "F")]
    F,
    /// No reference objects: the fish are the only ruler (`depth.scale = "fish"`, docs/pipeline.md).
    #[value(name = "none")]
    None,
}

impl Layout {
    /// Name as written in `meta.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::A => "A",
            Self::B => "B",
            Self::C => "C",
            Self::D => "D",
            Self::E => "E",
            Self::F => "F",
            Self::None => "none",
        }
    }
}

/// Where a cube sits: on the floor, or against a wall (its centre half an edge off the surface).
#[derive(Debug, Clone, Copy)]
enum Mount {
    Floor(f64, f64),
    FarWall(f64, f64),
    LeftWall(f64, f64),
    RightWall(f64, f64),
}

/// The ten placements of layout E in a 6 x 4 x 3 m pond, scaled to the actual pond, in the order
/// they are added from A to E.
const PLACEMENTS: [Mount; 10] = [
    Mount::FarWall(1.5, 0.8),
    Mount::FarWall(4.5, 1.6),
    Mount::Floor(4.5, 3.6),
    Mount::Floor(3.0, 1.8),
    Mount::Floor(3.0, 3.0),
    Mount::LeftWall(3.2, 0.6),
    Mount::Floor(1.8, 2.4),
    Mount::RightWall(3.0, 1.0),
    Mount::Floor(4.2, 2.4),
    Mount::Floor(2.0, 3.6),
];

/// Layout F's nudges (metres along the two in-surface axes of each mount).
const NUDGES: [(f64, f64); 10] = [
    (-0.3, 0.4),
    (0.2, -0.5),
    (0.3, -0.35),
    (-0.4, -0.25),
    (0.35, 0.3),
    (-0.4, 0.5),
    (-0.3, -0.4),
    (0.45, 0.35),
    (0.4, 0.45),
    (-0.35, 0.25),
];

/// The reference cubes of a layout, with the centre of the face turned towards `camera`.
pub fn reference_cubes(layout: Layout, pond: &Pond, camera: &Camera) -> Vec<ReferenceObject> {
    let count = match layout {
        Layout::A => 3,
        Layout::B => 5,
        Layout::C => 6,
        Layout::D => 8,
        Layout::E | Layout::F => 10,
        Layout::None => 0,
    };
    let s = pond.size;
    let (kx, ky, kz) = (s.x / 6.0, s.y / 4.0, s.z / 3.0);
    let h = CUBE_SIZE_M * 0.5;
    let eye = camera.pose.camera_center().0;
    PLACEMENTS[..count]
        .iter()
        .zip(NUDGES)
        .enumerate()
        .map(|(i, (m, nudge))| {
            let (da, db) = if layout == Layout::F { nudge } else { (0.0, 0.0) };
            let c = match *m {
                Mount::Floor(x, y) => Vector3::new(x * kx + da, y * ky + db, h),
                Mount::FarWall(x, z) => Vector3::new(x * kx + da, s.y - h, z * kz + db),
                Mount::LeftWall(y, z) => Vector3::new(h, y * ky + da, z * kz + db),
                Mount::RightWall(y, z) => Vector3::new(s.x - h, y * ky + da, z * kz + db),
            };
            let c = Vector3::new(c.x.clamp(h, s.x - h), c.y.clamp(h, s.y - h), c.z.clamp(h, s.z - h));
            ReferenceObject {
                id: i as u32 + 1,
                size_m: CUBE_SIZE_M,
                center_w: c.into(),
                front_face_center_w: front_face_center(&c, CUBE_SIZE_M, &eye).into(),
            }
        })
        .collect()
}

/// Centre of the face of an axis-aligned cube whose outward normal points most towards `eye`.
pub fn front_face_center(center: &Vector3<f64>, size: f64, eye: &Vector3<f64>) -> Vector3<f64> {
    let to_eye = eye - center;
    let axis = (0..3).max_by(|&a, &b| to_eye[a].abs().total_cmp(&to_eye[b].abs())).unwrap_or(1);
    let mut f = *center;
    f[axis] += 0.5 * size * to_eye[axis].signum();
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_grow_from_a_to_e_and_f_moves_every_cube() {
        let pond = Pond::default();
        let cam = default_camera(&pond, 640, 384).unwrap();
        let n: Vec<usize> = [Layout::A, Layout::B, Layout::C, Layout::D, Layout::E]
            .iter()
            .map(|&l| reference_cubes(l, &pond, &cam).len())
            .collect();
        assert_eq!(n, vec![3, 5, 6, 8, 10]);
        let e = reference_cubes(Layout::E, &pond, &cam);
        let f = reference_cubes(Layout::F, &pond, &cam);
        for (a, b) in e.iter().zip(&f) {
            assert!(a.center().distance(&b.center()).0 > 0.2);
        }
        for c in &f {
            // Every cube is in view, inside the pond, and its front face is towards the camera.
            let px = cam.world_to_pixel(&c.center()).unwrap();
            assert!(px.u > 0.0 && px.u < 640.0 && px.v > 0.0 && px.v < 384.0, "cube {} at {px:?}", c.id);
            let eye = cam.pose.camera_center();
            assert!(c.front_face_center().distance(&eye).0 < c.center().distance(&eye).0);
            assert!((c.front_face_center().distance(&c.center()).0 - 0.05).abs() < 1e-12);
        }
    }
}
