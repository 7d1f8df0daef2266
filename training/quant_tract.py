"""int8 files for tract (the static binary's backend) in QOperator form, to measure against its fp32 default.

tract fuses QDQ only around element-wise chains, so an ONNX Runtime QDQ file (quant.quantize) runs its
convolutions in float with a quantise/dequantise round trip around each. QOperator QLinearConv maps to
tract's quantised convolution (int8 matrix products with VNNI / SDOT kernels). What tract accepts:
QLinearConv with per-tensor weight scales (per-channel is not honoured everywhere), ReLU folded into the
convolution's output range, and no com.microsoft contrib operators (QLinearAdd, QLinearConcat): the
Adds, Concats and upsamples stay float between DequantizeLinear / QuantizeLinear. The tail (the
detector's head and in-graph decode, the depth head) stays float as in quant.quantize.

  python quant_tract.py FP32.onnx OUT.onnx [--renders DIR] [--frames N]

Calibrates on N frames of the renders (default /tmp/fme-train-data, `make -C training all` or the
real recipe writes them), resized to the network's input, and prints the int8 file's agreement
with the fp32 one on those frames under ONNX Runtime. Time it with `make bench-backends`-style runs
under tract (docs/benchmarks.md#backends says what it measured)."""
import argparse
import collections
import glob
import os

import numpy as np
import onnx
import onnxruntime as ort
from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process
from PIL import Image

import depth
import quant


def frames(renders, n, hw, seed=0):
    seqs = sorted(glob.glob(os.path.join(renders, "*", "*", "img1")))
    if not seqs:
        raise SystemExit(f"quant_tract: no render sequences (*/*/img1) under {renders}")
    rng = np.random.default_rng(seed)
    out = []
    for s in rng.choice(seqs, min(n, len(seqs)), replace=False):
        files = sorted(glob.glob(os.path.join(s, "*.jpg")))
        img = Image.open(files[len(files) // 2]).convert("RGB").resize((hw[1], hw[0]), Image.BILINEAR)
        out.append(np.asarray(img))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("fp32")
    ap.add_argument("out")
    ap.add_argument("--renders", default="/tmp/fme-train-data")
    ap.add_argument("--frames", type=int, default=32)
    a = ap.parse_args()
    m = onnx.load(a.fp32)
    inp = m.graph.input[0]
    hw = [d.dim_value for d in inp.type.tensor_type.shape.dim][2:]
    # The depth network takes ImageNet-normalised input, the detector 0..1 (as the pipeline feeds them).
    is_depth = m.graph.output[0].name == "depth"
    imgs = frames(a.renders, a.frames, hw)
    calib = [depth.to_input(i) if is_depth else i.astype(np.float32).transpose(2, 0, 1) / 255.0 for i in imgs]
    pre = a.out + ".pre.onnx"
    quant_pre_process(a.fp32, pre, skip_symbolic_shape=True)
    quantize_static(pre, a.out, quant.Reader(inp.name, calib), quant_format=QuantFormat.QOperator,
                    activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=False,
                    calibrate_method=CalibrationMethod.MinMax, nodes_to_exclude=quant.tail_nodes(pre),
                    op_types_to_quantize=["Conv", "Relu"])
    os.remove(pre)
    ops = collections.Counter(n.op_type for n in onnx.load(a.out).graph.node)
    print(f"{a.out}: {sum(ops.values())} nodes, {ops['QLinearConv']} QLinearConv, "
          f"{ops['QuantizeLinear']} QuantizeLinear, {ops['DequantizeLinear']} DequantizeLinear")
    f32 = ort.InferenceSession(a.fp32, providers=["CPUExecutionProvider"])
    q8 = ort.InferenceSession(a.out, providers=["CPUExecutionProvider"])
    xs = np.stack(calib[:8])
    ya = np.concatenate([f32.run(None, {inp.name: x[None]})[0].ravel() for x in xs])
    yb = np.concatenate([q8.run(None, {inp.name: x[None]})[0].ravel() for x in xs])
    r = np.corrcoef(ya, yb)[0, 1]
    print(f"agreement with fp32 on {len(xs)} calibration frames (ONNX Runtime): Pearson r {r:.5f}, "
          f"max |diff| {np.abs(ya - yb).max():.4g}")


if __name__ == "__main__":
    main()
