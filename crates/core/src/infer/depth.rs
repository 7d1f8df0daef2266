//! The relative-depth network (MiDaS v2.1 small / Depth Anything V2 convention): input
//! `[1, 3, H, W]` resized without keeping the aspect ratio and normalised with mean/std; output
//! `[1, H', W']` or `[1, 1, H', W']` relative inverse depth (larger = nearer, paper sec. 4.3). The
//! map is kept at network resolution and sampled only where needed (box centres, reference points)
//! with a small median window, rather than resized to the frame.

use std::path::{Path, PathBuf};

use super::InferError;
use super::backend::{Backend, Model};
use super::config::DepthConfig;
use super::detector::resolve_size;
use super::frame::{Normalize, Resampler, RgbFrame};
use super::runtime::{SessionOptions, fmt_shape};
use crate::geometry::Pixel;
use crate::units::Seconds;

use super::config::MAX_SAMPLE_RADIUS;
const MAX_WINDOW: usize = ((2 * MAX_SAMPLE_RADIUS + 1) * (2 * MAX_SAMPLE_RADIUS + 1)) as usize;

/// A relative inverse-depth map at network resolution, with the frame size it was computed from
/// and the frame's timestamp. Larger values are nearer; the scale and shift are unknown until the
/// metric fit (paper eq. 1-2).
#[derive(Debug, Clone, PartialEq)]
pub struct RelDepthMap {
    /// Timestamp of the frame.
    pub t: Seconds,
    width: u32,
    height: u32,
    src: (u32, u32),
    radius: u32,
    data: Vec<f32>,
}

impl RelDepthMap {
    /// A map of `width x height` values (row-major) computed from a `src` frame (`(width,
    /// height)`), sampled with a `(2 radius + 1)^2` median window. `None` when the data length does
    /// not match or a size is zero.
    pub fn new(t: Seconds, width: u32, height: u32, src: (u32, u32), radius: u32, data: Vec<f32>) -> Option<Self> {
        (width > 0
            && height > 0
            && src.0 > 0
            && src.1 > 0
            && data.len() == width as usize * height as usize
            && radius <= MAX_SAMPLE_RADIUS)
            .then_some(Self { t, width, height, src, radius, data })
    }

    /// Map width and height, in map pixels.
    pub fn dims(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    /// Size of the frame the map belongs to.
    pub fn frame_size(&self) -> (u32, u32) {
        self.src
    }
    /// The raw values, row-major.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The relative inverse depth at frame pixel `p`: the median of the finite map values in the
    /// configured window around the map pixel that `p` falls in. `None` outside the frame or when
    /// no finite value is in the window.
    pub fn sample(&self, p: Pixel) -> Option<f32> {
        self.sample_with_radius(p, self.radius)
    }

    /// As [`Self::sample`] with an explicit window radius (clamped to [`MAX_SAMPLE_RADIUS`]).
    pub fn sample_with_radius(&self, p: Pixel, radius: u32) -> Option<f32> {
        let (sw, sh) = (self.src.0 as f64, self.src.1 as f64);
        if !(p.u >= 0.0 && p.v >= 0.0 && p.u < sw && p.v < sh) {
            return None;
        }
        // Frame pixel -> map pixel containing it (pixel centres at +0.5 in both frames).
        let mx = ((p.u * self.width as f64 / sw) as i64).min(self.width as i64 - 1);
        let my = ((p.v * self.height as f64 / sh) as i64).min(self.height as i64 - 1);
        let r = radius.min(MAX_SAMPLE_RADIUS) as i64;
        let mut win = [0f32; MAX_WINDOW];
        let mut n = 0;
        for y in (my - r).max(0)..=(my + r).min(self.height as i64 - 1) {
            let row = &self.data[y as usize * self.width as usize..][..self.width as usize];
            for x in (mx - r).max(0)..=(mx + r).min(self.width as i64 - 1) {
                let v = row[x as usize];
                if v.is_finite() {
                    win[n] = v;
                    n += 1;
                }
            }
        }
        if n == 0 {
            return None;
        }
        let win = &mut win[..n];
        let (_, m, _) = win.select_nth_unstable_by(n / 2, f32::total_cmp);
        Some(*m)
    }
}

/// A loaded depth network with its reusable buffers.
pub struct DepthNet {
    model: Model,
    path: PathBuf,
    net: (u32, u32),
    norm: Normalize,
    radius: u32,
    flip: bool,
    input: Vec<f32>,
    src: Option<(u32, u32)>,
    resampler: Resampler,
    map: RelDepthMap,
}

impl std::fmt::Debug for DepthNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DepthNet")
            .field("path", &self.path)
            .field("backend", &self.model.backend())
            .field("net", &self.net)
            .finish()
    }
}

impl DepthNet {
    /// Loads `cfg.model` with the build's default backend and checks that it follows the
    /// relative-depth convention.
    pub fn open(cfg: &DepthConfig, opts: SessionOptions) -> Result<Self, InferError> {
        Self::open_with(cfg, opts, Backend::DEFAULT)
    }

    /// As [`Self::open`], with the given backend.
    pub fn open_with(cfg: &DepthConfig, opts: SessionOptions, backend: Backend) -> Result<Self, InferError> {
        cfg.validate()?;
        let path = cfg.model.clone();
        let mut model = Model::open(&path, opts, backend)?;
        let net = check_layout(&path, &mut model, cfg)?;
        let plane = net.0 as usize * net.1 as usize;
        Ok(Self {
            model,
            path,
            net,
            norm: cfg.normalize(),
            radius: cfg.sample_radius,
            flip: cfg.flip,
            input: vec![0.0; 3 * plane],
            src: None,
            resampler: Resampler::default(),
            map: RelDepthMap { t: Seconds(0.0), width: 1, height: 1, src: (1, 1), radius: 0, data: Vec::new() },
        })
    }

    /// Network input `(width, height)`.
    pub fn input_size(&self) -> (u32, u32) {
        self.net
    }
    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// The model file's numeric form.
    pub fn form(&self) -> super::ModelForm {
        self.model.form()
    }
    /// The backend running the network.
    pub fn backend(&self) -> Backend {
        self.model.backend()
    }

    /// The map of the last successful [`Self::estimate`], until the next call; `None` before the first.
    pub fn last_map(&self) -> Option<&RelDepthMap> {
        (!self.map.data.is_empty()).then_some(&self.map)
    }

    /// The network input buffer as last filled by `preprocess` (planar `[3, H, W]`; mirrored
    /// after an `estimate` with `flip`).
    pub fn input_tensor(&self) -> &[f32] {
        &self.input
    }

    /// Resizes and normalises `frame` into the input buffer (exposed for benchmarks).
    pub fn preprocess(&mut self, frame: &RgbFrame<'_>) {
        let src = (frame.width(), frame.height());
        if self.src != Some(src) {
            self.resampler.build(src, self.net);
            self.src = Some(src);
        }
        let (w, h) = (self.net.0 as usize, self.net.1 as usize);
        self.resampler.run(frame, 0, 0, w, h, &self.norm, &mut self.input);
    }

    /// Runs the network on one frame taken at `t`; the returned map is reused by the next call.
    /// With `flip`, the map is the mean of the frame's and its mirror image's (mirrored back).
    pub fn estimate(&mut self, frame: &RgbFrame<'_>, t: Seconds) -> Result<&RelDepthMap, InferError> {
        self.preprocess(frame);
        self.run(false)?;
        let m = &mut self.map;
        m.src = (frame.width(), frame.height());
        m.radius = self.radius;
        m.t = t;
        if self.flip {
            // Mirror every row of every channel in place; the preprocessed frame is not needed again.
            for row in self.input.chunks_exact_mut(self.net.0 as usize) {
                row.reverse();
            }
            self.run(true)?;
        }
        Ok(&self.map)
    }

    /// One network run on the input buffer: stores the output as the map's data and size
    /// (`mirrored_mean == false`) or averages the mirrored output into the stored map.
    fn run(&mut self, mirrored_mean: bool) -> Result<(), InferError> {
        let (w, h) = (self.net.0 as usize, self.net.1 as usize);
        let (path, m) = (&self.path, &mut self.map);
        self.model.run(path, [1, 3, h, w], &self.input, |dims, data| {
            let (mh, mw) = match dims {
                [1, h, w] | [1, 1, h, w] if *h > 0 && *w > 0 => (*h as u32, *w as u32),
                _ => {
                    return Err(InferError::Shape {
                        path: path.clone(),
                        what: "output at run time".into(),
                        expected: "[1, H, W] or [1, 1, H, W]".into(),
                        actual: fmt_shape(dims),
                    });
                }
            };
            if !mirrored_mean {
                m.data.clear();
                m.data.extend_from_slice(data);
                m.width = mw;
                m.height = mh;
            } else {
                // Same input size, so the same map size as the first run: a model that says
                // otherwise is broken, and the unflipped map stays.
                if (mw, mh) != (m.width, m.height) {
                    return Err(InferError::Shape {
                        path: path.clone(),
                        what: "output of the mirrored run".into(),
                        expected: format!("a {}x{} map, as the first run", m.width, m.height),
                        actual: fmt_shape(dims),
                    });
                }
                for (dst, src) in m.data.chunks_exact_mut(mw as usize).zip(data.chunks_exact(mw as usize)) {
                    for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
                        *d = 0.5 * (*d + *s);
                    }
                }
            }
            Ok(())
        })
    }
}

fn check_layout(path: &Path, model: &mut Model, cfg: &DepthConfig) -> Result<(u32, u32), InferError> {
    let shape_err = |what: &str, expected: &str, actual: String| InferError::Shape {
        path: path.to_path_buf(),
        what: what.to_string(),
        expected: expected.to_string(),
        actual,
    };
    if model.inputs().len() != 1 {
        return Err(shape_err("inputs", "1 input `[1, 3, H, W]`", format!("{} inputs", model.inputs().len())));
    }
    let input = &model.inputs()[0];
    let what = format!("input `{}`", input.name);
    let dims = input.float_shape(path, &what)?;
    if dims.len() != 4 || !(dims[0] == 1 || dims[0] < 0) || dims[1] != 3 {
        return Err(shape_err(&what, "[1, 3, H, W] (RGB, NCHW)", fmt_shape(&dims)));
    }
    let net = resolve_size(path, &what, &dims[2..4], cfg.input_size, "depth.input_size")?;
    // The outputs' shapes are known once the input's is (tract plans the graph for it here).
    model.set_input_shape(path, [1, 3, net.1 as usize, net.0 as usize])?;
    let Some(output) = model.outputs().first() else {
        return Err(shape_err("outputs", "1 output `[1, H, W]`", "none".into()));
    };
    let what = format!("output `{}`", output.name);
    let odims = output.float_shape(path, &what)?;
    let ok = match odims.as_slice() {
        [b, _, _] => *b == 1 || *b < 0,
        [b, c, _, _] => (*b == 1 || *b < 0) && *c == 1,
        _ => false,
    };
    if !ok {
        return Err(shape_err(&what, "[1, H, W] or [1, 1, H, W] (relative inverse depth)", fmt_shape(&odims)));
    }
    // Depth maps keep the input's aspect ratio (MiDaS and Depth Anything output the input size);
    // a map that does not is some other kind of model (e.g. a detector given as the depth model).
    let (oh, ow) = (odims[odims.len() - 2], odims[odims.len() - 1]);
    if oh > 0 && ow > 0 {
        let ratio = (ow as f64 / oh as f64) / (net.0 as f64 / net.1 as f64);
        if !(0.8..=1.25).contains(&ratio) {
            return Err(shape_err(
                &what,
                &format!("[1, H, W] or [1, 1, H, W] with the input's aspect ratio (input {}x{})", net.0, net.1),
                fmt_shape(&odims),
            ));
        }
    }
    Ok(net)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_maps_frame_pixels_and_takes_median() {
        // 4x2 map for an 8x4 frame: each map pixel covers 2x2 frame pixels.
        let data = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, f32::NAN];
        let m = RelDepthMap::new(Seconds(1.0), 4, 2, (8, 4), 0, data).unwrap();
        assert_eq!(m.sample(Pixel::new(0.0, 0.0)), Some(1.0));
        assert_eq!(m.sample(Pixel::new(7.9, 0.5)), Some(4.0));
        assert_eq!(m.sample(Pixel::new(5.0, 3.0)), Some(7.0));
        assert_eq!(m.sample(Pixel::new(7.0, 3.0)), None); // NaN only
        assert_eq!(m.sample(Pixel::new(8.0, 0.0)), None); // outside
        assert_eq!(m.sample(Pixel::new(-0.1, 0.0)), None);
        // Radius 1 around (1, 0): values 1,2,3,5,6,7 -> median (upper) 5.
        assert_eq!(m.sample_with_radius(Pixel::new(2.5, 0.5), 1), Some(5.0));
        // An outlier in a 3x3 window does not move the median.
        let mut d = vec![2.0f32; 9];
        d[4] = 100.0;
        let m = RelDepthMap::new(Seconds(0.0), 3, 3, (3, 3), 1, d).unwrap();
        assert_eq!(m.sample(Pixel::new(1.5, 1.5)), Some(2.0));
    }

    #[test]
    fn new_rejects_inconsistent_sizes() {
        assert!(RelDepthMap::new(Seconds(0.0), 2, 2, (4, 4), 0, vec![0.0; 3]).is_none());
        assert!(RelDepthMap::new(Seconds(0.0), 2, 2, (4, 4), 9, vec![0.0; 4]).is_none());
    }
}
