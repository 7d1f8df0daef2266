#!/usr/bin/env python3
"""Writes the tiny ONNX fixtures in tests/fixtures/onnx/ used by tests/infer_*.rs.

Needs only the `onnx` package (pip install onnx==1.23.2). Deterministic: running it again gives
byte-identical files. Each model has the I/O layout of a real convention but a few hand-built
nodes, so the tests know exactly what it outputs:

- det_yolo_nc2.onnx: Ultralytics YOLO layout, input `images` [1,3,64,96], output `output0`
  [1,6,N] (4 box rows + 2 classes, N = 8*12 + 4*6 + 2*3 = 126 anchors, as strides 8/16/32).
  Boxes are constants (cx,cy,w,h in input pixels); class scores = base * mean(images), so a white
  frame gives the base scores and a black frame none: the test sees that the input reaches the model.
- depth_chw.onnx: input `image` [1,3,24,32], output `depth` [1,24,32] = mean over channels of
  the (normalised) input. depth_c1hw.onnx: same with output [1,1,24,32].
- det_dynamic.onnx: det layout with dynamic H, W and N (needs detector.input_size).
- det_bad_input.onnx: input [1,1,64,96] (grey), a shape mismatch.
- det_end2end.onnx: output [1,100,6] (YOLO26-style end-to-end), a layout mismatch.
"""
import os
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures", "onnx")
OPSET = [helper.make_opsetid("", 17)]

# Detector fixture constants (also hard-coded in tests/infer_onnx.rs).
DET_H, DET_W = 64, 96
N_ANCHORS = sum((DET_H // s) * (DET_W // s) for s in (8, 16, 32))
# (cx, cy, w, h, score class0, score class1) for the first anchors; the rest have score 0.
BOXES = [
    (20.0, 30.0, 10.0, 8.0, 0.9, 0.1),   # class 0
    (21.0, 30.0, 10.0, 8.0, 0.8, 0.0),   # overlaps the first (IoU ~0.82): suppressed
    (70.0, 40.0, 12.0, 12.0, 0.05, 0.6),  # class 1
    (50.0, 10.0, 6.0, 6.0, 0.2, 0.1),    # below conf 0.25
]


def save(model, name):
    model.producer_name = "fme-fixtures"
    onnx.checker.check_model(model, full_check=True)
    path = os.path.join(OUT, name)
    onnx.save(model, path)
    print(f"wrote {path} ({os.path.getsize(path)} bytes)")


def det_model(name, in_shape, h_dim, w_dim, n_dim, end2end=False):
    boxes = np.zeros((1, 4, N_ANCHORS), np.float32)
    scores = np.zeros((1, 2, N_ANCHORS), np.float32)
    boxes[0, 2:, :] = 1.0
    for j, (cx, cy, w, h, s0, s1) in enumerate(BOXES):
        boxes[0, :, j] = (cx, cy, w, h)
        scores[0, :, j] = (s0, s1)
    inits = [numpy_helper.from_array(boxes, "boxes"), numpy_helper.from_array(scores, "base_scores")]
    nodes = [
        helper.make_node("ReduceMean", ["images"], ["m"], keepdims=1),  # [1,1,1,1]
        helper.make_node("Squeeze", ["m", "sq_axes"], ["m1"]),  # [1]
        helper.make_node("Mul", ["base_scores", "m1"], ["scores"]),
        helper.make_node("Concat", ["boxes", "scores"], ["cat"], axis=1),
    ]
    inits.append(numpy_helper.from_array(np.array([0, 1, 2], np.int64), "sq_axes"))
    if end2end:
        inits.append(numpy_helper.from_array(np.array([0, 0, 0], np.int64), "st"))
        inits.append(numpy_helper.from_array(np.array([1, 6, 100], np.int64), "en"))
        nodes.append(helper.make_node("Slice", ["cat", "st", "en"], ["sl"]))
        nodes.append(helper.make_node("Transpose", ["sl"], ["output0"], perm=[0, 2, 1]))
        out_shape = [1, 100, 6]
    else:
        nodes[-1].output[0] = "output0"
        out_shape = [1, 6, n_dim]
    graph = helper.make_graph(
        nodes,
        name,
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, in_shape)],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, out_shape)],
        inits,
    )
    return helper.make_model(graph, opset_imports=OPSET, ir_version=8)


def depth_model(keep_channel):
    nodes = [helper.make_node("ReduceMean", ["image", "axes"], ["depth"], keepdims=1 if keep_channel else 0)]
    inits = [numpy_helper.from_array(np.array([1], np.int64), "axes")]
    out_shape = [1, 1, 24, 32] if keep_channel else [1, 24, 32]
    graph = helper.make_graph(
        nodes,
        "depth",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 24, 32])],
        [helper.make_tensor_value_info("depth", TensorProto.FLOAT, out_shape)],
        inits,
    )
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)], ir_version=8)


def main():
    os.makedirs(OUT, exist_ok=True)
    save(det_model("det", [1, 3, DET_H, DET_W], DET_H, DET_W, N_ANCHORS), "det_yolo_nc2.onnx")
    save(det_model("det_dyn", [1, 3, "height", "width"], "height", "width", "anchors"), "det_dynamic.onnx")
    save(det_model("det_bad", [1, 1, DET_H, DET_W], DET_H, DET_W, N_ANCHORS), "det_bad_input.onnx")
    save(det_model("det_e2e", [1, 3, DET_H, DET_W], DET_H, DET_W, N_ANCHORS, end2end=True), "det_end2end.onnx")
    save(depth_model(False), "depth_chw.onnx")
    save(depth_model(True), "depth_c1hw.onnx")
    return 0


if __name__ == "__main__":
    sys.exit(main())
