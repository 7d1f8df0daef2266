//! Conformance with real model exports: YOLO11n (Ultralytics export) and Depth Anything
//! V2 Small (transformers), random weights. The models are large, so they are not in the
//! repository: `bash scripts/onnx_conformance.sh` exports them with the pinned Python stack and then
//! runs these tests with `--ignored`. FME_CONFORMANCE_DIR points at the exports.

use std::path::PathBuf;

use fme::geometry::PixelBox;
use fme::infer::{DepthConfig, DepthNet, Detector, DetectorConfig, RgbFrame, SessionOptions};
use fme::units::Seconds;

fn dir() -> PathBuf {
    PathBuf::from(std::env::var("FME_CONFORMANCE_DIR").unwrap_or_else(|_| "/tmp/fme-conformance".into()))
}

fn read_f32(name: &str) -> Vec<f32> {
    let bytes =
        std::fs::read(dir().join(name)).unwrap_or_else(|e| panic!("{name}: {e} (run scripts/onnx_conformance.sh)"));
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

fn frame() -> image::RgbImage {
    image::open(dir().join("frame.png")).expect("frame.png (run scripts/onnx_conformance.sh)").to_rgb8()
}

#[test]
#[ignore = "needs the exports of scripts/onnx_conformance.sh"]
fn yolo11n_export_loads_and_decodes_like_ultralytics() {
    let img = frame();
    let frame = RgbFrame::from(&img);
    for size in [640u32, 320] {
        let conf: f32 =
            std::fs::read_to_string(dir().join(format!("yolo11n_{size}.conf"))).unwrap().trim().parse().unwrap();
        let cfg = DetectorConfig {
            model: dir().join(format!("yolo11n_{size}.onnx")),
            num_classes: Some(80),
            // Ultralytics keeps scores strictly above conf; fme keeps >= conf.
            confidence: f64::from(conf.next_up()),
            // Ultralytics' NMS: per class, IoU 0.7.
            nms_iou: 0.7,
            class_agnostic: false,
            ..Default::default()
        };
        let mut det = Detector::open(&cfg, SessionOptions::default()).unwrap();
        assert_eq!(det.input_size(), (size, size));
        assert_eq!(det.num_classes(), 80);

        det.preprocess(&frame);
        let want = read_f32(&format!("yolo11n_{size}.input.f32"));
        let diff = det.input_tensor().iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        println!(
            "yolo11n {size}: letterbox input max |fme - ultralytics| = {diff:.5} ({:.2} grey levels)",
            diff * 255.0
        );
        assert_eq!(det.input_tensor().len(), want.len());
        assert!(diff <= 2.5 / 255.0, "letterbox differs from Ultralytics by {diff}");

        let text = std::fs::read_to_string(dir().join(format!("yolo11n_{size}.dets.txt"))).unwrap();
        let theirs: Vec<(PixelBox, f64, u16)> = text
            .lines()
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                (PixelBox::new(v[0], v[1], v[2], v[3]), v[4], v[5] as u16)
            })
            // fme drops boxes that clipping leaves empty; Ultralytics keeps them.
            .filter(|(b, _, _)| b.w > 0.5 && b.h > 0.5)
            .collect();
        assert!(!theirs.is_empty());
        let matched = |ours: &[fme::infer::Detection]| {
            theirs
                .iter()
                .filter(|(b, s, c)| {
                    ours.iter().any(|o| o.class == *c && o.bbox.iou(b) > 0.9 && (o.score - s).abs() < 0.02)
                })
                .count()
        };

        // Decoding + NMS on Ultralytics' own input tensor: the same boxes.
        det.input_tensor_mut().copy_from_slice(&want);
        let lb = fme::infer::Letterbox::new((img.width(), img.height()), (size, size));
        let ours: Vec<_> = det.run_preprocessed(&lb, Seconds(0.0)).unwrap().items.to_vec();
        let m = matched(&ours);
        println!(
            "yolo11n {size}, same input: ultralytics {} boxes, fme {} boxes, {m} matched",
            theirs.len(),
            ours.len()
        );
        assert!(m * 100 >= theirs.len() * 95, "only {m} of {} Ultralytics boxes found", theirs.len());
        assert!(ours.len().abs_diff(theirs.len()) * 20 <= theirs.len() + 20);

        // End to end from the frame: sub-grey-level resize differences may flip borderline anchors.
        let ours: Vec<_> = det.detect(&frame, Seconds(0.0)).unwrap().items.to_vec();
        let m = matched(&ours);
        println!(
            "yolo11n {size}, from frame: ultralytics {} boxes, fme {} boxes, {m} matched",
            theirs.len(),
            ours.len()
        );
        assert!(m * 10 >= theirs.len() * 7, "only {m} of {} Ultralytics boxes found", theirs.len());
    }
}

#[test]
#[ignore = "needs the exports of scripts/onnx_conformance.sh"]
fn depth_anything_v2_small_export_loads_and_matches_onnxruntime_python() {
    let img = frame();
    let frame = RgbFrame::from(&img);
    let cfg = DepthConfig { model: dir().join("da2s_252x448.onnx"), ..Default::default() };
    let mut net = DepthNet::open(&cfg, SessionOptions::default()).unwrap();
    assert_eq!(net.input_size(), (448, 252));
    net.preprocess(&frame);
    let want = read_f32("da2s_252x448.input.f32");
    let diff = net.input_tensor().iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    println!("depth anything v2 small: input max |fme - python| = {diff:.5} (ImageNet-normalised units)");
    assert!(diff < 0.05, "{diff}");

    let reference = read_f32("da2s_252x448.out.f32");
    let map = net.estimate(&frame, Seconds(1.0)).unwrap();
    assert_eq!(map.dims(), (448, 252));
    let scale = reference.iter().fold(0f32, |m, v| m.max(v.abs())).max(f32::MIN_POSITIVE);
    let err = map.data().iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max) / scale;
    println!("depth anything v2 small: output max relative |fme - python| = {err:.4}");
    assert!(map.data().iter().all(|v| v.is_finite()));
    assert!(err < 0.05, "{err}");
    assert!(map.sample(fme::geometry::Pixel::new(640.0, 360.0)).is_some());
}
