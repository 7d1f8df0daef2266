//! Synthetic underwater fish sequences with exact ground truth (`fme synth`).
//!
//! Replaces the paper's Unity scenes (sec. 4.1 and 4.4) with a deterministic software renderer:
//!
//! | module | what |
//! |---|---|
//! | [`scene`] | pond box, camera, reference cubes of layouts A-F (paper Fig. 7, Table 5) |
//! | [`water`] | Jerlov water types: attenuation and veiling light |
//! | [`fish`] | procedural fish bodies with a beating tail |
//! | [`motion`] | presets: swarm (schooling + milling), feeding, single, the 18 post-processing scenes |
//! | [`render`] | ray caster, image formation, caustics, snow, noise; exact amodal boxes and depth |
//! | [`mod@generate`] | runs a preset and writes the sequence(s) with [`fme_edge::sequence`] |
//!
//! Same arguments, same bytes: all randomness comes from [`crate::rng::Rng`] seeded by `--seed`, and frames
//! rendered in parallel are written to their own files.

pub mod fish;
pub mod generate;
pub mod motion;
pub mod render;
pub mod scene;
pub mod texture;
pub mod water;

pub use generate::{Preset, Summary, SynthConfig, generate};
pub use scene::Layout;
pub use water::WaterType;

/// Most fish a swarm may have.
pub const MAX_FISH: usize = 200;
/// Most frames one sequence may have (about 55 minutes at 30 fps).
pub const MAX_FRAMES: u32 = 100_000;

/// Errors of the generator.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Settings that cannot make a sequence (the message names the setting).
    #[error("{0}")]
    Config(String),
    /// Writing the sequence failed.
    #[error(transparent)]
    Sequence(#[from] fme_edge::sequence::Error),
    /// The camera could not be built.
    #[error("camera: {0}")]
    Geometry(#[from] fme_core::geometry::GeometryError),
}
