//! Runs a motion preset through the renderer and writes MOTChallenge sequences.

use super::fish::Cohort;
use super::motion::{self, Activity, Motion};
use super::render::{FrameBuffers, Renderer};
use super::scene::{self, Layout, Pond};
use super::water::WaterType;
use super::{Error, MAX_FISH, MAX_FRAMES};
use crate::rng::Rng;
use fme_core::units::Metres;
use fme_edge::sequence::{
    CameraMeta, GeneratorMeta, GtBox, Meta, SeqInfo, SequenceWriter, StagedDir, WorldRow, encode_jpeg,
};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// JPEG quality of the frames.
pub const JPEG_QUALITY: u8 = 90;

/// Motion presets of `fme synth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Preset {
    /// One fish on a random smooth 3D path.
    Single,
    /// A schooling, milling swarm whose mean speed rises and falls.
    Swarm,
    /// The paper's 18 single-fish post-processing scenes (sec. 4.4), one subfolder each.
    #[value(name = "postproc-suite")]
    PostprocSuite,
    /// A swarm whose activity rises sharply for a while and settles (feeding).
    Feeding,
}

impl Preset {
    /// Name as on the command line and in `meta.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Single => "single",
            Self::Swarm => "swarm",
            Self::PostprocSuite => "postproc-suite",
            Self::Feeding => "feeding",
        }
    }
}

/// Everything that determines a generated sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthConfig {
    /// Motion preset.
    pub preset: Preset,
    /// Number of fish (swarm and feeding).
    pub fish: usize,
    /// Frames per sequence.
    pub frames: u32,
    /// Seed of all randomness.
    pub seed: u64,
    /// Frame rate.
    pub fps: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Water type.
    pub water: WaterType,
    /// Reference-cube layout.
    pub layout: Layout,
    /// Radial lens distortion `k1` (OpenCV; negative = barrel), 0 for a pinhole.
    pub k1: f64,
    /// The fish's length distribution.
    pub cohort: Cohort,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            preset: Preset::Swarm,
            fish: 20,
            frames: 150,
            seed: 1,
            fps: 30.0,
            width: 640,
            height: 384,
            water: WaterType::C3,
            layout: Layout::F,
            k1: 0.0,
            cohort: Cohort::default(),
        }
    }
}

impl SynthConfig {
    /// Checks the settings; the message names the offending one.
    pub fn validate(&self) -> Result<(), Error> {
        if self.frames == 0 {
            return Err(Error::Config("--frames must be at least 1".into()));
        }
        if self.frames > MAX_FRAMES {
            return Err(Error::Config(format!("--frames {} is more than the maximum of {MAX_FRAMES}", self.frames)));
        }
        if self.fish == 0 || self.fish > MAX_FISH {
            return Err(Error::Config(format!("--fish {} is outside 1..={MAX_FISH}", self.fish)));
        }
        if !self.fps.is_finite() || self.fps <= 0.0 || self.fps > 1000.0 {
            return Err(Error::Config(format!("--fps {} must be within (0, 1000]", self.fps)));
        }
        for (name, v) in [("--width", self.width), ("--height", self.height)] {
            if !(16..=8192).contains(&v) {
                return Err(Error::Config(format!("{name} {v} must be within 16..=8192 pixels")));
            }
        }
        let c = self.cohort;
        if !(c.mean_length_m.is_finite() && (0.05..=3.0).contains(&c.mean_length_m)) {
            return Err(Error::Config(format!("--fish-length {} must be within [0.05, 3] m", c.mean_length_m)));
        }
        if !(c.length_cv.is_finite() && (0.0..=0.3).contains(&c.length_cv)) {
            return Err(Error::Config(format!("--fish-length-cv {} must be within [0, 0.3]", c.length_cv)));
        }
        if !self.k1.is_finite() || self.k1.abs() > 0.3 {
            return Err(Error::Config(format!("--k1 {} must be within [-0.3, 0.3]", self.k1)));
        }
        Ok(())
    }
}

/// What [`generate`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The output folder.
    pub out: PathBuf,
    /// The sequence folders (one, or 18 for the post-processing suite).
    pub sequences: Vec<PathBuf>,
    /// Frames rendered in all.
    pub frames: u64,
}

/// Generates the configured preset into `out`, staged so that an interrupted or failed run leaves
/// nothing that looks complete. `progress` is called with the number of frames just finished.
pub fn generate(cfg: &SynthConfig, out: &Path, force: bool, progress: &(dyn Fn(u64) + Sync)) -> Result<Summary, Error> {
    cfg.validate()?;
    let pond = Pond::default();
    let mut camera = scene::default_camera(&pond, cfg.width, cfg.height)?;
    camera.intrinsics.distortion[0] = cfg.k1;
    if cfg.k1 < 0.0 {
        // Barrel distortion folds over at r^2 = -1/(3 k1), where r (1 + k1 r^2) peaks at 2/3 of that
        // radius: the image corners must stay well inside the peak or the lens cannot be inverted.
        let k = &camera.intrinsics;
        let corner = ((k.cx / k.fx).powi(2) + (k.cy / k.fy).powi(2)).sqrt();
        let peak = 2.0 / 3.0 * (-1.0 / (3.0 * cfg.k1)).sqrt();
        if peak < 1.1 * corner {
            return Err(Error::Config(format!(
                "--k1 {} folds the image over before its corners (this camera allows k1 >= {:.3})",
                cfg.k1,
                -4.0 / (27.0 * (1.1 * corner).powi(2))
            )));
        }
    }
    let cubes = scene::reference_cubes(cfg.layout, &pond, &camera);
    let renderer = Renderer::new(camera, cfg.width, cfg.height, pond, cfg.water, &cubes, cfg.seed);
    let stage = StagedDir::create(out, force)?;
    let name = out.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "synth".into());
    let frames = cfg.frames as usize;
    let mut rng = Rng::new(cfg.seed);
    let base = Base { cfg, pond: &pond, renderer: &renderer, cubes: &cubes };
    let mut sequences = Vec::new();
    match cfg.preset {
        Preset::Swarm | Preset::Feeding => {
            let duration = frames as f64 / cfg.fps;
            let activity = if cfg.preset == Preset::Feeding {
                Activity::feeding(&mut rng, duration)
            } else {
                Activity::swarm(&mut rng)
            };
            let m = motion::swarm(cfg.fish, frames, cfg.fps, &pond, &activity, cfg.cohort, &mut rng);
            base.write(stage.path(), &name, cfg.preset.name(), &m, progress)?;
            sequences.push(out.to_path_buf());
        }
        Preset::Single => {
            let m = motion::single(frames, cfg.fps, &pond, cfg.cohort, &mut rng);
            base.write(stage.path(), &name, cfg.preset.name(), &m, progress)?;
            sequences.push(out.to_path_buf());
        }
        Preset::PostprocSuite => {
            let eye = camera.pose.camera_center().0;
            let scenes = motion::suite_scenes();
            let mut list = String::new();
            for (k, s) in scenes.iter().enumerate() {
                let mut srng = Rng::derive(cfg.seed, k as u64 + 1);
                let m = motion::suite(s, frames, cfg.fps, &pond, &eye, cfg.cohort, &mut srng);
                let dir = stage.path().join(&s.name);
                base.write(&dir, &s.name, &format!("postproc-suite/{}", s.name), &m, progress)?;
                list.push_str(&s.name);
                list.push('\n');
                sequences.push(out.join(&s.name));
            }
            let p = stage.path().join("scenes.txt");
            std::fs::write(&p, list).map_err(|e| fme_edge::sequence::Error::Io { path: p, error: e })?;
        }
    }
    let n = sequences.len() as u64 * u64::from(cfg.frames);
    stage.commit()?;
    Ok(Summary { out: out.to_path_buf(), sequences, frames: n })
}

struct Base<'a> {
    cfg: &'a SynthConfig,
    pond: &'a Pond,
    renderer: &'a Renderer,
    cubes: &'a [fme_edge::sequence::ReferenceObject],
}

impl Base<'_> {
    /// Renders and writes one sequence into `dir`.
    fn write(
        &self,
        dir: &Path,
        name: &str,
        preset: &str,
        m: &Motion,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<(), Error> {
        let cfg = self.cfg;
        let writer = SequenceWriter::new(dir)?;
        let (w, h) = (cfg.width, cfg.height);
        let mut gt = Vec::new();
        let mut world = Vec::new();
        // Frames are rendered in parallel batches; each worker writes its own files and returns its
        // rows, which are appended in frame order, so the output does not depend on scheduling.
        let batch = (rayon::current_num_threads() * 8).max(8);
        // One set of frame buffers per worker thread, reused for every frame (every buffer is fully
        // rewritten per frame): allocating ~12 MB per rayon job cost more than the rendering.
        let pool: Vec<std::sync::Mutex<FrameBuffers>> =
            (0..rayon::current_num_threads().max(1)).map(|_| std::sync::Mutex::new(FrameBuffers::new(w, h))).collect();
        let n = m.states.len();
        let mut start = 0;
        while start < n {
            let end = (start + batch).min(n);
            let results: Vec<Result<Vec<super::render::FishPixels>, Error>> = (start..end)
                .into_par_iter()
                .map(|f| {
                    let slot = rayon::current_thread_index().unwrap_or(0) % pool.len();
                    let mut guard = pool[slot].lock().unwrap_or_else(|e| e.into_inner());
                    let buf = &mut *guard;
                    let frame = f as u32 + 1;
                    let t = f as f64 / cfg.fps;
                    let px = self.renderer.render(frame, t, &m.bodies, &m.states[f], buf);
                    let rgb = image::RgbImage::from_raw(w, h, buf.rgb.clone())
                        .ok_or_else(|| Error::Config("internal: frame buffer size".into()))?;
                    let jpeg = encode_jpeg(&rgb, JPEG_QUALITY)
                        .map_err(|error| fme_edge::sequence::Error::Image { path: writer.frame_path(frame), error })?;
                    writer.write_frame_bytes(frame, &jpeg)?;
                    writer.write_depth(frame, &buf.depth_map(w, h))?;
                    progress(1);
                    Ok(px)
                })
                .collect();
            for (k, r) in results.into_iter().enumerate() {
                let f = start + k;
                let frame = f as u32 + 1;
                for (i, (p, s)) in r?.iter().zip(&m.states[f]).enumerate() {
                    let id = i as u32 + 1;
                    let visibility = p.visibility();
                    if p.alone > 0 {
                        gt.push(GtBox { frame, id, bbox: p.bbox, visibility });
                    }
                    world.push(WorldRow {
                        frame,
                        id,
                        position: fme_core::geometry::WorldPoint(s.position),
                        velocity: s.velocity,
                        length: Metres(m.bodies[i].length),
                        visibility,
                    });
                }
            }
            start = end;
        }
        let info = SeqInfo {
            name: name.to_string(),
            im_dir: "img1".into(),
            frame_rate: cfg.fps,
            seq_length: cfg.frames,
            im_width: w,
            im_height: h,
            im_ext: ".jpg".into(),
        };
        let meta = Meta {
            fps: cfg.fps,
            width: w,
            height: h,
            frames: cfg.frames,
            seed: cfg.seed,
            preset: preset.to_string(),
            generator: GeneratorMeta { name: "fme synth".into(), version: env!("CARGO_PKG_VERSION").into() },
            camera: CameraMeta::from_camera(self.renderer.camera()),
            water: cfg.water.meta(),
            reference_objects: self.cubes.to_vec(),
            layout: Some(cfg.layout.name().into()),
            pond_size_m: Some(self.pond.size.into()),
            fish: Some(m.bodies.len() as u32),
        };
        writer.finish(&info, &meta, &gt, &world)?;
        Ok(())
    }
}
