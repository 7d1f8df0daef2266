"""Static int8 quantisation (QDQ) with onnxruntime.quantization, calibrated on generator frames.

Two variants are produced and measured, because on x86 ONNX Runtime 1.31 fuses QDQ convolutions
into int8 kernels only with uint8 activations (U8S8), while int8/int8 (S8S8) runs most convolutions
in float between Q/DQ pairs (research note onnx-timings.md). The tail of each graph (the
detector's head 1x1 convolution, exported as a Gemm, and in-graph box decode; the depth head's
last convolution and softplus, as `depth.fast_tail` writes them) stays in float: it mixes pixel
coordinates with probabilities under one scale otherwise.
With `float_stem`, the first convolution (the one reading the 3-channel image) stays in float too:
for the detector, ONNX Runtime's int8 kernel used its 3 input channels poorly (0.82 ms of ~6 ms,
plus quantising the image), and the float one with its output quantised was faster (interleaved,
2 threads 5.99 -> 5.76 ms, 1 thread 7.83 -> 7.16 ms) and at least as accurate. The depth network
gained nothing that way (8.41 -> 8.28 ms with 2 threads, 11.38 -> 11.47 ms with 1), so it keeps it int8.
With uint8 activations, `channels_last_upsample` then rewrites the networks' nearest 2x upsamples (see there).
"""
import os

import numpy as np
import onnx
from onnx import helper, numpy_helper
from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType,
                                      quantize_static)
from onnxruntime.quantization.shape_inference import quant_pre_process


class Reader(CalibrationDataReader):
    def __init__(self, name, xs):
        self.it = iter([{name: x[None].astype(np.float32)} for x in xs])

    def get_next(self):
        return next(self.it, None)


def tail_nodes(model_path):
    """Names of the last Conv, MatMul or Gemm (the detector's head convolution, exported channels-last as
    a MatMul, which the pre-processing may fuse with its bias into a Gemm) and every node downstream of it."""
    m = onnx.load(model_path)
    nodes = list(m.graph.node)
    last = [n for n in nodes if n.op_type in ("Conv", "MatMul", "Gemm")][-1]
    tail = {last.name}
    tensors = set(last.output)
    for n in nodes[nodes.index(last) + 1:]:
        if any(i in tensors for i in n.input):
            tail.add(n.name)
            tensors.update(n.output)
    return sorted(tail)


def first_conv(model_path):
    """Name of the first Conv node (the one reading the image)."""
    return next(n.name for n in onnx.load(model_path).graph.node if n.op_type == "Conv")


def _attr(node, name, default):
    a = next((a for a in node.attribute if a.name == name), None)
    v = default if a is None else helper.get_attribute_value(a)
    return v.decode() if isinstance(v, bytes) else v


def channels_last_upsample(path):
    """Rewrites each quantised nearest 2x upsample (PyTorch's F.interpolate(scale_factor=2, mode="nearest"),
    which quantize_static leaves as DequantizeLinear -> Resize -> QuantizeLinear with one scale and zero
    point) as copies of the uint8 tensor in channels-last order: Transpose to NHWC, Concat each pixel with
    itself, then each row with itself, Transpose back. Same bytes out, so the network's output does not change.

    Why: ONNX Runtime runs the int8 convolutions channels-last and drops the Q/DQ pair around a Resize, so the
    Resize gets NHWC scales [1, 2, 2, 1], which miss its 2x fast path (NCHW only) and take the per-element
    loop: 0.34 ms for the detector's stride-4 upsample, 1.0 ms for the depth decoder's last one, 2 threads.
    Its layout pass cancels these Transposes against the ones it puts around its NHWC convolutions, and the
    two Concats are row copies (0.05 ms for the detector's largest). Only for uint8 activations: with int8
    ones ONNX Runtime runs the convolutions in float (NCHW), so the Transposes would stay.
    Returns how many upsamples were rewritten; a Resize of any other kind is left alone."""
    m = onnx.load(path)
    g = m.graph
    shapes = {v.name: [d.dim_value if d.HasField("dim_value") else 0 for d in v.type.tensor_type.shape.dim]
              for v in onnx.shape_inference.infer_shapes(m).graph.value_info}
    producer = {o: n for n in g.node for o in n.output}
    consumers = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    inits = {t.name: numpy_helper.to_array(t) for t in g.initializer}

    def same_param(a, b):
        return a == b or (a in inits and b in inits and np.array_equal(inits[a], inits[b]))

    rewritten, drop = 0, set()
    for node in list(g.node):
        if node.op_type != "Resize" or node.input[0] not in producer or len(consumers.get(node.output[0], [])) != 1:
            continue
        dq, q = producer[node.input[0]], consumers[node.output[0]][0]
        shape_in, shape_out = shapes.get(node.input[0], []), shapes.get(node.output[0], [])
        if (dq.op_type != "DequantizeLinear" or q.op_type != "QuantizeLinear" or len(dq.input) < 3
                or len(q.input) < 3 or not all(same_param(a, b) for a, b in zip(dq.input[1:3], q.input[1:3]))
                or _attr(node, "mode", "nearest") != "nearest"
                or _attr(node, "coordinate_transformation_mode", "half_pixel") != "asymmetric"
                or _attr(node, "nearest_mode", "round_prefer_floor") != "floor"
                or len(shape_in) != 4 or 0 in shape_in
                or shape_out != [shape_in[0], shape_in[1], 2 * shape_in[2], 2 * shape_in[3]]):
            continue
        batch, c, h, w = shape_in
        p = node.name.strip("/").replace("/", "_") or f"upsample{rewritten}"

        def dims(name, values):
            g.initializer.append(numpy_helper.from_array(np.array(values, dtype=np.int64), f"{p}_{name}"))
            return f"{p}_{name}"

        chain = [helper.make_node("Transpose", [dq.input[0]], [f"{p}_nhwc"], perm=[0, 2, 3, 1]),
                 helper.make_node("Concat", [f"{p}_nhwc", f"{p}_nhwc"], [f"{p}_cols"], axis=3),
                 helper.make_node("Reshape", [f"{p}_cols", dims("row_shape", [batch, h, 1, 2 * w * c])], [f"{p}_row"]),
                 helper.make_node("Concat", [f"{p}_row", f"{p}_row"], [f"{p}_rows"], axis=2),
                 helper.make_node("Reshape", [f"{p}_rows", dims("nhwc_shape", [batch, 2 * h, 2 * w, c])], [f"{p}_up"]),
                 helper.make_node("Transpose", [f"{p}_up"], [q.output[0]], perm=[0, 3, 1, 2])]
        at = list(g.node).index(node)
        for k, new in enumerate(chain):
            new.name = f"{p}_{new.op_type.lower()}{k}"
            g.node.insert(at + k, new)
        drop.update({id(node), id(q)} | ({id(dq)} if len(consumers[dq.output[0]]) == 1 else set()))
        rewritten += 1
    if rewritten:
        kept = [n for n in g.node if id(n) not in drop]
        del g.node[:]
        g.node.extend(kept)
        used = {i for n in g.node for i in n.input}
        unused = [t for t in g.initializer if t.name not in used]
        for t in unused:
            g.initializer.remove(t)
        onnx.checker.check_model(m)
        onnx.save(m, path)
    return rewritten


def quantize(fp32, out, calib, input_name, act=QuantType.QUInt8, float_stem=False, upsample_rewrite=True):
    """Writes the int8 QDQ file `out` from `fp32`, calibrated on `calib` (CHW float frames); returns how many
    upsamples `channels_last_upsample` rewrote in it (0 for int8 activations or upsample_rewrite=False)."""
    pre = out + ".pre.onnx"
    quant_pre_process(fp32, pre, skip_symbolic_shape=True)
    exclude = tail_nodes(pre)
    if float_stem:
        exclude = sorted(set(exclude) | {first_conv(pre)})
    quantize_static(pre, out, Reader(input_name, calib), quant_format=QuantFormat.QDQ, activation_type=act,
                    weight_type=QuantType.QInt8, per_channel=True, calibrate_method=CalibrationMethod.MinMax,
                    nodes_to_exclude=exclude)
    os.remove(pre)
    return channels_last_upsample(out) if upsample_rewrite and act == QuantType.QUInt8 else 0
