#!/usr/bin/env python3
"""Checks that the exported graphs' rewritten tails compute what the plain forms do (run by
`make -C training smoke`; random weights, no data needed):

- det.peak_max equals max_pool2d on the pixel-shuffled score map, bit for bit (ties included);
- det.decode_nhwc equals det.decode, bit for bit, given the same head output;
- the exported detector (each det.ARCHS layout, and mnv2 with a random body) in ONNX Runtime matches
  the PyTorch module it came from, and so does det.from_onnx's rebuild of it;
- det.average (`train_real.py --average`) gives each weight the files' mean, and a file averaged
  with itself is that file's network;
- depth.fast_tail leaves the depth map as the plain export gives it, up to float rounding, and a
  second call changes nothing;
- quant.channels_last_upsample rewrites every upsample of both int8 networks and changes no output
  bit, and a second call finds nothing left to rewrite.
"""
import os
import shutil
import sys
import tempfile

import numpy as np
import onnx
import onnxruntime as ort
import torch
import torch.nn.functional as F

import depth
import det
import quant


def fail(msg):
    raise SystemExit(f"check_export: {msg}")


def session(path):
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def run_onnx(path, name, x):
    return session(path).run(None, {name: x})[0]


def check_peak_max():
    g = torch.Generator().manual_seed(0)
    for gh, gw in ((72, 120), (5, 7), (1, 1), (2, 3)):
        hm = torch.rand(4, gh, gw, generator=g)
        hm[:, ::2, ::3] = 0.5  # ties between neighbours
        want = F.pixel_unshuffle(F.max_pool2d(F.pixel_shuffle(hm[None], 2), 3, 1, 1), 2)[0]
        if not torch.equal(det.peak_max(hm, 2), want):
            fail(f"peak_max differs from the shuffled max_pool2d on a {gh}x{gw} grid")
        one = hm[:1]
        if not torch.equal(det.peak_max(one, 1), F.max_pool2d(one[None], 3, 1, 1)[0]):
            fail(f"peak_max(sub=1) differs from max_pool2d on a {gh}x{gw} grid")


def check_decode():
    g = torch.Generator().manual_seed(1)
    for sub in (1, 2):
        c = 5 * sub * sub
        o = torch.randn(1, c, 9, 13, generator=g)
        o[:, 0:sub * sub, ::2, ::2] = 0.0  # tied scores
        eye = torch.eye(c)[:, :, None, None]  # the head's 1x1 convolution as the identity: y is its output
        got = det.decode_nhwc(o, eye, torch.zeros(c), sub)
        if not torch.equal(got, det.decode(o, sub)):
            fail(f"decode_nhwc differs from decode (sub={sub})")


def check_det_export(tmp, arch):
    torch.manual_seed(2)
    pretrained = arch in det.PRETRAINED_ARCHS  # random body: the graph, not the weights, is checked
    model = (det.MNV2Det(sub=2, **det.PRETRAINED_ARCHS[arch]) if pretrained else det.FishDet(sub=2, **det.ARCHS[arch])).eval()
    # Distinct BatchNorm affines: with the defaults every folded bias is zero and the export shares them.
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.normal_(0.0, 0.1)
    x = torch.rand(1, 3, 96, 160)
    path = os.path.join(tmp, f"det_{arch}.onnx")
    det.export(model, path, 96, 160)
    model.export_decode = True
    with torch.no_grad():
        want = model(x).numpy()
    checks = [("PyTorch", run_onnx(path, "images", x.numpy())),
              ("det.from_onnx's rebuild", rebuilt(path, x, arch if pretrained else None))]
    for what, got in checks:
        if got.shape != want.shape:
            fail(f"{arch} detector: {what} output {got.shape}, PyTorch {want.shape}")
        box = np.abs(got[0, :4] - want[0, :4]).max()
        same_score = np.mean(np.abs(got[0, 4] - want[0, 4]) < 1e-4)
        if box > 1e-2 or same_score < 0.999:
            fail(f"{arch} detector: the export and {what} differ: boxes up to {box:.3g} px apart, "
                 f"{same_score:.4f} of the scores agree")


def rebuilt(path, x, arch=None):
    """The output of det.from_onnx's module for the exported file (for --reexport and --init)."""
    return output(det.from_onnx(path, 2, arch), x)


def output(model, x):
    model.export_decode = True
    with torch.no_grad():
        return model(x).numpy()


def check_average(tmp):
    """det.average (train_real.py --average): each weight the mean of the files', and a file averaged
    with itself the same network."""
    paths = []
    for seed in (5, 6):
        torch.manual_seed(seed)
        model = det.MNV2Det(sub=2, **det.PRETRAINED_ARCHS["mnv2"]).eval()
        for p in model.parameters():  # the body's folded BatchNorm biases start at zero: give them values
            p.data.add_(0.05 * torch.randn_like(p))
        paths.append(os.path.join(tmp, f"avg_{seed}.onnx"))
        det.export(model, paths[-1], 96, 160)
    a, b = (det.from_onnx(p, 2, "mnv2").state_dict() for p in paths)
    mean = det.average(paths, "mnv2").state_dict()
    off = max((mean[k] - (a[k] + b[k]) / 2).abs().max().item() for k in a if a[k].is_floating_point())
    if off > 1e-6 or not any((a[k] != b[k]).any() for k in a):
        fail(f"det.average: a weight is {off:.3g} off the files' mean (or the two files are alike)")
    x = torch.rand(1, 3, 96, 160)
    if not np.array_equal(output(det.average([paths[0]] * 2, "mnv2"), x), rebuilt(paths[0], x, "mnv2")):
        fail("det.average of a file with itself is not that file's network")
    try:
        det.average(paths[:1], "mnv2")
        fail("det.average took one file")
    except ValueError:
        pass


def check_depth_tail(tmp):
    torch.manual_seed(3)
    model = depth.FishDepth().eval()
    x = torch.randn(1, 3, 96, 160)
    plain = os.path.join(tmp, "depth_plain.onnx")
    torch.onnx.export(model, (x,), plain, input_names=["image"], output_names=["depth"], opset_version=17,
                      dynamo=False)
    fast = os.path.join(tmp, "depth_fast.onnx")
    depth.export(model, fast, 96, 160)
    a, b = run_onnx(plain, "image", x.numpy()), run_onnx(fast, "image", x.numpy())
    err = np.abs(a - b).max() / max(np.abs(a).max(), 1e-6)
    if a.shape != b.shape or err > 1e-5:
        fail(f"depth.fast_tail changed the map: shapes {a.shape} / {b.shape}, largest difference {err:.3g} of the range")
    if depth.fast_tail(fast):
        fail("depth.fast_tail rewrote an already rewritten graph")


def check_upsample(tmp):
    torch.manual_seed(4)
    rng = np.random.default_rng(4)
    calib = [rng.random((3, 96, 160), dtype=np.float32) for _ in range(4)]
    for name, model, export, inp in (("det", det.FishDet(sub=2).eval(), det.export, "images"),
                                     ("depth", depth.FishDepth().eval(), depth.export, "image")):
        fp32 = os.path.join(tmp, f"{name}_up_fp32.onnx")
        export(model, fp32, 96, 160)
        plain, fast = os.path.join(tmp, f"{name}_up_plain.onnx"), os.path.join(tmp, f"{name}_up_fast.onnx")
        quant.quantize(fp32, plain, calib, inp, float_stem=name == "det", upsample_rewrite=False)
        shutil.copyfile(plain, fast)
        resizes = sum(n.op_type == "Resize" for n in onnx.load(plain).graph.node)
        done = quant.channels_last_upsample(fast)
        left = sum(n.op_type == "Resize" for n in onnx.load(fast).graph.node)
        if resizes == 0 or done != resizes or left:
            fail(f"channels_last_upsample rewrote {done} of the {name} network's {resizes} upsamples, {left} left")
        sa, sb = session(plain), session(fast)
        for x in calib:
            a, b = sa.run(None, {inp: x[None]})[0], sb.run(None, {inp: x[None]})[0]
            if not np.array_equal(a, b):
                fail(f"channels_last_upsample changed the int8 {name} output "
                     f"(largest difference {np.abs(a - b).max():.3g})")
        if quant.channels_last_upsample(fast):
            fail(f"channels_last_upsample rewrote the already rewritten {name} network again")


def main():
    check_peak_max()
    check_decode()
    with tempfile.TemporaryDirectory() as tmp:
        for arch in (*det.ARCHS, "mnv2"):
            check_det_export(tmp, arch)
        check_average(tmp)
        check_depth_tail(tmp)
        check_upsample(tmp)
    print("check_export: detector and depth graph tails and upsamples match their plain forms")


if __name__ == "__main__":
    sys.exit(main())
