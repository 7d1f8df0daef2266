//! The fish detector: an Ultralytics-style YOLO ONNX model (input `[1, 3, H, W]` RGB in 0..1,
//! letterboxed; output `[1, 4 + nc, N]`), with preprocessing, decoding and NMS in Rust.
//! Buffers are sized at load and reused, so a frame allocates nothing once the frame size is known.

use std::path::{Path, PathBuf};

use super::InferError;
use super::backend::{Backend, Model};
use super::config::DetectorConfig;
use super::decode::{Detection, clip_to_frame, decode_yolo, nms};
use super::frame::{Normalize, Resampler, RgbFrame};
use super::letterbox::{Letterbox, PAD_VALUE};
use super::runtime::{SessionOptions, fmt_shape};
use crate::units::Seconds;

/// Detections of one frame, stamped with that frame's time.
#[derive(Debug, Clone, Copy)]
pub struct Detections<'a> {
    /// Timestamp of the frame the detector ran on.
    pub t: Seconds,
    /// The detections after NMS, highest score first.
    pub items: &'a [Detection],
}

/// A loaded detector with its reusable buffers.
pub struct Detector {
    model: Model,
    path: PathBuf,
    cfg: DetectorConfig,
    net: (u32, u32),
    nc: usize,
    input: Vec<f32>,
    letterbox: Option<Letterbox>,
    resampler: Resampler,
    dets: Vec<Detection>,
}

impl std::fmt::Debug for Detector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Detector")
            .field("path", &self.path)
            .field("backend", &self.model.backend())
            .field("net", &self.net)
            .field("nc", &self.nc)
            .finish()
    }
}

impl Detector {
    /// Loads `cfg.model` with the build's default backend and checks that it follows the YOLO
    /// detection convention.
    pub fn open(cfg: &DetectorConfig, opts: SessionOptions) -> Result<Self, InferError> {
        Self::open_with(cfg, opts, Backend::DEFAULT)
    }

    /// As [`Self::open`], with the given backend.
    pub fn open_with(cfg: &DetectorConfig, opts: SessionOptions, backend: Backend) -> Result<Self, InferError> {
        cfg.validate()?;
        let path = cfg.model.clone();
        let mut model = Model::open(&path, opts, backend)?;
        let (net, nc) = check_layout(&path, &mut model, cfg)?;
        let plane = net.0 as usize * net.1 as usize;
        Ok(Self {
            model,
            path,
            cfg: cfg.clone(),
            net,
            nc,
            input: vec![PAD_VALUE as f32 / 255.0; 3 * plane],
            letterbox: None,
            resampler: Resampler::default(),
            dets: Vec::with_capacity(cfg.max_candidates.min(1 << 16)),
        })
    }

    /// Network input `(width, height)`.
    pub fn input_size(&self) -> (u32, u32) {
        self.net
    }
    /// Number of classes of the model.
    pub fn num_classes(&self) -> usize {
        self.nc
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

    /// The network input buffer as last filled by `preprocess` (planar `[3, H, W]`).
    pub fn input_tensor(&self) -> &[f32] {
        &self.input
    }

    /// Letterboxes `frame` into the input buffer (exposed for benchmarks); returns the transform.
    pub fn preprocess(&mut self, frame: &RgbFrame<'_>) -> Letterbox {
        let src = (frame.width(), frame.height());
        let lb = match self.letterbox {
            Some(lb) if lb.src == src => lb,
            _ => {
                // New frame size: rebuild the resize tables and repaint the padding once.
                let lb = Letterbox::new(src, self.net);
                self.resampler.build(src, lb.inner);
                self.input.fill(PAD_VALUE as f32 / 255.0);
                self.letterbox = Some(lb);
                lb
            }
        };
        let (w, h) = (self.net.0 as usize, self.net.1 as usize);
        let (l, t) = (lb.pad.0 as usize, lb.pad.1 as usize);
        self.resampler.run(frame, l, t, w, h, &Normalize::UNIT, &mut self.input);
        lb
    }

    /// Runs the detector on one frame taken at `t`.
    pub fn detect(&mut self, frame: &RgbFrame<'_>, t: Seconds) -> Result<Detections<'_>, InferError> {
        let lb = self.preprocess(frame);
        self.run_preprocessed(&lb, t)
    }

    /// Mutable access to the input buffer, for callers that prepare the tensor themselves (e.g. to
    /// check decoding against a reference implementation on identical input).
    pub fn input_tensor_mut(&mut self) -> &mut [f32] {
        &mut self.input
    }

    /// Runs the network on the current input buffer and decodes with letterbox `lb`.
    pub fn run_preprocessed(&mut self, lb: &Letterbox, t: Seconds) -> Result<Detections<'_>, InferError> {
        let (w, h) = (self.net.0 as usize, self.net.1 as usize);
        let (path, nc, conf, dets) = (&self.path, self.nc, self.cfg.confidence as f32, &mut self.dets);
        self.model.run(path, [1, 3, h, w], &self.input, |dims, data| {
            if dims.len() != 3 || dims[0] != 1 || dims[1] as usize != 4 + nc {
                return Err(InferError::Shape {
                    path: path.clone(),
                    what: "output at run time".into(),
                    expected: format!("[1, {}, N]", 4 + nc),
                    actual: fmt_shape(dims),
                });
            }
            decode_yolo(data, nc, dims[2] as usize, conf, lb, dets);
            Ok(())
        })?;
        nms(
            &mut self.dets,
            self.cfg.nms_iou,
            self.cfg.class_agnostic,
            self.cfg.max_candidates,
            self.cfg.max_detections,
        );
        clip_to_frame(&mut self.dets, lb);
        Ok(Detections { t, items: &self.dets })
    }
}

/// Checks the model's I/O against the convention; returns the input `(w, h)` and class count.
fn check_layout(path: &Path, model: &mut Model, cfg: &DetectorConfig) -> Result<((u32, u32), usize), InferError> {
    let shape_err = |what: &str, expected: String, actual: String| InferError::Shape {
        path: path.to_path_buf(),
        what: what.to_string(),
        expected,
        actual,
    };
    if model.inputs().len() != 1 {
        return Err(shape_err("inputs", "1 input `[1, 3, H, W]`".into(), format!("{} inputs", model.inputs().len())));
    }
    let input = &model.inputs()[0];
    let what = format!("input `{}`", input.name);
    let dims = input.float_shape(path, &what)?;
    let ok_batch = |d: i64| d == 1 || d < 0;
    if dims.len() != 4 || !ok_batch(dims[0]) || dims[1] != 3 {
        return Err(shape_err(&what, "[1, 3, H, W] (RGB, NCHW)".into(), fmt_shape(&dims)));
    }
    let net = resolve_size(path, &what, &dims[2..4], cfg.input_size, "detector.input_size")?;
    // The outputs' shapes are known once the input's is (tract plans the graph for it here).
    model.set_input_shape(path, [1, 3, net.1 as usize, net.0 as usize])?;
    let Some(output) = model.outputs().first() else {
        return Err(shape_err("outputs", "1 output `[1, 4 + nc, N]`".into(), "none".into()));
    };
    let what = format!("output `{}`", output.name);
    let odims = output.float_shape(path, &what)?;
    // A YOLO head has far more anchors than rows; `[1, N, 6]` is an end-to-end (NMS-free, e.g.
    // YOLO26) or transposed export, which this decoder does not read.
    let transposed = odims.len() == 3 && odims[2] > 0 && odims[2] <= odims[1];
    if odims.len() != 3 || !ok_batch(odims[0]) || odims[1] < 5 || transposed {
        return Err(shape_err(
            &what,
            "[1, 4 + nc, N] (Ultralytics YOLOv8/YOLO11 detect: cx, cy, w, h, class scores; no NMS)".into(),
            fmt_shape(&odims),
        ));
    }
    let nc = odims[1] as usize - 4;
    if let Some(want) = cfg.num_classes
        && want != nc
    {
        return Err(shape_err(
            &what,
            format!("[1, {}, N] (detector.num_classes = {want})", want + 4),
            fmt_shape(&odims),
        ));
    }
    // Ultralytics heads have one column per cell of strides 8/16/32; fme's own model has one per
    // stride-2 cell. Both decode the same way, so a different count is only logged.
    if odims[2] > 0 {
        let (w, h) = (net.0 as i64, net.1 as i64);
        let anchors: i64 = [8, 16, 32].iter().map(|s| (w / s) * (h / s)).sum();
        if odims[2] != anchors {
            tracing::debug!(model = %path.display(), n = odims[2], yolo = anchors, "detector column count is not strides 8/16/32");
        }
    }
    Ok((net, nc))
}

/// The network input size from the model's spatial dims (`H, W`), or from the configuration when
/// they are dynamic; a configured size must agree with static dims.
pub(crate) fn resolve_size(
    path: &Path,
    what: &str,
    hw: &[i64],
    configured: Option<[u32; 2]>,
    key: &'static str,
) -> Result<(u32, u32), InferError> {
    let (h, w) = (hw[0], hw[1]);
    match (h > 0 && w > 0, configured) {
        (true, None) => Ok((w as u32, h as u32)),
        (true, Some([cw, ch])) if cw as i64 == w && ch as i64 == h => Ok((cw, ch)),
        (true, Some([cw, ch])) => Err(InferError::Shape {
            path: path.to_path_buf(),
            what: format!("{what} vs {key}"),
            expected: format!("[1, 3, {ch}, {cw}] ({key} = [{cw}, {ch}])"),
            actual: format!("[1, 3, {h}, {w}]"),
        }),
        (false, Some([cw, ch])) => Ok((cw, ch)),
        (false, None) => Err(InferError::Config {
            key,
            reason: format!("model {} has a dynamic input size ({what}); set [width, height]", path.display()),
        }),
    }
}
