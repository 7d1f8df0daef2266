"""A small relative-depth network in the MiDaS convention: input [1,3,H,W] RGB normalised with
ImageNet mean/std, output [1,H/2,W/2] relative inverse depth (larger = nearer, positive).

Trained with MiDaS' scale- and shift-invariant loss (Ranftl et al., TPAMI 2020, eq. 5-7): target
disparity 1/z and prediction are each normalised by their median and mean absolute deviation over
valid pixels, then compared with L1 (the 20% largest residuals trimmed), plus a multi-scale
gradient-matching term on the normalised maps.

fme reads the map only at fish and at the reference cubes (the metric fit, paper eq. 1-2), and both
are small: the trimmed L1 throws their large residuals away as outliers and the background's pixels
outnumber them. So a focus term adds the untrimmed L1 over the fish box cores and the cubes'
footprints (`focus_masks`), weight `focus_weight` (FOCUS_WEIGHT by default).
"""
import math
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from det import Block, conv, lr_at, train_forward, use_bf16

MEAN = np.array([0.485, 0.456, 0.406], np.float32)
STD = np.array([0.229, 0.224, 0.225], np.float32)


class FishDepth(nn.Module):
    def __init__(self, w=(16, 32, 48, 64, 96)):
        super().__init__()
        self.e2 = conv(3, w[0], 2)
        self.e4 = nn.Sequential(conv(w[0], w[1], 2), Block(w[1]))
        self.e8 = nn.Sequential(conv(w[1], w[2], 2), Block(w[2]))
        self.e16 = nn.Sequential(conv(w[2], w[3], 2), Block(w[3]))
        self.e32 = nn.Sequential(conv(w[3], w[4], 2), Block(w[4]), Block(w[4]))
        self.d16 = conv(w[4] + w[3], w[3])
        self.d8 = conv(w[3] + w[2], w[2])
        self.d4 = conv(w[2] + w[1], w[1])
        self.d2 = conv(w[1] + w[0], w[0])
        self.out = nn.Conv2d(w[0], 1, 3, 1, 1)

    def forward(self, x):
        f2 = self.e2(x)
        f4 = self.e4(f2)
        f8 = self.e8(f4)
        f16 = self.e16(f8)
        f32 = self.e32(f16)
        up = lambda a: F.interpolate(a, scale_factor=2.0, mode="nearest")  # noqa: E731
        y = self.d16(torch.cat([up(f32), f16], 1))
        y = self.d8(torch.cat([up(y), f8], 1))
        y = self.d4(torch.cat([up(y), f4], 1))
        y = self.d2(torch.cat([up(y), f2], 1))
        return F.softplus(self.out(y))[:, 0]  # [B, H/2, W/2], positive


def normalise(x, m):
    """Per image: (x - median) / mean|x - median| over mask m (MiDaS eq. 6)."""
    out = []
    for xi, mi in zip(x, m):
        v = xi[mi]
        if v.numel() < 10:
            out.append(torch.zeros_like(xi))
            continue
        t = v.median()
        s = (v - t).abs().mean().clamp(min=1e-6)
        out.append((xi - t) / s)
    return torch.stack(out)


FOCUS_WEIGHT = 3.0


def ssi_loss(pred, disp, mask, trim=0.2, alpha=0.5, focus=None, focus_weight=FOCUS_WEIGHT):
    pn = normalise(pred, mask)
    tn = normalise(disp, mask)
    res = (pn - tn).abs()
    loss = 0.0
    if focus is not None:
        fm = focus & mask
        if fm.any():
            loss = focus_weight * res[fm].mean()
    for r, m in zip(res, mask):
        v = r[m]
        if v.numel() < 10:
            continue
        k = int(v.numel() * (1 - trim))
        loss = loss + torch.topk(v, k, largest=False).values.mean()
    loss = loss / len(pred)
    # Gradient matching on 4 scales (MiDaS eq. 8).
    g = 0.0
    d = pn - tn
    mm = mask.float()
    for s in range(4):
        if s:
            d = d[:, ::2, ::2]
            mm = mm[:, ::2, ::2]
        gx = (d[:, :, 1:] - d[:, :, :-1]).abs() * mm[:, :, 1:] * mm[:, :, :-1]
        gy = (d[:, 1:] - d[:, :-1]).abs() * mm[:, 1:] * mm[:, :-1]
        g = g + (gx.sum() + gy.sum()) / mm.sum().clamp(min=1.0)
    return loss + alpha * g


def to_input(img_u8):
    return ((img_u8.astype(np.float32) / 255.0 - MEAN) / STD).transpose(2, 0, 1)


def focus_masks(boxes, refs, out_hw, net_hw, core=0.5):
    """Per frame, a bool map at the network's output size: the central `core` fraction of each
    fish box (network input pixels) and a disc around each reference cube's front face (u, v,
    radius in input pixels)."""
    oh, ow = out_hw
    k = oh / net_hw[0]
    out = np.zeros((len(boxes), oh, ow), bool)

    def fill(m, cx, cy, hw, hh):  # centre and half-sizes in output pixels, at least one pixel
        hw, hh = max(hw, 0.5), max(hh, 0.5)
        m[int(max(np.floor(cy - hh), 0)):int(min(np.ceil(cy + hh), oh)),
          int(max(np.floor(cx - hw), 0)):int(min(np.ceil(cx + hw), ow))] = True

    for m, b, r in zip(out, boxes, refs):
        for x, y, w, h, _vis in b:
            fill(m, (x + w / 2) * k, (y + h / 2) * k, w * k * core / 2, h * k * core / 2)
        for u, v, rad in r:
            fill(m, u * k, v * k, rad * k, rad * k)
    return out


def train(images, depth, epochs, batch=16, lr=2e-3, seed=0, log=print, time_budget_s=None, focus=None,
          focus_weight=FOCUS_WEIGHT, crop=None, crop_until=1.0):
    """Returns the trained model and the number of epochs run (the time budget may stop it early).

    `crop` (w, h in input pixels, multiples of 32): each training frame is a random window of that
    size instead of the whole frame (the network is fully convolutional; the export keeps the full
    input size). Offsets are even, so the half-resolution depth target and focus map crop exactly.
    `crop_until`: the fraction of the run (steps or time budget, as the learning rate) after which
    training goes on with whole frames."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = FishDepth().to(memory_format=torch.channels_last)
    bf16 = use_bf16()
    log(f"depth: {'bf16 autocast' if bf16 else 'fp32'}, channels-last"
        + (f", random {crop[0]}x{crop[1]} crops until {crop_until:.0%} of the run" if crop else ""))
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    n = len(images)
    steps = epochs * math.ceil(n / batch)
    t0 = time.time()
    step = 0
    frac = lr_at(opt, lr, 0.0, 0.0, time_budget_s)
    epochs_run = 0
    for ep in range(epochs):
        epochs_run = ep + 1
        model.train()
        perm = rng.permutation(n)
        tot = 0.0
        for i in range(0, n, batch):
            idx = perm[i:i + batch]
            xs, ds, fs = [], [], []
            for j in idx:
                im, d = images[j], depth[j]
                fj = focus[j] if focus is not None else None
                if crop and frac < crop_until:
                    ox = 2 * int(rng.integers(0, (im.shape[1] - crop[0]) // 2 + 1))
                    oy = 2 * int(rng.integers(0, (im.shape[0] - crop[1]) // 2 + 1))
                    win = (slice(oy // 2, (oy + crop[1]) // 2), slice(ox // 2, (ox + crop[0]) // 2))
                    im, d = im[oy:oy + crop[1], ox:ox + crop[0]], d[win]
                    fj = fj[win] if fj is not None else None
                flip = rng.random() < 0.5
                if flip:
                    im, d = im[:, ::-1], d[:, ::-1]
                if fj is not None:
                    fs.append(np.ascontiguousarray(fj[:, ::-1] if flip else fj))
                im = np.clip(im.astype(np.float32) * rng.uniform(0.85, 1.15) + rng.uniform(-10, 10), 0, 255)
                xs.append(to_input(im))
                ds.append(np.ascontiguousarray(d))
            x = torch.from_numpy(np.stack(xs))
            z = torch.from_numpy(np.stack(ds))
            mask = z > 0.05
            disp = torch.where(mask, 1.0 / z.clamp(min=0.05), torch.zeros_like(z))
            fm = torch.from_numpy(np.stack(fs)) if focus is not None else None
            loss = ssi_loss(train_forward(model, x, bf16), disp, mask, focus=fm, focus_weight=focus_weight)
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            frac = lr_at(opt, lr, step / steps, time.time() - t0, time_budget_s)
            if frac >= 1.0:
                break
            tot += loss.item() * len(idx)
        log(f"depth epoch {ep + 1}/{epochs} loss {tot / n:.4f} ({time.time() - t0:.0f} s)")
        if frac >= 1.0:
            log(f"depth: schedule finished (time budget {time_budget_s} s or steps) in epoch {ep + 1}")
            break
    model.eval()
    return model, epochs_run


def export(model, path, h, w):
    model.to(memory_format=torch.contiguous_format)
    model.eval()
    torch.onnx.export(model, (torch.zeros(1, 3, h, w),), path, input_names=["image"], output_names=["depth"],
                      opset_version=17, dynamo=False)
    fast_tail(path)


def fast_tail(path):
    """Rewrites the exported graph's tail (the `out` convolution and softplus, which stay in float in
    the int8 file) into cheaper ONNX Runtime kernels with the same numbers up to float rounding
    (on 64 frames at most 3.8e-6 apart, where the map's values run up to 9.4):
    - the 3x3 convolution to one channel becomes a depthwise 3x3 convolution, a channel sum and the
      bias. ONNX Runtime runs a float convolution in a blocked layout of 16 channels, so one output
      channel cost as much as 16 (0.74 ms of ~7.7 ms with 2 threads here);
    - Softplus(x) becomes Relu(x) + Log(1 + Exp(-|x|)): ONNX Runtime's Softplus kernel took 0.25 ms
      on the 240x144 map. An identity for every x, and Exp(-|x|) cannot overflow.
    Returns whether the file changed (it is left alone when already rewritten)."""
    import onnx
    from onnx import helper, numpy_helper

    m = onnx.load(path)
    g = m.graph
    nodes = list(g.node)
    sp = [n for n in nodes if n.op_type == "Softplus"]
    convs = [n for n in nodes if n.op_type == "Conv"]
    init = {i.name: i for i in g.initializer}
    if convs and not sp and any(a.name == "group" and a.i > 1 for a in convs[-1].attribute):
        return False
    if len(sp) != 1 or not convs or len(convs[-1].input) < 3 or any(i not in init for i in convs[-1].input[1:]):
        raise SystemExit(f"{path}: not a FishDepth export (expected one Softplus after a 1-channel Conv with bias)")
    conv = convs[-1]
    wt = numpy_helper.to_array(init[conv.input[1]])
    bias = numpy_helper.to_array(init[conv.input[2]])
    if wt.shape[0] != 1:
        raise SystemExit(f"{path}: the last Conv has {wt.shape[0]} output channels, expected 1")
    c = wt.shape[1]
    attrs = {a.name: helper.get_attribute_value(a) for a in conv.attribute}
    g.initializer.extend([numpy_helper.from_array(wt.reshape(c, 1, *wt.shape[2:]), "out_dw.weight"),
                          numpy_helper.from_array(np.array([1], np.int64), "out_sum.axes"),
                          numpy_helper.from_array(bias.reshape(1, 1, 1, 1), "out.bias_4d"),
                          numpy_helper.from_array(np.array(1.0, np.float32), "softplus.one")])
    for name in conv.input[1:]:  # the 1-channel weights and bias are unused now
        g.initializer.remove(init[name])
    x, y = sp[0].input[0], sp[0].output[0]
    tail = [
        helper.make_node("Conv", [conv.input[0], "out_dw.weight"], ["/out/dw"], name="/out/ConvDepthwise", group=c,
                         kernel_shape=attrs["kernel_shape"], pads=attrs["pads"], strides=attrs.get("strides", [1, 1])),
        helper.make_node("ReduceSum", ["/out/dw", "out_sum.axes"], ["/out/sum"], name="/out/ReduceSum", keepdims=1),
        helper.make_node("Add", ["/out/sum", "out.bias_4d"], [conv.output[0]], name="/out/Bias"),
        helper.make_node("Abs", [x], ["/softplus/abs"], name="/softplus/Abs"),
        helper.make_node("Neg", ["/softplus/abs"], ["/softplus/neg"], name="/softplus/Neg"),
        helper.make_node("Exp", ["/softplus/neg"], ["/softplus/exp"], name="/softplus/Exp"),
        helper.make_node("Add", ["/softplus/exp", "softplus.one"], ["/softplus/1p"], name="/softplus/Add1"),
        helper.make_node("Log", ["/softplus/1p"], ["/softplus/log"], name="/softplus/Log"),
        helper.make_node("Relu", [x], ["/softplus/relu"], name="/softplus/Relu"),
        helper.make_node("Add", ["/softplus/relu", "/softplus/log"], [y], name="/softplus/Add"),
    ]
    i = nodes.index(conv)
    rest = [n for n in nodes if n is not conv and n is not sp[0]]
    # Conv's replacement where it stood; softplus's right after the last node producing its input.
    before, after = rest[:i], rest[i:]
    k = max((j + 1 for j, n in enumerate(after) if x in n.output), default=0)
    new_nodes = before + tail[:3] + after[:k] + tail[3:] + after[k:]
    del g.node[:]
    g.node.extend(new_nodes)
    onnx.checker.check_model(m)
    onnx.save(m, path)
    return True


def from_onnx(path):
    """A FishDepth holding the weights of an exported fp32 file (`export`, tail rewritten by `fast_tail`
    or not), to fine-tune the bundled network instead of training it again. The export folded each
    BatchNorm into its convolution, so every BatchNorm becomes the identity plus that bias (eps 0:
    exactly the exported numbers); a fine-tune keeps them frozen (`freeze_norms`)."""
    import onnx
    from onnx import numpy_helper

    m = onnx.load(path)
    init = {i.name: numpy_helper.to_array(i) for i in m.graph.initializer}
    model = FishDepth()
    mods = dict(model.named_modules())
    done = set()
    for n in m.graph.node:
        if n.op_type != "Conv" or n.input[1] not in init:
            continue
        # Scope "/e4/e4.1/a/a.0/Conv" is module "e4.1.a.0"; its BatchNorm is the next child, "e4.1.a.1".
        scope = n.name.strip("/").split("/")[:-1]
        name = ".".join([scope[0]] + [p.split(".")[-1] for p in scope[1:]])
        w = init[n.input[1]]
        if name == "out":  # `fast_tail`'s depthwise [C,1,3,3] + channel sum + "out.bias_4d", or the plain Conv
            bias = init[n.input[2]] if len(n.input) > 2 else init.get("out.bias_4d")
            if bias is None:
                raise SystemExit(f"{path}: the output convolution has no bias (not a FishDepth export?)")
            want = tuple(model.out.weight.shape)
            if w.size != np.prod(want):
                raise SystemExit(f"{path}: output convolution weights {w.shape}, FishDepth has {want}")
            model.out.weight.data.copy_(torch.from_numpy(w.reshape(want).copy()))
            model.out.bias.data.copy_(torch.from_numpy(bias.reshape(-1).copy()))
            done.add("out")
            continue
        parent, _, idx = name.rpartition(".")
        conv_m = mods.get(name)
        bn = mods.get(f"{parent}.{int(idx) + 1}") if idx.isdigit() else None
        if not isinstance(conv_m, nn.Conv2d) or not isinstance(bn, nn.BatchNorm2d) or conv_m.weight.shape != w.shape:
            raise SystemExit(f"{path}: node {n.name} (weights {w.shape}) has no matching convolution in FishDepth")
        conv_m.weight.data.copy_(torch.from_numpy(w.copy()))
        bn.eps = 0.0
        bn.running_mean.zero_()
        bn.running_var.fill_(1.0)
        bn.weight.data.fill_(1.0)
        bn.bias.data.copy_(torch.from_numpy(init[n.input[2]].copy()))
        done.add(name)
    missing = [k for k, v in mods.items() if isinstance(v, nn.Conv2d) and k not in done]
    if missing:
        raise SystemExit(f"{path}: no weights for {missing} (not a FishDepth export?)")
    return model.eval()


def freeze_norms(model):
    """Puts every BatchNorm in eval mode: after `from_onnx` they are the folded affine layers of the
    export, and batch statistics would re-normalise the activations the network learnt."""
    for mod in model.modules():
        if isinstance(mod, nn.BatchNorm2d):
            mod.eval()
