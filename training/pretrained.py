#!/usr/bin/env python3
"""Pretrained MobileNetV2 weights for the detector's `mnv2` layout (det.MNV2Det): the feature extractor
of MediaPipe's SSD-MobileNetV2 (Open Images V4 subset, 24 classes, none of them fish), Apache-2.0,
shipped inside the npm package `@mediapipe/objectron` (pinned below).

    python pretrained.py [--cache DIR]      # writes DIR/mnv2_oidv4.pt and prints the checks

Steps (each skipped when its output is already in DIR, default $FME_PRETRAINED or /tmp/fme-pretrained):
1. `npm pack @mediapipe/objectron@VERSION` into DIR (npm's own registry client).
2. The tflite file is a byte range of the package's Emscripten asset pack
   (`objectron_solution_packed_assets.data`); the range comes from the package's loader JS, and the
   slice's sha256 is checked against the pinned one.
3. tflite -> ONNX with PyPI `tflite2onnx` (pinned in requirements-pretrained.txt, installed into a
   small tool venv layered over VENV: it is needed only here, not while training). The fp16 weights
   (DEQUANTIZE) become float32 initialisers; batch-norm is already folded into each convolution.
4. The 51 convolutions of `FeatureExtractor/MobilenetV2` (stem, 17 inverted-residual blocks; the SSD's
   Conv_1, extra layers and box predictors are left out) are mapped by their TF names onto
   det.MobileNetV2Body (TF "SAME" padding, ReLU6, identity batch-norms carrying the folded biases).
5. Checks, printed: the body's stride 4/8/16/32 features against the ONNX graph's own intermediate
   tensors on one input at 300x300 (max abs diff), with the explicit TF padding; the "k4" form that
   det.MNV2Det trains (TFConv) against that body at 480x288; and the whole SSD on two photographs (ultralytics' bus.jpg
   and zidane.jpg) with [-1, 1] and with [0, 1] input, the top classes, to confirm the input convention.
"""
import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tarfile

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
NPM_PACKAGE = "@mediapipe/objectron"
NPM_VERSION = "0.4.1675468480"
TARBALL = f"mediapipe-objectron-{NPM_VERSION}.tgz"
ASSET_PACK = "package/objectron_solution_packed_assets.data"
LOADER = "package/objectron_solution_packed_assets_loader.js"
TFLITE_NAME = "object_detection_ssd_mobilenetv2_oidv4_fp16.tflite"
TFLITE_SHA256 = "d0a5255bf8c4f5a0"  # prefix; the full digest is printed and kept in DIR/source.json
LABELMAP_NAME = "object_detection_oidv4_labelmap.txt"
WEIGHTS = "mnv2_oidv4.pt"
TF_PREFIX = "FeatureExtractor/MobilenetV2/"


def default_cache():
    return os.environ.get("FME_PRETRAINED", "/tmp/fme-pretrained")


def weights_path(cache=None):
    return os.path.join(cache or default_cache(), WEIGHTS)


def sha256(b):
    return hashlib.sha256(b).hexdigest()


def npm_pack(cache):
    tgz = os.path.join(cache, TARBALL)
    if not os.path.exists(tgz):
        print(f"npm pack {NPM_PACKAGE}@{NPM_VERSION} -> {cache}", flush=True)
        subprocess.run(["npm", "pack", f"{NPM_PACKAGE}@{NPM_VERSION}", "--pack-destination", cache],
                       check=True, stdout=subprocess.DEVNULL)
    return tgz


def extract_tflite(cache):
    """The tflite file and the labelmap, sliced out of the package's asset pack."""
    out = os.path.join(cache, TFLITE_NAME)
    lm_out = os.path.join(cache, LABELMAP_NAME)
    if os.path.exists(out) and os.path.exists(lm_out):
        return out, lm_out
    with tarfile.open(npm_pack(cache)) as t:
        pack = t.extractfile(ASSET_PACK).read()
        loader = t.extractfile(LOADER).read().decode()
        pkg = json.loads(t.extractfile("package/package.json").read())
    ranges = {os.path.basename(m.group(1)): (int(m.group(2)), int(m.group(3))) for m in re.finditer(
        r'"filename":\s*"([^"]+)",\s*"start":\s*(\d+),\s*"end":\s*(\d+)', loader)}
    s, e = ranges[TFLITE_NAME]
    blob = pack[s:e]
    if blob[4:8] != b"TFL3" or not sha256(blob).startswith(TFLITE_SHA256):
        raise SystemExit(f"{TFLITE_NAME}: bytes {s}..{e} of {ASSET_PACK} are not the expected model "
                         f"(sha256 {sha256(blob)})")
    ls, le = ranges[LABELMAP_NAME]
    with open(out, "wb") as f:
        f.write(blob)
    with open(lm_out, "wb") as f:
        f.write(pack[ls:le])
    with open(os.path.join(cache, "source.json"), "w") as f:
        json.dump({"npm": f"{NPM_PACKAGE}@{NPM_VERSION}", "license": pkg.get("license"), "file": ASSET_PACK,
                   "bytes": [s, e], "tflite": TFLITE_NAME, "sha256": sha256(blob)}, f, indent=1)
    print(f"{TFLITE_NAME}: bytes {s}..{e} of {ASSET_PACK}, sha256 {sha256(blob)}, package licence "
          f"{pkg.get('license')}", flush=True)
    return out, lm_out


def tool_python(cache):
    """A venv with tflite2onnx and tflite (requirements-pretrained.txt, no dependencies of their own
    pulled: onnx and numpy come from the training venv, made visible through a .pth file)."""
    venv = os.path.join(cache, "tools-venv")
    py = os.path.join(venv, "bin", "python")
    if not os.path.exists(py):
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
        import site
        site_dir = subprocess.run([py, "-c", "import site; print(site.getsitepackages()[0])"], check=True,
                                  capture_output=True, text=True).stdout.strip()
        with open(os.path.join(site_dir, "zz_training_venv.pth"), "w") as f:
            f.write("\n".join(site.getsitepackages()) + "\n")
        subprocess.run([py, "-m", "pip", "install", "-q", "--no-deps", "-r",
                        os.path.join(HERE, "requirements-pretrained.txt")], check=True)
    return py


def to_onnx(cache):
    onnx_path = os.path.join(cache, "ssd_oidv4.onnx")
    if not os.path.exists(onnx_path):
        tfl, _ = extract_tflite(cache)
        py = tool_python(cache)
        r = subprocess.run([py, "-c", f"import tflite2onnx; tflite2onnx.convert({tfl!r}, {onnx_path!r})"],
                           capture_output=True, text=True)
        lines = (r.stdout + r.stderr).splitlines()
        fp16 = sum("float16 not supported" in l for l in lines)
        print("\n".join(l for l in lines if "float16 not supported" not in l))
        print(f"tflite2onnx: {fp16} warnings 'float16 not supported/tested yet' (the fp16 weights are "
              "dequantised to float32 initialisers; the check below compares against this graph)", flush=True)
        if r.returncode:
            raise SystemExit(f"tflite2onnx failed ({r.returncode})")
    return onnx_path


def tf_convs(onnx_path):
    """{(block, part): (weight, bias, node)} of the feature extractor's convolutions, by TF name:
    block 'Conv' (stem), 'expanded_conv', 'expanded_conv_1' .. '_16'; part 'expand', 'depthwise',
    'project' ('conv' for the stem)."""
    import onnx
    from onnx import numpy_helper
    m = onnx.load(onnx_path)
    init = {i.name: numpy_helper.to_array(i) for i in m.graph.initializer}
    out = {}
    for n in m.graph.node:
        if n.op_type != "Conv":
            continue
        mm = re.match(re.escape(TF_PREFIX) + r"(Conv|expanded_conv(?:_\d+)?)/(expand|depthwise|project|Conv2D)", n.input[1])
        if not mm:
            continue
        part = "conv" if mm.group(2) == "Conv2D" else mm.group(2)
        out[(mm.group(1), part)] = (init[n.input[1]], init[n.input[2]], n)
    return m, out


def tf_block_name(i):
    return "expanded_conv" if i == 0 else f"expanded_conv_{i}"


def map_weights(onnx_path):
    """A det.MobileNetV2Body carrying the SSD's feature-extractor weights, and the ONNX graph."""
    import det
    m, convs = tf_convs(onnx_path)
    body = det.MobileNetV2Body()
    used = 0

    def put(layer, key):
        nonlocal used
        w, b, _ = convs[key]
        if tuple(layer.conv.weight.shape) != w.shape:
            raise SystemExit(f"{key}: weights {w.shape}, body layer {tuple(layer.conv.weight.shape)}")
        layer.load_folded(torch.from_numpy(w.copy()), torch.from_numpy(b.copy()))
        used += 1

    put(body.stem, ("Conv", "conv"))
    for i, blk in enumerate(body.blocks):
        name = tf_block_name(i)
        if blk.expand is not None:
            put(blk.expand, (name, "expand"))
        put(blk.dw, (name, "depthwise"))
        put(blk.project, (name, "project"))
    if used != len(convs):
        raise SystemExit(f"mapped {used} of {len(convs)} feature-extractor convolutions")
    return body.eval(), m, convs, used


def check_features(body, model, convs, tag="tf"):
    """Max |diff| between the body's stride 4/8/16/32 features and the ONNX graph's tensors (the outputs
    of blocks 2, 5, 12 and 16: their residual Add, or the project convolution where the block has none)
    on one input in [-1, 1] at the SSD's 300x300."""
    import onnx
    import onnxruntime as ort
    names = []
    for i in det_taps():
        name = TF_PREFIX + tf_block_name(i)
        add = [n.output[0] for n in model.graph.node if n.op_type == "Add" and n.name == name + "/add"]
        names.append(add[0] if add else convs[(tf_block_name(i), "project")][2].output[0])
    g = onnx.helper.make_graph(model.graph.node, model.graph.name, model.graph.input,
                               [onnx.helper.make_tensor_value_info(nm, onnx.TensorProto.FLOAT, None) for nm in names],
                               model.graph.initializer)
    mm = onnx.helper.make_model(g, opset_imports=model.opset_import, ir_version=model.ir_version)
    sess = ort.InferenceSession(mm.SerializeToString(), providers=["CPUExecutionProvider"])
    x = np.random.default_rng(0).uniform(-1, 1, (1, 3, 300, 300)).astype(np.float32)
    ref = sess.run(None, {sess.get_inputs()[0].name: x})
    with torch.no_grad():
        got = body(torch.from_numpy(x))
    diffs = []
    for stride, a, b in zip((4, 8, 16, 32), got, ref):
        d = float(np.abs(a.numpy() - b).max())
        diffs.append(d)
        print(f"check ({tag} padding): stride {stride:2d} {tuple(a.shape)}: max |body - onnx| {d:.2e} (tensor range "
              f"{float(np.abs(b).max()):.1f})", flush=True)
    return diffs


def det_taps():
    import det
    return det.MobileNetV2Body.TAPS


def check_photos(onnx_path, labelmap):
    """The whole SSD on two photographs: top anchors' classes (sigmoid scores, class 0 is the
    background) with [-1, 1] and with [0, 1] input."""
    import cv2
    import onnxruntime as ort
    labels = [l.strip() for l in open(labelmap) if l.strip()]
    sess = ort.InferenceSession(onnx_path, providers=["CPUExecutionProvider"])
    outs = [o.name for o in sess.get_outputs()]
    # Anchor cells of the six SSD layers (19, 10, 5, 3, 2, 1 cells a side; 3 anchors in the first, 6 after).
    cells = []
    for size, k in ((19, 3), (10, 6), (5, 6), (3, 6), (2, 6), (1, 6)):
        for i in range(size):
            for j in range(size):
                cells += [((j + 0.5) / size, (i + 0.5) / size, size)] * k
    try:
        import ultralytics
        assets = os.path.join(os.path.dirname(ultralytics.__file__), "assets")
    except ImportError:
        print("check: ultralytics not installed, no photographs to check on")
        return {}
    res = {}
    for photo in ("bus.jpg", "zidane.jpg"):
        img = cv2.imread(os.path.join(assets, photo))
        if img is None:
            continue
        rgb = cv2.resize(img, (300, 300))[:, :, ::-1].astype(np.float32).transpose(2, 0, 1)[None] / 255.0
        for tag, x in (("[-1,1]", rgb * 2 - 1), ("[0,1]", rgb)):
            o = dict(zip(outs, sess.run(None, {sess.get_inputs()[0].name: np.ascontiguousarray(x)})))
            cls = [v for k, v in o.items() if v.shape[-1] == len(labels)][0][0]
            p = 1 / (1 + np.exp(-cls[:, 1:]))
            best = p.max(1)
            top = np.argsort(-best)[:8]
            found = [(labels[1 + int(p[a].argmax())], round(float(best[a]), 2),
                      f"({cells[a][0]:.2f},{cells[a][1]:.2f})") for a in top]
            n_over = {labels[1 + c]: int((p[:, c] > 0.5).sum()) for c in range(p.shape[1]) if (p[:, c] > 0.5).any()}
            print(f"check: {photo} {tag}: top anchors {found}; anchors > 0.5 per class {n_over}", flush=True)
            res[f"{photo} {tag}"] = {"top": found, "over_0.5": n_over}
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cache", default=default_cache())
    ap.add_argument("--force", action="store_true", help="map and check again even if the weights exist")
    args = ap.parse_args()
    os.makedirs(args.cache, exist_ok=True)
    out = weights_path(args.cache)
    if os.path.exists(out) and not args.force:
        print(f"{out} exists (--force to redo)")
        return
    onnx_path = to_onnx(args.cache)
    body, model, convs, used = map_weights(onnx_path)
    print(f"mapped {used} convolutions ({sum(p.numel() for p in body.parameters()) / 1e6:.2f} M parameters) of "
          f"{TF_PREFIX} onto det.MobileNetV2Body", flush=True)
    diffs = check_features(body, model, convs)
    import det
    k4 = det.MobileNetV2Body("k4")
    det.load_body(k4, body.state_dict())
    # The k4 form is exact on even sizes only (all of them at 480x288; 300x300 has odd ones): checked
    # against the TF-padded body, just checked against the graph, on one input at the detector's size.
    x = torch.from_numpy(np.random.default_rng(1).uniform(-1, 1, (1, 3, 288, 480)).astype(np.float32))
    with torch.no_grad():
        for stride, a, b in zip((4, 8, 16, 32), k4.eval()(x), body(x)):
            d = float((a - b).abs().max())
            diffs.append(d)
            print(f"check (k4 padding, 480x288): stride {stride:2d} {tuple(a.shape)}: max |k4 body - tf body| "
                  f"{d:.2e} (tensor range {float(b.abs().max()):.1f})", flush=True)
    if max(diffs) > 2e-3:
        raise SystemExit(f"the mapped body does not reproduce the ONNX graph (max diff {max(diffs):.2e})")
    photos = check_photos(onnx_path, os.path.join(args.cache, LABELMAP_NAME))
    torch.save({"state_dict": body.state_dict(), "source": json.load(open(os.path.join(args.cache, "source.json"))),
                "check_max_abs_diff": diffs, "photos": photos}, out)
    print(f"wrote {out}", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    main()
