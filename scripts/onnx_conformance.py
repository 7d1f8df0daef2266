#!/usr/bin/env python3
"""Conformance with the real ONNX formats: exports the YOLO11n architecture (Ultralytics,
from yolo11n.yaml, random weights) and a Depth Anything V2 Small architecture (transformers config,
random weights) to ONNX in OUT_DIR, runs them with ONNX Runtime on a test frame, and writes the
reference results that `tests/infer_conformance.rs` (run with --ignored) compares fme against:

  frame.png                       the test frame (RGB)
  yolo11n_{S}.onnx                YOLO11n, nc=80, static S x S input (S = 640, 320)
  yolo11n_{S}.input.f32           Ultralytics LetterBox of frame.png, [1,3,S,S] float32 little-endian
  yolo11n_{S}.conf / .dets.txt    score threshold used / Ultralytics non_max_suppression (iou 0.7): x,y,w,h,score,class per line
  da2s_{H}x{W}.onnx               Depth Anything V2 Small, static [1,3,H,W] input, output [1,H,W]
  da2s_{H}x{W}.input.f32 / .out.f32  its input (fme-style bilinear resize + ImageNet norm) and output

Large files stay outside the repository. Nothing is downloaded at run time (random weights).
"""
import os
import sys
import time

import cv2
import numpy as np
import onnxruntime as ort
import torch

OUT = sys.argv[1] if len(sys.argv) > 1 else "/tmp/fme-conformance"
os.makedirs(OUT, exist_ok=True)
torch.manual_seed(0)
rng = np.random.default_rng(0)


def make_frame():
    # 1280x720 underwater-ish frame: blue-green gradient with bright ellipses ("fish").
    h, w = 720, 1280
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([20 + 30 * y / h, 80 + 60 * x / w, 120 + 40 * y / h], -1)
    for _ in range(25):
        cx, cy = rng.uniform(60, w - 60), rng.uniform(40, h - 40)
        a, b = rng.uniform(25, 70), rng.uniform(8, 20)
        m = ((x - cx) / a) ** 2 + ((y - cy) / b) ** 2 < 1
        img[m] = rng.uniform(150, 230, 3)
    img += rng.normal(0, 4, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def yolo(frame_rgb, size):
    from ultralytics import YOLO
    from ultralytics.data.augment import LetterBox
    from ultralytics.utils import nms as nms_mod

    model = YOLO("yolo11n.yaml")
    # A fresh network has BatchNorm statistics that do not match its activations, and Ultralytics
    # starts every class score at the same prior, so the output would barely depend on the image.
    # Calibrate BatchNorm on random images and randomise the last class convolution, so scores vary
    # across anchors and NMS has real work to do (the I/O layout is unchanged).
    net = model.model
    for mod in net.modules():
        if isinstance(mod, torch.nn.BatchNorm2d):
            mod.reset_running_stats()
            mod.momentum = None
    net.train()
    with torch.no_grad():
        for _ in range(3):
            net(torch.rand(4, 3, size, size))
    net.eval()
    for seq in net.model[-1].cv3:
        torch.nn.init.normal_(seq[-1].weight, std=0.005)
        torch.nn.init.constant_(seq[-1].bias, -3.0)
    path = model.export(format="onnx", imgsz=size, dynamic=False, simplify=True, opset=17)
    dst = os.path.join(OUT, f"yolo11n_{size}.onnx")
    os.replace(path, dst)
    lb = LetterBox(new_shape=(size, size), auto=False, scale_fill=False, scaleup=True, center=True)
    img = lb(image=frame_rgb)  # channel order is preserved; we pass RGB
    x = img.transpose(2, 0, 1)[None].astype(np.float32) / 255.0
    x = np.ascontiguousarray(x)
    x.tofile(os.path.join(OUT, f"yolo11n_{size}.input.f32"))
    sess = ort.InferenceSession(dst, providers=["CPUExecutionProvider"])
    out = sess.run(None, {sess.get_inputs()[0].name: x})[0]
    print(f"yolo11n {size}: input {sess.get_inputs()[0].shape} output {out.shape}")
    # Random weights give class scores near the head's prior (~0.01), so conf 0.25 would leave
    # nothing: use the 98th percentile of the best class score, so about 2% of anchors enter NMS.
    conf = float(np.quantile(out[0, 4:].max(0), 0.98))
    with open(os.path.join(OUT, f"yolo11n_{size}.conf"), "w") as f:
        f.write(f"{conf:.9g}\n")
    dets = nms_mod.non_max_suppression(torch.from_numpy(out), conf_thres=conf, iou_thres=0.7, max_det=300)[0].numpy()
    # Undo the letterbox as ultralytics.utils.ops.scale_boxes does.
    h0, w0 = frame_rgb.shape[:2]
    gain = min(size / h0, size / w0)
    padw = round((size - w0 * gain) / 2 - 0.1)
    padh = round((size - h0 * gain) / 2 - 0.1)
    with open(os.path.join(OUT, f"yolo11n_{size}.dets.txt"), "w") as f:
        for x1, y1, x2, y2, s, c in dets:
            x1 = np.clip((x1 - padw) / gain, 0, w0)
            x2 = np.clip((x2 - padw) / gain, 0, w0)
            y1 = np.clip((y1 - padh) / gain, 0, h0)
            y2 = np.clip((y2 - padh) / gain, 0, h0)
            f.write(f"{x1:.3f},{y1:.3f},{x2 - x1:.3f},{y2 - y1:.3f},{s:.6f},{int(c)}\n")
    print(f"yolo11n {size}: {len(dets)} detections after NMS")


def bilinear_like_fme(img, w, h):
    # cv2 INTER_LINEAR has the same half-pixel sampling as fme (up to 8-bit fixed-point rounding).
    return cv2.resize(img.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)


def depth_anything(frame_rgb, h, w):
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

    backbone = Dinov2Config(
        hidden_size=384, num_hidden_layers=12, num_attention_heads=6, image_size=518, patch_size=14,
        out_indices=[3, 6, 9, 12], out_features=["stage3", "stage6", "stage9", "stage12"],
        reshape_hidden_states=False, apply_layernorm=True,
    )
    cfg = DepthAnythingConfig(
        backbone_config=backbone, reassemble_hidden_size=384, reassemble_factors=[4, 2, 1, 0.5],
        neck_hidden_sizes=[48, 96, 192, 384], fusion_hidden_size=64, head_hidden_size=32,
        depth_estimation_type="relative", max_depth=1,
    )
    model = DepthAnythingForDepthEstimation(cfg).eval()
    n = sum(p.numel() for p in model.parameters())

    class Wrap(torch.nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, image):
            return self.m(pixel_values=image).predicted_depth

    dst = os.path.join(OUT, f"da2s_{h}x{w}.onnx")
    dummy = torch.zeros(1, 3, h, w)
    torch.onnx.export(Wrap(model), (dummy,), dst, input_names=["image"], output_names=["depth"], opset_version=17,
                      dynamo=False)
    mean = np.array([0.485, 0.456, 0.406], np.float32)
    std = np.array([0.229, 0.224, 0.225], np.float32)
    x = (bilinear_like_fme(frame_rgb, w, h) / 255.0 - mean) / std
    x = np.ascontiguousarray(x.transpose(2, 0, 1)[None].astype(np.float32))
    x.tofile(os.path.join(OUT, f"da2s_{h}x{w}.input.f32"))
    sess = ort.InferenceSession(dst, providers=["CPUExecutionProvider"])
    out = sess.run(None, {"image": x})[0]
    out.astype(np.float32).tofile(os.path.join(OUT, f"da2s_{h}x{w}.out.f32"))
    with torch.no_grad():
        ref = model(pixel_values=torch.from_numpy(x)).predicted_depth.numpy()
    print(f"depth-anything-v2-small {h}x{w}: {n / 1e6:.2f}M params, output {out.shape}, "
          f"ORT vs torch max abs diff {np.abs(out - ref).max():.2e}, range {out.min():.4f}..{out.max():.4f}")


def main():
    t0 = time.time()
    frame = make_frame()
    cv2.imwrite(os.path.join(OUT, "frame.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    for s in (640, 320):
        yolo(frame, s)
    depth_anything(frame, 252, 448)
    print(f"conformance exports in {OUT} ({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
