//! The per-frame Rust side of detection (decode, NMS, clipping) and depth sampling allocate nothing
//! once their buffers exist. A counting global allocator checks it (own test binary).

use fme::geometry::Pixel;
use fme::infer::{Letterbox, RelDepthMap, clip_to_frame, decode_yolo, nms};
use fme::units::Seconds;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;

#[test]
fn decode_nms_and_sampling_do_not_allocate_per_frame() {
    let n = 3840;
    let mut out = vec![0f32; 5 * n];
    for j in 0..n {
        let (gx, gy) = ((j % 80) as f32, (j / 80) as f32);
        out[j] = gx * 4.0 + 2.0;
        out[n + j] = gy * 4.0 + 2.0;
        out[2 * n + j] = 12.0;
        out[3 * n + j] = 6.0;
        out[4 * n + j] = if j % 7 == 0 { 0.3 + (j % 5) as f32 * 0.1 } else { 0.0 };
    }
    let lb = Letterbox::new((640, 384), (320, 192));
    let mut dets = Vec::with_capacity(n);
    let map =
        RelDepthMap::new(Seconds(0.0), 160, 96, (640, 384), 1, (0..160 * 96).map(|i| i as f32).collect()).unwrap();
    // Warm-up frame, then count.
    decode_yolo(&out, 1, n, 0.25, &lb, &mut dets);
    let mut kept = 0;
    let mut acc = 0.0;
    let (allocs, ()) = counting_alloc::allocations_in(|| {
        for _ in 0..10 {
            decode_yolo(&out, 1, n, 0.25, &lb, &mut dets);
            nms(&mut dets, 0.7, false, 3000, 300);
            clip_to_frame(&mut dets, &lb);
            kept = dets.len();
            for d in &dets {
                acc += map.sample(d.bbox.center()).unwrap_or(0.0);
            }
            acc += map.sample(Pixel::new(10.0, 10.0)).unwrap_or(0.0);
        }
    });
    assert!(kept > 100, "{kept}");
    assert!(acc > 0.0);
    assert_eq!(allocs, 0, "allocations in the per-frame path");
}
