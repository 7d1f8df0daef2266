//! A missing ONNX Runtime library is a clear error, not a panic. Its own test binary, because once
//! a process has loaded the library it stays loaded. ONNX Runtime's library lookup: only with the feature `ort`.
#![cfg(feature = "ort")]

use std::path::{Path, PathBuf};

use fme::infer::runtime;
use fme::infer::{DepthConfig, DepthNet, Detector, DetectorConfig, InferError, SessionOptions};

#[test]
fn missing_library_is_an_error_naming_the_path() {
    let e = runtime::environment_from(Path::new("/nonexistent/fme-test/libonnxruntime.so")).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, InferError::Library { .. }), "{msg}");
    assert!(msg.contains("/nonexistent/fme-test/libonnxruntime.so") && msg.contains("make setup"), "{msg}");

    // A file that exists but is not a shared library: the loader's message is passed on.
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("libonnxruntime.so");
    std::fs::write(&fake, b"not an ELF file").unwrap();
    let msg = runtime::environment_from(&fake).unwrap_err().to_string();
    assert!(msg.contains("libonnxruntime.so") && msg.contains("configured path"), "{msg}");

    // ORT_DYLIB_PATH set to a wrong path: opening a model fails with the library error (no panic,
    // no silent fallback to another copy).
    // SAFETY: this binary has a single test, so no other thread reads the environment meanwhile.
    unsafe { std::env::set_var("ORT_DYLIB_PATH", "/nonexistent/fme-env/libonnxruntime.so") };
    let model = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/onnx/det_yolo_nc2.onnx");
    let opts = SessionOptions::default();
    let e = Detector::open(&DetectorConfig { model: model.clone(), ..Default::default() }, opts).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("/nonexistent/fme-env/libonnxruntime.so") && msg.contains("ORT_DYLIB_PATH"), "{msg}");
    let e = DepthNet::open(&DepthConfig { model, ..Default::default() }, opts).unwrap_err();
    assert!(matches!(e, InferError::Library { .. }));
}
