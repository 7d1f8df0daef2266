//! ONNX inference (ONNX Runtime or tract, see [`backend`]): YOLO-style detector, MiDaS-style relative depth, reduced-rate scheduling
//! (paper sec. 4.2 detection, sec. 4.3 relative depth).
//!
//! - [`backend`]: the seam to the runtime chosen at build time; [`embedded`]: the bundled models
//!   inside the executable (feature `embed-models`).
//! - [`runtime`]: one ONNX Runtime environment per process, library lookup, model path lookup.
//! - [`Detector`]: Ultralytics YOLOv8/YOLO11 export convention, letterbox + decode + NMS in Rust,
//!   producing [`Detection`]s in frame pixels.
//! - [`DepthNet`]: MiDaS v2.1 small / Depth Anything V2 convention, producing a [`RelDepthMap`]
//!   (relative inverse depth, larger = nearer) sampled at the pixels the estimator needs.
//! - [`InferSchedule`]: which frames get detection and depth, at configured rates on frame time.

pub mod backend;
pub mod config;
mod decode;
mod depth;
mod detector;
pub mod embedded;
mod error;
mod form;
mod frame;
mod letterbox;
pub mod runtime;
mod scheduler;

pub use backend::Backend;
pub use config::{DepthConfig, DetectorConfig, MAX_DETECTIONS, MAX_SAMPLE_RADIUS};
pub use decode::{Detection, clip_to_frame, decode_yolo, nms};
pub use depth::{DepthNet, RelDepthMap};
pub use detector::{Detections, Detector};
pub use error::InferError;
pub use form::ModelForm;
pub use frame::{Normalize, RgbFrame};
pub use letterbox::{Letterbox, PAD_VALUE};
pub use runtime::SessionOptions;
pub use scheduler::{FramePlan, InferSchedule, RateScheduler};
