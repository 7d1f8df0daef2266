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
"""
import os

import numpy as np
import onnx
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


def quantize(fp32, out, calib, input_name, act=QuantType.QUInt8, float_stem=False):
    pre = out + ".pre.onnx"
    quant_pre_process(fp32, pre, skip_symbolic_shape=True)
    exclude = tail_nodes(pre)
    if float_stem:
        exclude = sorted(set(exclude) | {first_conv(pre)})
    quantize_static(pre, out, Reader(input_name, calib), quant_format=QuantFormat.QDQ, activation_type=act,
                    weight_type=QuantType.QInt8, per_channel=True, calibrate_method=CalibrationMethod.MinMax,
                    nodes_to_exclude=exclude)
    os.remove(pre)
    return exclude
