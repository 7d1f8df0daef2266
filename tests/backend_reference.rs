//! ONNX Runtime's outputs on the bundled models and recording agree with the stored reference that
//! tests/backend_parity.rs holds tract to (tests/common/backend_outputs.rs), so the static check's
//! parity test, which runs without ONNX Runtime, compares tract with ONNX Runtime. The bounds are
//! tighter than the parity bounds but leave room for other CPUs' kernels (int8 dot products differ
//! between instruction sets). `FME_WRITE_BACKEND_REFERENCE=1` writes the reference instead (after a
//! change of the bundled models).
#![cfg(feature = "ort")]

#[path = "common/backend_outputs.rs"]
mod backend_outputs;

use backend_outputs::{Bounds, ModelSet, check, compare, compute, frames, load_reference, save_reference};
use fme::infer::Backend;

const SAME: Bounds =
    Bounds { mean_iou: 0.995, count_diff: 0.005, depth_r: 0.9999, activity_rmse: 0.002, activity_only_one: 1 };

#[test]
fn onnx_runtime_matches_the_stored_reference() {
    let frames = frames();
    let write = std::env::var_os("FME_WRITE_BACKEND_REFERENCE").is_some_and(|v| v == "1");
    for set in [ModelSet::Int8, ModelSet::Fp32] {
        let ours = compute(Backend::Ort, set, &frames);
        if write {
            save_reference(set, &ours);
        }
        let reference = load_reference(set);
        check(&format!("onnxruntime {} vs the reference", set.name()), &compare(&reference, &ours), &SAME);
    }
}
