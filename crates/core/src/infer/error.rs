//! Errors of the inference stage. Every variant names the file (model or library) it is about and,
//! for layout problems, the expected versus the actual tensor shape.

use std::path::PathBuf;

/// What can go wrong while loading or running the ONNX models.
#[derive(Debug, thiserror::Error)]
pub enum InferError {
    /// No usable ONNX Runtime shared library was found.
    #[error(
        "ONNX Runtime library not found or unusable; tried: {tried}. Run `make setup` (puts ONNX Runtime 1.31 in \
         .ort/lib) or set ORT_DYLIB_PATH to libonnxruntime.so"
    )]
    Library {
        /// Every candidate path with the reason it was rejected.
        tried: String,
    },
    /// The library loaded but the environment could not be created.
    #[error("ONNX Runtime environment could not be created: {0}")]
    Environment(String),
    /// The model file is missing, unreadable, or not a valid ONNX model.
    #[error("model file {}: {reason}", path.display())]
    ModelFile {
        /// The model file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The model's inputs or outputs do not follow the configured convention.
    #[error("model {}: {what}: expected {expected}, got {actual}", path.display())]
    Shape {
        /// The model file.
        path: PathBuf,
        /// Which tensor (e.g. `input \`images\``).
        what: String,
        /// The shape or type the convention requires.
        expected: String,
        /// The shape or type found in the model.
        actual: String,
    },
    /// ONNX Runtime failed while running a model.
    #[error("model {}: inference failed: {reason}", path.display())]
    Run {
        /// The model file.
        path: PathBuf,
        /// The runtime's message.
        reason: String,
    },
    /// A frame whose buffer does not match its stated size.
    #[error("frame {width}x{height}: buffer has {len} bytes, packed RGB8 needs {expected}")]
    BadFrame {
        /// Stated width, pixels.
        width: u32,
        /// Stated height, pixels.
        height: u32,
        /// Actual buffer length, bytes.
        len: usize,
        /// Required length, bytes.
        expected: usize,
    },
    /// An inference setting that cannot work.
    #[error("invalid inference setting `{key}`: {reason}")]
    Config {
        /// The configuration key (e.g. `detector.iou_threshold`).
        key: &'static str,
        /// Why it is invalid.
        reason: String,
    },
}
