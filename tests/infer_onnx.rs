//! Loads the tiny ONNX fixtures (tests/fixtures/onnx, made by scripts/make_onnx_fixtures.py) with
//! ONNX Runtime and checks decoding, depth sampling and the start-up errors. Needs the library that
//! `make setup` puts in .ort/lib (no network, no GPU).

use std::path::PathBuf;

use fme::geometry::{Pixel, PixelBox};
use fme::infer::{DepthConfig, DepthNet, Detector, DetectorConfig, InferError, RgbFrame, SessionOptions};
use fme::units::Seconds;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/onnx").join(name)
}

/// The fixtures' expectations follow Ultralytics' defaults: conf 0.25, per-class NMS at IoU 0.7.
fn det_cfg(name: &str) -> DetectorConfig {
    DetectorConfig { model: fixture(name), confidence: 0.25, nms_iou: 0.7, class_agnostic: false, ..Default::default() }
}

fn solid(w: u32, h: u32, v: u8) -> Vec<u8> {
    vec![v; (w * h * 3) as usize]
}

const ONE_THREAD: SessionOptions = SessionOptions { intra_threads: 1, spin: false };

fn close(a: &PixelBox, b: &PixelBox) -> bool {
    (a.x - b.x).abs() < 1e-3 && (a.y - b.y).abs() < 1e-3 && (a.w - b.w).abs() < 1e-3 && (a.h - b.h).abs() < 1e-3
}

#[test]
fn detector_decodes_known_output_with_nms_and_unletterboxing() {
    let mut det = Detector::open(&det_cfg("det_yolo_nc2.onnx"), ONE_THREAD).expect("fixture loads");
    assert_eq!(det.input_size(), (96, 64));
    assert_eq!(det.num_classes(), 2);

    // A white 192x128 frame fills the 96x64 input exactly (gain 0.5, no padding): mean(input) = 1,
    // so the fixture's scores are its base scores.
    let buf = solid(192, 128, 255);
    let frame = RgbFrame::new(192, 128, &buf).unwrap();
    let d = det.detect(&frame, Seconds(3.25)).unwrap();
    assert_eq!(d.t, Seconds(3.25));
    assert_eq!(d.items.len(), 2, "{:?}", d.items);
    // Anchor 0: cx 20, cy 30, w 10, h 8 in input pixels -> frame (15, 26, 10, 8) / 0.5.
    assert_eq!(d.items[0].class, 0);
    assert!((d.items[0].score - 0.9).abs() < 1e-6);
    assert!(close(&d.items[0].bbox, &PixelBox::new(30.0, 52.0, 20.0, 16.0)), "{:?}", d.items[0]);
    // Anchor 1 overlaps anchor 0 (IoU 0.82 > 0.7) and is suppressed; anchor 3 is below conf 0.25.
    assert_eq!(d.items[1].class, 1);
    assert!((d.items[1].score - 0.6).abs() < 1e-6);
    assert!(close(&d.items[1].bbox, &PixelBox::new(128.0, 68.0, 24.0, 24.0)), "{:?}", d.items[1]);

    // A black frame: scores 0, nothing detected. Proves the pixels reach the model.
    let buf = solid(192, 128, 0);
    let frame = RgbFrame::new(192, 128, &buf).unwrap();
    assert!(det.detect(&frame, Seconds(3.5)).unwrap().items.is_empty());
}

#[test]
fn detector_letterbox_padding_is_114_and_boxes_map_back() {
    let mut det = Detector::open(&det_cfg("det_yolo_nc2.onnx"), ONE_THREAD).unwrap();
    // A white square 64x64 frame: gain 1, inner 64x64, padded 16 px left and right with 114/255,
    // so mean(input) = (64*64 + 32*64*114/255) / (96*64).
    let buf = solid(64, 64, 255);
    let frame = RgbFrame::new(64, 64, &buf).unwrap();
    let mean = (64.0 * 64.0 + 32.0 * 64.0 * 114.0 / 255.0) / (96.0 * 64.0);
    let d = det.detect(&frame, Seconds(0.0)).unwrap();
    assert_eq!(d.items.len(), 2);
    // 1e-4: the runtimes sum the 18432 float32 inputs in different orders (tract is 5e-5 off).
    assert!((d.items[0].score - 0.9 * mean).abs() < 1e-4, "{}", d.items[0].score);
    // Anchor 0 at input (15..25, 26..34) -> frame (-1..9, 26..34), clipped at the left edge.
    assert!(close(&d.items[0].bbox, &PixelBox::new(0.0, 26.0, 9.0, 8.0)), "{:?}", d.items[0].bbox);
    // Anchor 2 at input (64..76, 34..46) -> frame (48..60, 34..46), clipped to 64.
    assert!(close(&d.items[1].bbox, &PixelBox::new(48.0, 34.0, 12.0, 12.0)), "{:?}", d.items[1].bbox);
}

#[test]
fn dynamic_input_needs_a_configured_size() {
    let e = Detector::open(&det_cfg("det_dynamic.onnx"), ONE_THREAD).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, InferError::Config { key: "detector.input_size", .. }), "{msg}");
    assert!(msg.contains("det_dynamic.onnx") && msg.contains("dynamic"), "{msg}");

    let cfg = DetectorConfig { input_size: Some([96, 64]), ..det_cfg("det_dynamic.onnx") };
    let mut det = Detector::open(&cfg, ONE_THREAD).unwrap();
    let buf = solid(96, 64, 255);
    let frame = RgbFrame::new(96, 64, &buf).unwrap();
    assert_eq!(det.detect(&frame, Seconds(0.0)).unwrap().items.len(), 2);
}

#[test]
fn shape_mismatches_name_file_and_shapes() {
    let e = Detector::open(&det_cfg("det_bad_input.onnx"), ONE_THREAD).unwrap_err().to_string();
    assert!(e.contains("det_bad_input.onnx") && e.contains("[1, 3, H, W]") && e.contains("[1, 1, 64, 96]"), "{e}");

    let e = Detector::open(&det_cfg("det_end2end.onnx"), ONE_THREAD).unwrap_err().to_string();
    assert!(e.contains("det_end2end.onnx") && e.contains("[1, 4 + nc, N]") && e.contains("[1, 100, 6]"), "{e}");

    let cfg = DetectorConfig { num_classes: Some(1), ..det_cfg("det_yolo_nc2.onnx") };
    let e = Detector::open(&cfg, ONE_THREAD).unwrap_err().to_string();
    assert!(e.contains("[1, 5, N]") && e.contains("[1, 6, 126]"), "{e}");

    let cfg = DetectorConfig { input_size: Some([320, 320]), ..det_cfg("det_yolo_nc2.onnx") };
    let e = Detector::open(&cfg, ONE_THREAD).unwrap_err().to_string();
    assert!(e.contains("[1, 3, 320, 320]") && e.contains("[1, 3, 64, 96]"), "{e}");

    // A detector file given as the depth model: its output is not a depth map.
    let cfg = DepthConfig { model: fixture("det_yolo_nc2.onnx"), ..Default::default() };
    let e = DepthNet::open(&cfg, ONE_THREAD).unwrap_err().to_string();
    assert!(e.contains("[1, H, W] or [1, 1, H, W]") && e.contains("[1, 6, 126]"), "{e}");
}

#[test]
fn missing_and_corrupt_models_name_the_file() {
    let e = Detector::open(&det_cfg("no_such_model.onnx"), ONE_THREAD).unwrap_err();
    assert!(matches!(e, InferError::ModelFile { .. }));
    assert!(e.to_string().contains("no_such_model.onnx") && e.to_string().contains("cannot read"), "{e}");

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("garbage.onnx");
    std::fs::write(&bad, b"this is not a protobuf model \x00\x01\x02").unwrap();
    let e = DepthNet::open(&DepthConfig { model: bad.clone(), ..Default::default() }, ONE_THREAD).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("garbage.onnx") && msg.contains("not a loadable ONNX model"), "{msg}");

    let empty = dir.path().join("empty.onnx");
    std::fs::write(&empty, b"").unwrap();
    let e = DepthNet::open(&DepthConfig { model: empty, ..Default::default() }, ONE_THREAD).unwrap_err();
    assert!(e.to_string().contains("empty.onnx") && e.to_string().contains("empty"), "{e}");
}

/// A 64x48 frame whose grey level is 4 * column: after the 2x bilinear downscale to the 32x24
/// input (half-pixel centres) map column d holds 4 * (2d + 0.5) = 8d + 2.
fn gradient() -> Vec<u8> {
    let mut v = Vec::with_capacity(64 * 48 * 3);
    for _y in 0..48 {
        for x in 0..64u32 {
            v.extend_from_slice(&[(4 * x) as u8; 3]);
        }
    }
    v
}

#[test]
fn depth_map_resizes_normalises_and_samples() {
    for name in ["depth_chw.onnx", "depth_c1hw.onnx"] {
        let cfg = DepthConfig {
            model: fixture(name),
            mean: [0.5; 3],
            std: [0.25; 3],
            sample_radius: 0,
            ..Default::default()
        };
        let mut net = DepthNet::open(&cfg, ONE_THREAD).unwrap();
        assert_eq!(net.input_size(), (32, 24));
        let buf = gradient();
        let frame = RgbFrame::new(64, 48, &buf).unwrap();
        let map = net.estimate(&frame, Seconds(7.0)).unwrap();
        assert_eq!(map.t, Seconds(7.0));
        assert_eq!(map.dims(), (32, 24));
        assert_eq!(map.frame_size(), (64, 48));
        for (u, d) in [(10.3, 5.0), (0.0, 0.0), (63.9, 31.0)] {
            let want = ((8.0 * d + 2.0) / 255.0 - 0.5) / 0.25;
            let got = map.sample(Pixel::new(u, 20.0)).unwrap();
            assert!((got - want).abs() < 1e-5, "{name} at u={u}: {got} vs {want}");
        }
        assert_eq!(map.sample(Pixel::new(64.0, 10.0)), None);
        // Median of a 3x3 window on a linear ramp is the centre value.
        let c = map.sample_with_radius(Pixel::new(20.0, 20.0), 1).unwrap();
        assert!((c - ((8.0 * 10.0 + 2.0) / 255.0 - 0.5) / 0.25).abs() < 1e-5);
    }
}

#[test]
fn depth_flip_mirrors_the_second_map_back_before_averaging() {
    // The fixture is per pixel (channel mean), so the mirrored run's map, mirrored back, is the
    // first map again: the average must equal the unflipped ramp. Without mirroring back it
    // would be the ramp plus its mirror image, a constant.
    let plain = DepthConfig { model: fixture("depth_chw.onnx"), sample_radius: 0, ..Default::default() };
    let buf = gradient();
    let frame = RgbFrame::new(64, 48, &buf).unwrap();
    let mut net = DepthNet::open(&plain, ONE_THREAD).unwrap();
    let want = net.estimate(&frame, Seconds(1.0)).unwrap().data().to_vec();
    let mut flipped = DepthNet::open(&DepthConfig { flip: true, ..plain }, ONE_THREAD).unwrap();
    for t in [2.0, 3.0] {
        // Twice: the second call must start again from the frame, not from the mirrored buffer.
        let map = flipped.estimate(&frame, Seconds(t)).unwrap();
        assert_eq!(map.t, Seconds(t));
        assert_eq!(map.dims(), (32, 24));
        assert_eq!(map.data(), &want[..]);
    }
    assert!(want[0] < want[31], "the test frame must not be symmetric");
}
