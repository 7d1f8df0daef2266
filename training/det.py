"""A small one-class fish detector with the Ultralytics YOLO output layout.

Architecture: a plain 3x3-conv backbone (strides 2-32, ReLU: fuses and quantises well in ONNX
Runtime) with a top-down FPN to one stride-4 head (CenterNet-style: centre heatmap, sub-cell
offset, log size). With sub=2 the head's last 1x1 convolution predicts 2x2 sub-cells per stride-4
cell (pixel shuffle), so heat map and boxes come out at stride 2. The box decode is inside the
graph, so the ONNX output is exactly the YOLO export layout `[1, 5, N]`: cx, cy, w, h in input
pixels, then the sigmoided fish score, one column per output cell (N = H/s * W/s at output stride
s; non-peak cells score 0). fme's Rust decoder and NMS read it like any YOLO11 export.
"""
import math
import os
import time

import cv2
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

STRIDE = 4  # stride of the head's features; the output stride is STRIDE // sub
# Smallest heat-map Gaussian sigma, in input pixels (0.6 stride-4 cells, as before sub-cells).
SIGMA_MIN_PX = 2.4


def conv(cin, cout, s=1, k=3, relu=True):
    layers = [nn.Conv2d(cin, cout, k, s, k // 2, bias=False), nn.BatchNorm2d(cout)]
    return nn.Sequential(*layers, nn.ReLU(inplace=True)) if relu else nn.Sequential(*layers)


def sep_conv(cin, cout, relu=True):
    """A depthwise-separable 3x3 convolution (MobileNet): depthwise 3x3, then pointwise 1x1, each with
    its BatchNorm. In int8 ONNX Runtime runs the two in a third (stride 8) to a half (stride 4) of a
    full 3x3 convolution's time at these widths (docs/lab-notes/2026-12-detector.md "Depthwise-separable detector")."""
    layers = [nn.Conv2d(cin, cin, 3, 1, 1, groups=cin, bias=False), nn.BatchNorm2d(cin), nn.ReLU(inplace=True),
              nn.Conv2d(cin, cout, 1, bias=False), nn.BatchNorm2d(cout)]
    return nn.Sequential(*layers, nn.ReLU(inplace=True)) if relu else nn.Sequential(*layers)


def conv3(cin, cout, sep, relu=True):
    """A stride-1 3x3 convolution with BatchNorm [and ReLU]: full, or depthwise-separable with sep."""
    return sep_conv(cin, cout, relu) if sep else conv(cin, cout, relu=relu)


class Block(nn.Module):
    def __init__(self, c, sep=False):
        super().__init__()
        self.a = conv3(c, c, sep)
        self.b = conv3(c, c, sep, relu=False)  # no ReLU before the residual sum

    def forward(self, x):
        return F.relu(x + self.b(self.a(x)))


class FishDet(nn.Module):
    # sub=1 is the original stride-4 head; train.py (and so train.sh) defaults to sub=2.
    # s8_blocks and head_conv size the two most expensive parts of the int8 graph (ORT profile, 2 threads:
    # each stride-8 3x3 convolution ~0.30 ms, each stride-4 one ~0.35 ms); see docs/lab-notes/2026-12-detector.md "A slimmer detector".
    # sep names the parts (SEP_PARTS) whose stride-1 3x3 convolutions are depthwise-separable; the strided
    # ones stay full.
    def __init__(self, w=(16, 32, 64, 96, 128), fpn=64, head=32, sub=1, s8_blocks=2, head_conv=True, sep=()):
        super().__init__()
        assert STRIDE % sub == 0, f"sub must divide {STRIDE}, got {sub}"
        self.sub = sub
        self.stride = STRIDE // sub
        self.stem = conv(3, w[0], 2)
        assert set(sep) <= set(SEP_PARTS), f"sep parts are {SEP_PARTS}, got {sep}"
        self.s4 = nn.Sequential(conv(w[0], w[1], 2), Block(w[1], "s4" in sep))
        self.s8 = nn.Sequential(conv(w[1], w[2], 2), *[Block(w[2], "s8" in sep) for _ in range(s8_blocks)])
        self.s16 = nn.Sequential(conv(w[2], w[3], 2), Block(w[3], "s16" in sep), Block(w[3], "s16" in sep))
        self.s32 = nn.Sequential(conv(w[3], w[4], 2), Block(w[4], "s32" in sep))
        self.add_neck((w[1], w[2], w[3], w[4]), fpn, head, sub, head_conv, sep)

    def add_neck(self, chans, fpn, head, sub, head_conv, sep):
        """The top-down FPN (stride 32 -> 16 -> 8 -> 4) and the head on backbone taps of `chans`
        channels at strides 4, 8, 16, 32."""
        c4, c8, c16, c32 = chans
        self.l32 = conv(c32, fpn, k=1)
        self.l16 = conv(c16, fpn, k=1)
        self.l8 = conv(c8, fpn, k=1)
        self.l4 = conv(c4, head, k=1)
        self.m16 = conv3(fpn, fpn, "m16" in sep)
        self.m8 = conv3(fpn, fpn, "m8" in sep)
        self.r4 = conv(fpn, head, k=1)
        self.m4 = conv3(head, head, "m4" in sep)
        self.h = conv3(head, head, "h" in sep) if head_conv else nn.Identity()
        self.out = nn.Conv2d(head, 5 * sub * sub, 1)
        # pixel_shuffle takes output channel c from input channels c*sub^2 .. (c+1)*sub^2 - 1.
        nn.init.constant_(self.out.bias[0:sub * sub], -4.6)  # score prior 0.01
        self.export_decode = False

    def features(self, x):
        """The head's activation before its last 1x1 convolution: [B, head, H/4, W/4]."""
        c4 = self.s4(self.stem(x))
        c8 = self.s8(c4)
        c16 = self.s16(c8)
        return self.top_down(c4, c8, c16, self.s32(c16))

    def top_down(self, c4, c8, c16, c32):
        """The neck on the backbone's taps: the head's activation before its last 1x1 convolution."""
        p16 = self.m16(self.l16(c16) + F.interpolate(self.l32(c32), scale_factor=2.0, mode="nearest"))
        p8 = self.m8(self.l8(c8) + F.interpolate(p16, scale_factor=2.0, mode="nearest"))
        p4 = self.m4(self.l4(c4) + F.interpolate(self.r4(p8), scale_factor=2.0, mode="nearest"))
        return self.h(p4)

    def head_out(self, x):
        """The head's last 1x1 convolution: [B, 5*sub^2, H/4, W/4]."""
        return self.out(self.features(x))

    def raw(self, x):
        o = self.head_out(x)
        if self.sub > 1:
            o = F.pixel_shuffle(o, self.sub)
        return o  # [B,5,H/s,W/s]: heat, ox, oy, lw, lh

    def forward(self, x):
        if not self.export_decode:
            return self.raw(x)
        return decode_nhwc(self.features(x), self.out.weight, self.out.bias, self.sub)


# Named layouts (train.py --det-arch): "full" is the bundled one; "slim" drops one stride-8 residual
# block and the stride-4 head convolution (int8 -19% with random weights; docs/lab-notes/2026-12-detector.md "A slimmer detector"),
# "no_head_conv" only the latter (-9%); "s8_48" runs stride 8 and the FPN at 48 channels (-17%; train.sh's
# layout, docs/lab-notes/2026-12-detector.md "Narrower at stride 8"), "lean" both that and no head convolution (-23%); "sep" makes every
# stride-1 3x3 convolution depthwise-separable (-28% with 2 threads, -42% with 1), "sep48" only those at
# strides 4 and 8 (-20%, -30%), "s8_48_sep4" s8_48 with those at stride 4 separable (-23%, -24%; docs/lab-notes/2026-12-detector.md
# "Depthwise-separable detector").
_S8_48 = {"w": (16, 32, 48, 96, 128), "fpn": 48}
# The parts with stride-1 3x3 convolutions: backbone stages, FPN merges, head.
SEP_PARTS = ("s4", "s8", "s16", "s32", "m4", "m8", "m16", "h")
ARCHS = {"full": {}, "slim": {"s8_blocks": 1, "head_conv": False}, "no_head_conv": {"head_conv": False},
         "s8_48": _S8_48, "lean": {**_S8_48, "head_conv": False},
         "sep": {"sep": SEP_PARTS}, "sep48": {"sep": ("s4", "s8", "m4", "m8", "h")},
         "s8_48_sep4": {**_S8_48, "sep": ("s4", "m4", "h")}}



# --- The pretrained layout (`--arch mnv2`): a MobileNetV2 body with ImageNet-style pretraining -------------
# The body is the feature extractor of MediaPipe's SSD-MobileNetV2 (Open Images V4; Apache-2.0, npm
# @mediapipe/objectron: training/pretrained.py fetches, converts, maps and checks it), with TF's
# conventions kept so the pretrained features are reproduced exactly: input in [-1, 1] (done in the graph:
# fme feeds 0..1), TF "SAME" padding on the strided convolutions (zero pad 0 before, 1 after, on even
# sizes), ReLU6, and batch-norm folded into the convolutions (identity BatchNorms that carry the bias,
# eps 0; they stay in eval mode while training, their bias trainable). The FPN neck and the head are
# FishDet's, so the output layout, stride and decode are the same as every other layout's.


def tf_same_pad(size, k, s):
    """TF "SAME" padding (before, after) of one dimension."""
    out = -(-size // s)
    total = max((out - 1) * s + k - size, 0)
    return total // 2, total - total // 2


class TFConv(nn.Module):
    """Convolution, batch-norm (the folded TF one after `load_folded`) and ReLU6 (unless `act` is False).
    Padding at stride 1: symmetric k//2, as TF's SAME. At stride 2 (`pad`): "tf", an explicit Pad of TF
    SAME's (0, 1) on even sizes (exact, but in int8 ONNX Runtime runs the Pad in float between a
    DequantizeLinear and a QuantizeLinear: ~40 % of the body's time); "k4", the same numbers without a Pad
    op: a (k+1)x(k+1) kernel whose first row and column are zero, symmetric padding 1 (on even sizes
    output i then reads input rows 2i .. 2i+2, as TF SAME; exact); "sym", PyTorch's symmetric padding
    (the pretrained features shifted by one pixel at each strided layer)."""

    def __init__(self, cin, cout, k=1, s=1, groups=1, act=True, pad="tf"):
        super().__init__()
        self.pad = pad if s > 1 else "sym"
        kk = k + 1 if self.pad == "k4" else k
        p = 0 if self.pad == "tf" else k // 2
        self.conv = nn.Conv2d(cin, cout, kk, s, p, groups=groups, bias=False)
        self.k = k
        self.bn = nn.BatchNorm2d(cout)
        self.act = act

    def load_folded(self, w, b):
        if self.pad == "k4":
            self.conv.weight.data.zero_()
            self.conv.weight.data[:, :, 1:, 1:] = w
        else:
            self.conv.weight.data.copy_(w)
        self.bn.eps = 0.0
        self.bn.running_mean.zero_()
        self.bn.running_var.fill_(1.0)
        self.bn.weight.data.fill_(1.0)
        self.bn.bias.data.copy_(b)

    def forward(self, x):
        s, k = self.conv.stride[0], self.k
        if self.pad == "tf":
            ph, pw = tf_same_pad(x.shape[-2], k, s), tf_same_pad(x.shape[-1], k, s)
            x = F.pad(x, (pw[0], pw[1], ph[0], ph[1]))
        x = self.bn(self.conv(x))
        return F.relu6(x) if self.act else x


class InvertedResidual(nn.Module):
    def __init__(self, cin, cout, s, t, pad="tf"):
        super().__init__()
        mid = cin * t
        self.expand = TFConv(cin, mid) if t != 1 else None
        self.dw = TFConv(mid, mid, 3, s, groups=mid, pad=pad)
        self.project = TFConv(mid, cout, act=False)
        self.res = s == 1 and cin == cout

    def forward(self, x):
        y = self.project(self.dw(self.expand(x) if self.expand is not None else x))
        return x + y if self.res else y


class MobileNetV2Body(nn.Module):
    """MobileNetV2 1.0 without its last 1x1 convolution (TF's `Conv_1`): stem and 17 blocks (TF
    `expanded_conv` .. `expanded_conv_16`). Input in [-1, 1]. Returns the outputs of blocks TAPS: strides
    4, 8, 16 and 32, 24 / 32 / 96 / 320 channels."""
    # (expansion t, channels c, repeats n, first stride s), as in the paper and TF-slim.
    CFG = ((1, 16, 1, 1), (6, 24, 2, 2), (6, 32, 3, 2), (6, 64, 4, 2), (6, 96, 3, 1), (6, 160, 3, 2), (6, 320, 1, 1))
    TAPS = (2, 5, 12, 16)
    CHANNELS = (24, 32, 96, 320)

    def __init__(self, pad="tf"):
        super().__init__()
        self.stem = TFConv(3, 32, 3, 2, pad=pad)
        blocks, cin = [], 32
        for t, c, n, s in self.CFG:
            for i in range(n):
                blocks.append(InvertedResidual(cin, c, s if i == 0 else 1, t, pad))
                cin = c
        self.blocks = nn.ModuleList(blocks)

    def forward(self, x):
        x = self.stem(x)
        outs = []
        for i, b in enumerate(self.blocks):
            x = b(x)
            if i in self.TAPS:
                outs.append(x)
        return outs


def load_body(body, sd):
    """Loads a MobileNetV2Body state dict saved with pad "tf" (pretrained.py) into `body`, whatever its
    `pad` (TFConv.load_folded places 3x3 kernels into "k4"'s 4x4 ones)."""
    for name, mod in body.named_modules():
        if isinstance(mod, TFConv):
            mod.load_folded(sd[f"{name}.conv.weight"], sd[f"{name}.bn.bias"])


class MNV2Det(FishDet):
    """FishDet's neck (stride 32 -> 16 -> 8 -> 4 top-down FPN, fpn channels) and head on the pretrained
    MobileNetV2 body; same output layout (stride 4, `sub` sub-cells) and exported decode. The body's
    batch-norms stay in eval mode (`train`): they are TF's folded ones, not statistics to re-estimate."""

    def __init__(self, fpn=64, head=32, sub=1, head_conv=True, sep=(), weights=None, pad="k4"):
        nn.Module.__init__(self)
        assert STRIDE % sub == 0, f"sub must divide {STRIDE}, got {sub}"
        self.sub = sub
        self.stride = STRIDE // sub
        self.body = MobileNetV2Body(pad)
        if weights:
            load_body(self.body, torch.load(weights, map_location="cpu")["state_dict"])
        self.add_neck(MobileNetV2Body.CHANNELS, fpn, head, sub, head_conv, sep)

    def train(self, mode=True):
        super().train(mode)
        for m in self.body.modules():
            if isinstance(m, nn.BatchNorm2d):
                m.eval()
        return self

    def features(self, x):
        return self.top_down(*self.body(x * 2.0 - 1.0))


# Layouts with a pretrained body (train_real.py --arch): kept apart from ARCHS, whose layouts
# check_export.py and cards.py know. "mnv2_sep": the neck's stride-4 and stride-8 3x3 convolutions
# depthwise-separable (cheaper).
PRETRAINED_ARCHS = {"mnv2": {}, "mnv2_sep": {"sep": ("m4", "m8", "h")}, "mnv2_tfpad": {"pad": "tf"},
                    "mnv2_sym": {"pad": "sym"}}


def build(arch, sub, weights=None):
    """A fresh detector of layout `arch` (ARCHS or PRETRAINED_ARCHS; the latter loads `weights`,
    default training/pretrained.py's file)."""
    if arch in PRETRAINED_ARCHS:
        if weights is None:
            import pretrained
            weights = pretrained.weights_path()
        if not os.path.exists(weights):
            raise SystemExit(f"{weights}: no pretrained weights; run `python training/pretrained.py` first")
        return MNV2Det(sub=sub, weights=weights, **PRETRAINED_ARCHS[arch])
    return FishDet(sub=sub, **ARCHS[arch])

def decode(o, sub):
    """The box decode and peak extraction, from the head's output [B, 5*sub^2, gh, gw] (stride-4
    cells; channel c*sub^2 + a*sub + b is channel c of sub-cell row a, column b, as pixel_shuffle
    reads it) to the YOLO layout [B, 5, sub^2*gh*gw]. Columns are ordered by sub-cell, then cell
    (fme's decoder does not care about column order). The reference form: the exported graph
    computes the same with `decode_nhwc` (checked bit for bit by check_export.py). The boxes are
    decoded in the stride-4 layout; only the heat map is shuffled to stride STRIDE/sub for the 3x3
    peak test and back (shuffling all five channels with DepthToSpace had cost 0.24 ms of ~6 ms)."""
    b, _, gh, gw = o.shape
    st = STRIDE // sub
    r = o.reshape(b, 5, sub * sub, gh, gw)
    # Output-grid coordinates of every sub-cell, in output-stride units: constants in the graph.
    k = torch.arange(sub * sub, dtype=o.dtype)
    gy, gx = torch.meshgrid(torch.arange(gh, dtype=o.dtype), torch.arange(gw, dtype=o.dtype), indexing="ij")
    xy = torch.stack([gx[None] * sub + (k % sub)[:, None, None], gy[None] * sub + (k // sub)[:, None, None]])
    cxy = (xy[None] + 0.5 + r[:, 1:3]) * st
    wh = torch.exp(r[:, 3:5].clamp(-4.0, 6.0)) * st
    # CenterNet peak extraction: only local maxima of the heatmap (3x3 output cells) keep their
    # score, so neighbouring cells do not report the same fish; fme's NMS then only has real overlaps.
    hm = torch.sigmoid(r[:, 0])  # [B, sub^2, gh, gw]
    hm_out = F.pixel_shuffle(hm, sub) if sub > 1 else hm
    peak = (F.max_pool2d(hm_out, 3, 1, 1) == hm_out).to(hm.dtype)
    if sub > 1:
        peak = F.pixel_unshuffle(peak, sub)
    s = (hm * peak)[:, None]
    return torch.cat([cxy, wh, s], 1).reshape(b, 5, sub * sub * gh * gw)


def decode_nhwc(y, weight, bias, sub):
    """The exported graph's tail: the same numbers, in the same column order, as
    `decode(out(y), sub)` for the head's last 1x1 convolution (`weight`, `bias`) and the activation
    `y` [1, C, gh, gw] before it, but shaped for ONNX Runtime. Its int8 convolutions run
    channels-last, so `y` is read channels-last (the permute cancels the layout transpose ONNX
    Runtime puts after them) and the convolution is one float Gemm that writes its output
    component-major ([5*sub^2, gh*gw], what the output layout needs) instead of a float Conv in
    ONNX Runtime's blocked layout (reorder in, convolve, reorder out). The 3x3 peak test on the
    stride-STRIDE/sub map works on the sub-cell planes (`peak_max`) instead of shuffling the heat
    map there and back (DepthToSpace and a 5-D transpose were kernels of their own)."""
    b, c, gh, gw = y.shape
    assert b == 1, "the exported graph takes one frame"
    st = STRIDE // sub
    k2 = sub * sub
    o = torch.addmm(bias[:, None], weight[:, :, 0, 0], y.permute(0, 2, 3, 1).reshape(gh * gw, c).t())
    # Row c*sub^2 + a*sub + b is channel c of sub-cell row a, column b, as pixel_shuffle reads it.
    heat, ox, oy, lw, lh = o.reshape(5, k2, gh, gw).unbind(0)
    k = torch.arange(k2, dtype=y.dtype)[:, None, None]
    gy, gx = torch.meshgrid(torch.arange(gh, dtype=y.dtype), torch.arange(gw, dtype=y.dtype), indexing="ij")
    cx = (gx * sub + (k % sub) + 0.5 + ox) * st
    cy = (gy * sub + (k // sub) + 0.5 + oy) * st
    w = torch.exp(lw.clamp(-4.0, 6.0)) * st
    h = torch.exp(lh.clamp(-4.0, 6.0)) * st
    hm = torch.sigmoid(heat)  # [sub^2, gh, gw]
    peak = (peak_max(hm, sub) == hm).to(y.dtype)
    return torch.stack([v.reshape(k2 * gh * gw) for v in (cx, cy, w, h, hm * peak)])[None]


def peak_max(hm, sub):
    """The 3x3 maximum around every cell of the stride-STRIDE/sub score map (values 0..1),
    computed on its sub-cell planes `hm` [sub^2, gh, gw] (plane a*sub + b holds map rows a, a + sub,
    ...; columns b, b + sub, ...): max_pool2d(pixel_shuffle(hm), 3, 1, 1) without the shuffle. With
    sub=2 the row above a row of phase 0 is the previous cell's phase 1 and the row below it the
    same cell's phase 1; for phase 1, the same cell's phase 0 and the next cell's phase 0. Columns
    likewise."""
    if sub == 1:
        return F.max_pool2d(hm[None], 3, 1, 1)[0]
    assert sub == 2, "peak_max handles sub 1 and 2"
    low = -1.0  # the edge padding: below every score (sigmoid, 0..1), as max_pool2d's -inf padding is

    def prev(x, dim):  # x shifted by one cell along dim (-2 rows, -1 columns): x[i - 1], `low` at 0
        return F.pad(x.narrow(dim, 0, x.shape[dim] - 1), (1, 0) if dim == -1 else (0, 0, 1, 0), value=low)

    def next_(x, dim):  # x[i + 1], `low` at the end
        return F.pad(x.narrow(dim, 1, x.shape[dim] - 1), (0, 1) if dim == -1 else (0, 0, 0, 1), value=low)

    p = hm.reshape(2, 2, *hm.shape[1:])  # [row phase, column phase, gh, gw]
    r0, r1 = p[0], p[1]
    rows = torch.stack([torch.maximum(torch.maximum(r0, r1), prev(r1, -2)),
                        torch.maximum(torch.maximum(r1, r0), next_(r0, -2))])
    c0, c1 = rows[:, 0], rows[:, 1]
    cols = torch.stack([torch.maximum(torch.maximum(c0, c1), prev(c1, -1)),
                        torch.maximum(torch.maximum(c1, c0), next_(c0, -1))], 1)
    return cols.reshape(hm.shape)


def from_onnx(path, sub=2, arch=None):
    """A FishDet holding the weights of an exported fp32 file (`export`, with the head's last 1x1
    convolution as a Conv or as `decode_nhwc`'s Gemm), for re-exporting it with this module's
    current graph tail without training again. The export folded each BatchNorm into its
    convolution; here every BatchNorm becomes the identity plus that bias (eps 0, so exactly).
    `arch` in PRETRAINED_ARCHS: the file is an MNV2Det export of that layout (a second stage of a
    pretrained run starts from it; the body's BatchNorms were already folded ones)."""
    import onnx
    from onnx import numpy_helper

    m = onnx.load(path)
    init = {i.name: numpy_helper.to_array(i) for i in m.graph.initializer}
    def module_name(node):
        # Scope "/s4/s4.1/a/a.0/Conv" is module "s4.1.a.0" (Sequential children carry their parent's
        # name as a prefix); its BatchNorm is the next child, "s4.1.a.1".
        # A scope part named for a plain attribute ("/body/blocks.0/dw/conv/Conv") stays whole.
        scope = node.name.strip("/").split("/")[:-1]
        names = [scope[0]]
        for prev, part in zip(scope, scope[1:]):
            names.append(part[len(prev) + 1:] if part.startswith(prev + ".") else part)
        return ".".join(names)

    # The layout from the module names ("s8.2.*" is the second stride-8 block, "h.*" the head conv), the
    # widths from the output channels of each stage's first convolution and of the FPN's laterals.
    out_ch = {module_name(n): int(init[n.input[1]].shape[0]) for n in m.graph.node
              if n.op_type == "Conv" and n.input[1] in init}
    s8 = {int(k.split(".")[1]) for k in out_ch if k.startswith("s8.")}
    firsts = ["stem.0", "s4.0.0", "s8.0.0", "s16.0.0", "s32.0.0"]
    widths = {}
    if all(k in out_ch for k in firsts + ["l32.0", "l4.0"]):
        widths = {"w": tuple(out_ch[k] for k in firsts), "fpn": out_ch["l32.0"], "head": out_ch["l4.0"]}
    # The parts with depthwise-separable convolutions (`sep`): those with grouped ones ("s4.1.a.0" is in "s4").
    sep = tuple(sorted({module_name(n).split(".")[0] for n in m.graph.node if n.op_type == "Conv"
                        for a in n.attribute if a.name == "group" and a.i > 1}))
    head_conv = any(k.startswith("h.") for k in out_ch)
    if arch in PRETRAINED_ARCHS:
        neck = {k: v for k, v in widths.items() if k != "w"} or {"fpn": out_ch["l32.0"], "head": out_ch["l4.0"]}
        kw = dict(PRETRAINED_ARCHS[arch], sep=tuple(p for p in sep if p != "body"))
        model = MNV2Det(sub=sub, head_conv=head_conv, **neck, **kw)
    else:
        model = FishDet(sub=sub, s8_blocks=max(s8, default=0), head_conv=head_conv, sep=sep, **widths)
    mods = dict(model.named_modules())
    done = set()

    def set_head(w, bias, what):  # the head's 1x1 convolution, [out, in] as a Gemm or [out, in, 1, 1] as a Conv
        want = tuple(model.out.weight.shape)
        if w.shape not in (want, want[:2]):
            raise SystemExit(f"{path}: {what} weights {tuple(w.shape)}, FishDet(sub={sub}) has {want[:2]} "
                             "(trained with another --det-sub?)")
        model.out.weight.data.copy_(torch.from_numpy(w.reshape(want).copy()))
        model.out.bias.data.copy_(torch.from_numpy(bias.reshape(-1).copy()))
        done.add("out")

    for n in m.graph.node:
        if n.op_type == "Gemm" and n.input[0] in init:  # `decode_nhwc`'s head: Gemm(out.weight, y^T, out.bias)
            set_head(init[n.input[0]], init[n.input[2]], "head Gemm")
            continue
        if n.op_type != "Conv":
            continue
        mod_name = module_name(n)
        if mod_name == "out":
            set_head(init[n.input[1]], init[n.input[2]], "head convolution")
            continue
        w, bias = torch.from_numpy(init[n.input[1]].copy()), torch.from_numpy(init[n.input[2]].copy())
        parent, _, idx = mod_name.rpartition(".")
        conv_m = mods.get(mod_name)
        # A Sequential's BatchNorm is the next child ("s4.1.a.1"); a TFConv's is its sibling "bn".
        bn = mods.get(f"{parent}.{int(idx) + 1}") if idx.isdigit() else mods.get(f"{parent}.bn")
        if not isinstance(conv_m, nn.Conv2d) or not isinstance(bn, nn.BatchNorm2d) or conv_m.weight.shape != w.shape:
            raise SystemExit(f"{path}: node {n.name} (weights {tuple(w.shape)}) has no matching convolution in "
                             f"FishDet(sub={sub}) (not a FishDet export?)")
        conv_m.weight.data.copy_(w)
        bn.eps = 0.0
        bn.running_mean.zero_()
        bn.running_var.fill_(1.0)
        bn.weight.data.fill_(1.0)
        bn.bias.data.copy_(bias)
        done.add(mod_name)
    missing = [k for k, v in mods.items() if isinstance(v, nn.Conv2d) and k not in done]
    if missing:
        raise SystemExit(f"{path}: no weights for {missing} (not a FishDet export with sub={sub}?)")
    return model.eval()


def average(paths, arch):
    """One model whose every weight is the mean of those of the fp32 exports `paths` (det.from_onnx
    rebuilds each; they must share a layout). Meaningful only for runs that went on from one common
    stage: their weights then lie in one basin, where the mean is itself a good network."""
    if len(paths) < 2:
        raise ValueError("average: name two or more fp32 exports")
    models = [from_onnx(p, 2, arch) for p in paths]
    states = [m.state_dict() for m in models]
    keys = set(states[0])
    for p, st in zip(paths[1:], states[1:]):
        if set(st) != keys or any(st[k].shape != states[0][k].shape for k in keys):
            raise ValueError(f"average: {p} has another layout than {paths[0]}")
    mean = {k: (sum(st[k].double() for st in states) / len(states)).to(states[0][k].dtype)
            if states[0][k].is_floating_point() else states[0][k] for k in keys}
    models[0].load_state_dict(mean)
    return models[0]


# Regression samples (TTFNet, Liu et al. 2020): besides its centre cell, every cell where a fish's
# heat-map Gaussian is at least REG_GAUSS_MIN regresses that fish's box, weighted by the Gaussian and
# normalised per fish. CenterNet's one sample per fish trains the size head slowly, and training here
# is time-boxed; held-out errors were mostly boxes beside the fish (IoU 0.3-0.5), not missing fish.
REG_GAUSS_MIN = 0.4


def targets(boxes, gh, gw, min_vis, spread=True, stride=STRIDE):
    """CenterNet targets for one image: heat [gh,gw], reg [4,gh,gw] (cell-relative centre offset,
    log width, log height, in units of the output stride `stride`) and the regression weight
    [gh,gw] (each fish's weights sum to about 1; with spread=False only its centre cell, weight 1). Each fish's Gaussian is
    evaluated within 3 sigma of its centre (beyond that it is below 0.012)."""
    heat = np.zeros((gh, gw), np.float32)
    reg = np.zeros((4, gh, gw), np.float32)
    weight = np.zeros((gh, gw), np.float32)
    W, H = gw * stride, gh * stride
    smin = SIGMA_MIN_PX / stride
    fish = []
    for x, y, w, h, vis in boxes:
        x0, y0 = max(x, 0.0), max(y, 0.0)
        x1, y1 = min(x + w, W), min(y + h, H)
        if x1 - x0 < 2 or y1 - y0 < 2 or vis < min_vis:
            continue
        cx, cy, bw, bh = (x0 + x1) / 2 / stride, (y0 + y1) / 2 / stride, (x1 - x0) / stride, (y1 - y0) / stride
        ix, iy = min(int(cx), gw - 1), min(int(cy), gh - 1)
        sx, sy = max(bw / 6, smin), max(bh / 6, smin)
        rx, ry = math.ceil(3 * sx), math.ceil(3 * sy)
        wx0, wx1, wy0, wy1 = max(ix - rx, 0), min(ix + rx + 1, gw), max(iy - ry, 0), min(iy + ry + 1, gh)
        ys, xs = np.mgrid[wy0:wy1, wx0:wx1]
        g = np.exp(-((xs - ix) ** 2) / (2 * sx * sx) - ((ys - iy) ** 2) / (2 * sy * sy)).astype(np.float32)
        heat_win = heat[wy0:wy1, wx0:wx1]
        np.maximum(heat_win, g, out=heat_win)
        heat[iy, ix] = 1.0
        cells = (g >= REG_GAUSS_MIN) if spread else np.zeros(g.shape, bool)
        cells[iy - wy0, ix - wx0] = True
        fish.append((bw * bh, cx, cy, bw, bh, ix, iy, xs[cells], ys[cells], g[cells]))
    # Larger fish first, so a smaller fish in front owns the cells they share; centre cells last,
    # so every fish keeps its own centre sample. Weights are not renormalised after that, so in crowds
    # a large fish's samples sum to less than 1 (as in TTFNet).
    fish.sort(key=lambda f: -f[0])
    for _a, cx, cy, bw, bh, _ix, _iy, cxs, cys, cg in fish:
        reg[0, cys, cxs] = cx - cxs - 0.5
        reg[1, cys, cxs] = cy - cys - 0.5
        reg[2, cys, cxs] = math.log(bw)
        reg[3, cys, cxs] = math.log(bh)
        weight[cys, cxs] = cg / cg.sum()
    for _a, cx, cy, bw, bh, ix, iy, _cxs, _cys, cg in fish:
        reg[:, iy, ix] = (cx - ix - 0.5, cy - iy - 0.5, math.log(bw), math.log(bh))
        weight[iy, ix] = 1.0 / cg.sum()
    return heat, reg, weight


# A fish keeps its box in a training window when at least this share of the part the frame shows is
# inside the window; a fish cut more than that is ignored there (`cut_by_window`, `ignore_mask`).
MIN_INSIDE_WINDOW = 0.7


def cut_by_window(boxes, ox, oy, win_w, win_h, frame_w, frame_h):
    """Which boxes (x, y, w, h, vis; frame pixels) the window [ox, ox + win_w) x [oy, oy + win_h) cuts:
    less than MIN_INSIDE_WINDOW of the box's part inside the frame lies inside the window."""
    def area(x0, y0, x1, y1):
        w = np.minimum(boxes[:, 0] + boxes[:, 2], x1) - np.maximum(boxes[:, 0], x0)
        h = np.minimum(boxes[:, 1] + boxes[:, 3], y1) - np.maximum(boxes[:, 1], y0)
        return np.clip(w, 0, None) * np.clip(h, 0, None)
    in_frame = area(0, 0, frame_w, frame_h)
    return area(ox, oy, ox + win_w, oy + win_h) < MIN_INSIDE_WINDOW * np.maximum(in_frame, 1e-9)


def ignore_mask(boxes, gh, gw, stride):
    """[gh, gw] float mask, 1 on the output cells whose centres lie inside any of `boxes` (x, y, w, h)."""
    m = np.zeros((gh, gw), np.float32)
    for x, y, w, h in boxes[:, :4]:
        c0, c1 = max(math.ceil(x / stride - 0.5), 0), min(math.ceil((x + w) / stride - 0.5), gw)
        r0, r1 = max(math.ceil(y / stride - 0.5), 0), min(math.ceil((y + h) / stride - 0.5), gh)
        m[r0:r1, c0:c1] = 1.0
    return m


def giou(p, t):
    """Generalised IoU of boxes given as (centre x, centre y, log w, log h) relative to one cell."""
    pw, ph = torch.exp(p[:, 2].clamp(-4.0, 6.0)), torch.exp(p[:, 3].clamp(-4.0, 6.0))
    tw, th = torch.exp(t[:, 2]), torch.exp(t[:, 3])
    px0, px1, py0, py1 = p[:, 0] - pw / 2, p[:, 0] + pw / 2, p[:, 1] - ph / 2, p[:, 1] + ph / 2
    tx0, tx1, ty0, ty1 = t[:, 0] - tw / 2, t[:, 0] + tw / 2, t[:, 1] - th / 2, t[:, 1] + th / 2
    inter = (torch.min(px1, tx1) - torch.max(px0, tx0)).clamp(min=0) * (torch.min(py1, ty1) - torch.max(py0, ty0)).clamp(min=0)
    union = pw * ph + tw * th - inter
    hull = (torch.max(px1, tx1) - torch.min(px0, tx0)) * (torch.max(py1, ty1) - torch.min(py0, ty0))
    return inter / union - (hull - union) / hull


def fish_count(heat):
    """The losses' normaliser: ground-truth fish (heat-map peaks of 1) in the batch, at least 1."""
    return heat.eq(1.0).sum().clamp(min=1.0)


def loss_fn(r, heat, reg, weight, giou_weight=1.0, ignore=None):
    """Focal loss on the heat map (CenterNet), L1 on the regression targets and, with giou_weight,
    a GIoU loss on the decoded boxes (the quantity IoU 0.5 matching scores), both weighted per cell.
    `ignore` [B, gh, gw] (1 = ignore): cells that are neither positive nor negative."""
    p = torch.sigmoid(r[:, 0]).clamp(1e-4, 1 - 1e-4)
    pos = heat.eq(1.0).float()
    neg = 1.0 - pos
    if ignore is not None:
        neg = neg * (1.0 - ignore)
    pl = -(torch.log(p) * (1 - p) ** 2 * pos).sum()
    nl = -(torch.log(1 - p) * p ** 2 * (1 - heat) ** 4 * neg).sum()
    npos = fish_count(heat)
    rl = (F.l1_loss(r[:, 1:5], reg, reduction="none").sum(1) * weight).sum() / npos
    loss = (pl + nl) / npos + rl
    cells = weight > 0
    if giou_weight > 0 and bool(cells.any()):
        pr = r[:, 1:5].permute(0, 2, 3, 1)[cells]
        tr = reg.permute(0, 2, 3, 1)[cells]
        loss = loss + giou_weight * ((1.0 - giou(pr, tr)) * weight[cells]).sum() / npos
    return loss


# Distillation (train(teacher=...)): a teacher's heat-map cells at least this confident also teach the
# student their box regression.
KD_REG_MIN = 0.3


def kd_loss(r, t, heat, ignore=None):
    """Knowledge distillation from a teacher's raw output `t` (same layout as the student's `r`, no
    gradient): the binary KL divergence between the two heat maps on every cell (zero where they agree;
    the teacher's soft scores also rank neighbours and look-alikes, which the 0/1 targets do not) plus an
    L1 on the box regression where the teacher scores at least KD_REG_MIN, weighted by that score; both
    normalised by the ground-truth fish in `heat` (`fish_count`), as `loss_fn` is. `ignore` as in `loss_fn`."""
    pt = torch.sigmoid(t[:, 0]).clamp(1e-4, 1 - 1e-4)
    ls, l1s = F.logsigmoid(r[:, 0]), F.logsigmoid(-r[:, 0])
    kl = pt * (torch.log(pt) - ls) + (1 - pt) * (torch.log(1 - pt) - l1s)
    keep = 1.0 - ignore if ignore is not None else 1.0
    w = pt * (pt >= KD_REG_MIN).float() * keep
    rl = (F.l1_loss(r[:, 1:5], t[:, 1:5], reduction="none").sum(1) * w).sum()
    return ((kl * keep).sum() + rl) / fish_count(heat)


def augment(img, boxes, rng, out, color=False):
    """Horizontal flip and mild photometric jitter (the generator already varies water and light) of
    an HxWx3 uint8 image, written as float32 (0..255) into `out`; returns the boxes. Each step is one
    float32 operation, rounded as `img.astype(float32) * gain + bias` was before batches were built
    in place. With `color` (real footage: a handful of cameras and waters), each channel also gets
    its own gain (the water's tint) and one frame in five a blur (focus, motion)."""
    if rng.random() < 0.5:
        img = img[:, ::-1]
        b = boxes.copy()
        b[:, 0] = img.shape[1] - b[:, 0] - b[:, 2]
        boxes = b
    if color:
        if rng.random() < 0.2:
            k = int(rng.choice([3, 5]))
            img = cv2.GaussianBlur(np.ascontiguousarray(img), (k, k), 0)
        gains = rng.uniform(0.75, 1.25, 3).astype(np.float32) * np.float32(rng.uniform(0.8, 1.2))
        np.multiply(img, gains, out=out)
    else:
        np.multiply(img, np.float32(rng.uniform(0.8, 1.2)), out=out)
    np.add(out, np.float32(rng.uniform(-15, 15)), out=out)
    np.clip(out, 0, 255, out=out)
    return boxes


def zoom_in(img, boxes, rng, max_zoom):
    """A random window of 1/s of the frame (s log-uniform in 1..max_zoom) scaled back to the frame:
    fish s times larger, as a camera close to the fish sees them (real tanks and cages show fish
    filling a quarter of the frame, rarer in the training images). Returns the image, the boxes in
    its pixels and which of them the window cuts (to be ignored, as `cut_by_window` says)."""
    h, w = img.shape[:2]
    s = math.exp(rng.uniform(0.0, math.log(max_zoom)))
    ww, wh = w / s, h / s
    return zoom_window(img, boxes, s, rng.uniform(0, w - ww), rng.uniform(0, h - wh))


# Long side, in network pixels, that `zoom_to_fish` gives the chosen fish (log-uniform between them):
# the size band (48 px and more) where the held-out recall fell and which is 3 % of the real boxes.
FISH_ZOOM_LONG = (64.0, 320.0)
# Smallest fish `zoom_to_fish` enlarges (long side, px) and its largest factor: a 10 px fish blown up
# 8 times is a blur, not a fish.
FISH_ZOOM_MIN_LONG = 14.0
FISH_ZOOM_MAX_S = 6.0


def zoom_to_fish(img, boxes, rng, min_vis=0.2):
    """A window around one random visible fish, scaled so that the fish's long side becomes a
    log-uniform draw in FISH_ZOOM_LONG (at most FISH_ZOOM_MAX_S times and 95 % of the frame), the fish
    at a random place inside it. Unlike `zoom_in`'s random window, every draw makes a large fish, the
    size a camera close to the fish sees most. Returns `zoom_in`'s triple, or None where no fish is
    at least FISH_ZOOM_MIN_LONG px long or already as large as the draw."""
    h, w = img.shape[:2]
    if len(boxes) == 0:
        return None
    long_side = np.maximum(boxes[:, 2], boxes[:, 3])
    ok = np.flatnonzero((long_side >= FISH_ZOOM_MIN_LONG) & (boxes[:, 4] >= min_vis))
    if len(ok) == 0:
        return None
    x, y, bw, bh = boxes[int(rng.choice(ok)), :4]
    target = math.exp(rng.uniform(math.log(FISH_ZOOM_LONG[0]), math.log(FISH_ZOOM_LONG[1])))
    s = min(target / max(bw, bh), FISH_ZOOM_MAX_S, 0.95 * w / bw, 0.95 * h / bh)
    if s <= 1.05:
        return None
    ww, wh = w / s, h / s
    # The window holds the whole fish (where the frame allows) at a random offset.
    ox = rng.uniform(max(0.0, min(x + bw - ww, w - ww)), max(0.0, min(x, w - ww)))
    oy = rng.uniform(max(0.0, min(y + bh - wh, h - wh)), max(0.0, min(y, h - wh)))
    return zoom_window(img, boxes, s, ox, oy)


def zoom_window(img, boxes, s, ox, oy):
    """The window of 1/s of the frame at (ox, oy) scaled back to the frame's size: the image, the boxes
    in its pixels and which of them the window cuts (`cut_by_window`)."""
    h, w = img.shape[:2]
    cut = cut_by_window(boxes, ox, oy, w / s, h / s, w, h)
    # warpAffine maps pixel centres (pixel i's centre is i, where a box edge at i is pixel i's left
    # side): the half-pixel term keeps the boxes on the enlarged pixels (2.5 px off at 6x without it).
    m = np.float32([[s, 0, -ox * s + 0.5 * (s - 1)], [0, s, -oy * s + 0.5 * (s - 1)]])
    out = cv2.warpAffine(np.ascontiguousarray(img), m, (w, h), flags=cv2.INTER_LINEAR, borderValue=(114, 114, 114))
    b = boxes.copy()
    b[:, 0] = (b[:, 0] - ox) * s
    b[:, 1] = (b[:, 1] - oy) * s
    b[:, 2:4] *= s
    return out, b, cut


def lr_at(opt, max_lr, step_frac, elapsed, budget):
    """Warm-up then cosine decay over the run, where the run's progress is the larger of the step
    fraction and the elapsed fraction of the time budget, so training always anneals properly and
    ends on time on a busy CPU. Returns the progress (>= 1 means stop)."""
    frac = max(step_frac, elapsed / budget if budget else 0.0)
    f = min(frac, 1.0)
    scale = f / 0.05 if f < 0.05 else 0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * (f - 0.05) / 0.95))
    for g in opt.param_groups:
        g["lr"] = max_lr * max(scale, 0.02) * g.get("lr_mult", 1.0)
    return frac


def use_bf16():
    """Whether training runs the network under bf16 autocast: on CPUs with native bf16 (AMX or
    AVX512-BF16) oneDNN's bf16 convolutions with channels-last tensors made a training step of
    16 frames 3.9x faster here (detector 946 -> 241 ms, depth network 1298 -> 336 ms); where bf16
    would be emulated it is slower, so fp32. FME_BF16=0 or 1 overrides the check."""
    env = os.environ.get("FME_BF16", "auto")
    if env in ("0", "1"):
        return env == "1"
    try:
        with open("/proc/cpuinfo") as f:
            flags = set(f.read().split())
    except OSError:
        return False
    return bool({"amx_bf16", "avx512_bf16"} & flags)


def train_forward(model, x, bf16):
    """One training forward pass of a channels-last model: channels-last input, bf16 autocast when
    `bf16`, output in fp32 (the losses stay in fp32)."""
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        return model(x.contiguous(memory_format=torch.channels_last)).float()


def train(images, boxes, epochs, batch=16, lr=2e-3, seed=0, min_vis=0.2, log=print, time_budget_s=None, spread=True,
          giou_weight=1.0, sub=1, crop=None, arch="full", teacher=None, kd_weight=1.0, zoom=0.0, max_zoom=2.5,
          fish_zoom=0.0, color=None, init=None, body_lr_mult=1.0, freeze_frac=0.0, weights=None, freeze_blocks=0):
    """Returns the trained model and the number of epochs run (the time budget may stop it early).

    `crop` (w, h in input pixels, multiples of 32): each training frame is a random window of that
    size instead of the whole frame (the network is fully convolutional; the export keeps the full
    input size), so a step costs about the window's share of the pixels. Boxes are shifted into the
    window; a fish the window cuts (`cut_by_window`) gets no target and no background loss on its
    cells (`ignore_mask`). Without `crop` nothing changes: the same random draws, the same model.

    `teacher` (a FishDet with the same `sub`, e.g. `from_onnx` of the bundled detector): each batch also
    runs through it, and `kd_weight` times `kd_loss` joins the loss (same random draws as without it).

    `zoom` (real footage): the share of frames that `zoom_in` enlarges up to `max_zoom` times, fish the
    window cuts ignored; `fish_zoom`: a further share that `zoom_to_fish` enlarges around one fish.
    `color`: a bool per image (or None: none) that gets `augment`'s colour jitter.
    `init`: a FishDet to start from (fine-tuning) instead of random weights; `arch` is then its own.

    Pretrained layouts (PRETRAINED_ARCHS, `weights` as `build` takes them): the body learns at
    `body_lr_mult` times the learning rate, and not at all (no gradient) for the first `freeze_frac` of
    the run (the schedule's progress, steps or time), while the fresh neck and head settle; its stem and
    first `freeze_blocks` blocks never train (at strides 2 and 4 their backward pass is most of a step's
    time). They train in fp32 unless FME_BF16=1: bf16 autocast made a step of the mnv2 layout 1.5x slower
    on the AVX512-BF16 machine (depthwise convolutions)."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = (init if init is not None else build(arch, sub, weights)).to(memory_format=torch.channels_last)
    body = getattr(model, "body", None)
    bf16 = use_bf16() if body is None else os.environ.get("FME_BF16") == "1"
    if teacher is not None:
        if teacher.sub != sub:
            raise SystemExit(f"distillation teacher has sub={teacher.sub}, the student sub={sub}")
        teacher = teacher.to(memory_format=torch.channels_last).eval()
        log(f"det: distilling from a teacher ({sum(p.numel() for p in teacher.parameters())} parameters), "
            f"weight {kd_weight}")
    log(f"det: {arch}, {'bf16 autocast' if bf16 else 'fp32'}, channels-last, output stride {model.stride}"
        + (f", random {crop[0]}x{crop[1]} crops" if crop else ""))
    if body is not None:
        body_ids = {id(p) for p in body.parameters()}
        fixed = [body.stem, *body.blocks[:freeze_blocks]]
        for mod in fixed:
            mod.requires_grad_(False)
        fixed_ids = {id(p) for mod in fixed for p in mod.parameters()}
        body_train = [p for p in body.parameters() if id(p) not in fixed_ids]
        opt = torch.optim.AdamW([{"params": [p for p in model.parameters() if id(p) not in body_ids]},
                                 {"params": body_train, "lr_mult": body_lr_mult}], lr=lr, weight_decay=1e-4)
        frozen = freeze_frac > 0
        for p in body_train:
            p.requires_grad_(not frozen)
        log(f"det: pretrained body at {body_lr_mult} x the learning rate, stem and first {freeze_blocks} blocks fixed"
            + (f", the rest frozen for the first {freeze_frac:.0%} of the run" if frozen else ""))
    else:
        frozen = False
        opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    n = len(images)
    steps = epochs * math.ceil(n / batch)
    win_w, win_h = crop if crop else (images.shape[2], images.shape[1])
    gh, gw = win_h // model.stride, win_w // model.stride
    t0 = time.time()
    step = 0
    frac = lr_at(opt, lr, 0.0, 0.0, time_budget_s)
    epochs_run = 0
    for ep in range(epochs):
        epochs_run = ep + 1
        model.train()
        if init is not None:
            # The exported weights have each BatchNorm folded into its convolution (`from_onnx`: identity
            # statistics, eps 0); batch statistics would re-normalise the learnt activations, so a
            # fine-tune keeps them frozen as the affine layers they are.
            for mod in model.modules():
                if isinstance(mod, nn.BatchNorm2d):
                    mod.eval()
        perm = rng.permutation(n)
        tot = 0.0
        for i in range(0, n, batch):
            idx = perm[i:i + batch]
            # The batch is built in place as NHWC, which is the channels-last layout the model runs
            # in: stacking NCHW copies and converting them had cost ~25 ms of a ~460 ms step.
            xs = np.empty((len(idx), win_h, win_w, images.shape[3]), np.float32)
            hs, rs, ms, igs = [], [], [], []
            for k, j in enumerate(idx):
                im, b = images[j], boxes[j]
                zcut = None
                if zoom or fish_zoom:
                    r = rng.random()
                    z = zoom_to_fish(im, b, rng, min_vis) if r < fish_zoom else None
                    if z is None and fish_zoom <= r < fish_zoom + zoom:
                        z = zoom_in(im, b, rng, max_zoom)
                    if z is not None:
                        im, b, zcut = z
                if crop:
                    # Offsets on the head's stride-4 grid; `targets` clips the kept boxes to the window.
                    ox = STRIDE * int(rng.integers(0, (im.shape[1] - win_w) // STRIDE + 1))
                    oy = STRIDE * int(rng.integers(0, (im.shape[0] - win_h) // STRIDE + 1))
                    cut = cut_by_window(b, ox, oy, win_w, win_h, im.shape[1], im.shape[0])
                    im = im[oy:oy + win_h, ox:ox + win_w]
                    b = b.copy()
                    b[:, 0] -= ox
                    b[:, 1] -= oy
                b = augment(im, b, rng, xs[k], color=bool(color[j]) if color is not None else False)
                if crop or zoom or fish_zoom:
                    # A fish the window cuts (not the frame) is neither a fish nor background: as a
                    # positive it taught the detector to box halves of whole fish.
                    drop = np.zeros(len(b), bool)
                    if crop:
                        drop |= cut
                    if zcut is not None:
                        drop |= zcut
                    igs.append(ignore_mask(b[drop], gh, gw, model.stride))
                    b = b[~drop]
                h, r, m = targets(b, gh, gw, min_vis, spread, model.stride)
                hs.append(h)
                rs.append(r)
                ms.append(m)
            xs /= 255.0
            x = torch.from_numpy(xs).permute(0, 3, 1, 2)
            out = train_forward(model, x, bf16)
            heat = torch.from_numpy(np.stack(hs))
            ign = torch.from_numpy(np.stack(igs)) if (crop or zoom or fish_zoom) else None
            loss = loss_fn(out, heat, torch.from_numpy(np.stack(rs)), torch.from_numpy(np.stack(ms)), giou_weight, ign)
            if teacher is not None:
                with torch.no_grad():
                    t_out = train_forward(teacher, x, bf16)
                loss = loss + kd_weight * kd_loss(out, t_out, heat, ign)
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            frac = lr_at(opt, lr, step / steps, time.time() - t0, time_budget_s)
            if frozen and frac >= freeze_frac:
                frozen = False
                for p in body_train:
                    p.requires_grad_(True)
                log(f"det: body unfrozen at step {step} ({time.time() - t0:.0f} s)")
            if frac >= 1.0:
                break
            tot += loss.item() * len(idx)
            if body is not None and step % 50 == 0:
                log(f"det step {step}: loss {loss.item():.3f} ({time.time() - t0:.0f} s)")
        log(f"det epoch {ep + 1}/{epochs} loss {tot / n:.4f} ({time.time() - t0:.0f} s)")
        if frac >= 1.0:
            log(f"det: schedule finished (time budget {time_budget_s} s or steps) in epoch {ep + 1}")
            break
    model.eval()
    return model, epochs_run


def export(model, path, h, w):
    model.to(memory_format=torch.contiguous_format)
    model.eval()
    model.export_decode = True
    torch.onnx.export(model, (torch.zeros(1, 3, h, w),), path, input_names=["images"], output_names=["output0"],
                      opset_version=17, dynamo=False)
    model.export_decode = False
