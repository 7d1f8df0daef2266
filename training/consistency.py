"""fme's depth consistency (crates/lab/src/eval/consistency.rs) for training/: per frame, Spearman's rank
correlation between the network's relative inverse depth at each fish (3x3 median of the map at
the box centre) and the box's long side, over boxes inside the frame; the mean over frames with
at least MIN_BOXES such boxes. Within a cohort a nearer fish looks longer, so +1 is a network that
orders every fish as their sizes do.

The real images are fed as fme feeds its depth network: the whole frame resized to the input
(no letterbox, the aspect stretched), so the boxes' centres map to the map by the two scales and
their long sides are measured in source pixels.

Each image becomes (image at the network input, fish [K, 3]): the fish inside the frame as
(centre x, centre y in map pixels, long side in source pixels); the map is half the input.
"""
import os

import cv2
import numpy as np
from PIL import Image

import data
import real

MIN_BOXES = 3


def ranks(v):
    """1-based ranks, ties given their mean rank (as consistency.rs)."""
    order = np.argsort(v, kind="stable")
    r = np.empty(len(v), np.float64)
    sv = np.asarray(v)[order]
    i = 0
    while i < len(v):
        j = i + 1
        while j < len(v) and sv[j] == sv[i]:
            j += 1
        r[order[i:j]] = (i + j + 1) / 2.0
        i = j
    return r


def spearman(x, y):
    """Spearman's rho, None for fewer than MIN_BOXES pairs, a value not finite or a sample all tied."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if len(x) < MIN_BOXES or len(y) != len(x) or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return None
    rx, ry = ranks(x) - (len(x) + 1) / 2, ranks(y) - (len(y) + 1) / 2
    sxx, syy = (rx * rx).sum(), (ry * ry).sum()
    if sxx <= 0 or syy <= 0:
        return None
    return float(np.clip((rx * ry).sum() / np.sqrt(sxx * syy), -1.0, 1.0))


def inside_fish(boxes, src_w, src_h, map_w, map_h):
    """fish [K, 3] of the boxes (x, y, w, h, ... in source pixels) that lie inside the frame: as fme's
    eval, each box is clipped to the frame (dropped under a pixel), then kept only when it does not
    touch the edge (a box the edge cuts has a long side shorter than its fish)."""
    b = np.asarray(boxes, np.float64)
    b = b.reshape(len(b), -1) if len(b) else np.zeros((0, 4))
    x0, y0 = np.maximum(b[:, 0], 0), np.maximum(b[:, 1], 0)
    x1, y1 = np.minimum(b[:, 0] + b[:, 2], src_w), np.minimum(b[:, 1] + b[:, 3], src_h)
    ok = (x1 - x0 >= 1) & (y1 - y0 >= 1) & (x0 > 0) & (y0 > 0) & (x1 < src_w) & (y1 < src_h)
    cx, cy = (x0 + x1) / 2 * map_w / src_w, (y0 + y1) / 2 * map_h / src_h
    return np.stack([cx, cy, np.maximum(x1 - x0, y1 - y0)], 1)[ok].astype(np.float32)


def sample(m, fish, r=1):
    """The map's (2r+1)^2 median at each fish's centre (the map pixel holding it), as fme samples it."""
    h, w = m.shape
    out = []
    for cx, cy, _ in fish:
        x, y = min(int(cx), w - 1), min(int(cy), h - 1)
        out.append(float(np.median(m[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1])))
    return np.array(out)


def score(run, images, fish):
    """(mean rho over images with a correlation, images counted); `run` maps an input image
    [H, W, 3] uint8 to its [h, w] map."""
    rhos = []
    for im, f in zip(images, fish):
        if len(f) < MIN_BOXES:
            continue
        rho = spearman(sample(run(im), f), f[:, 2])
        if rho is not None:
            rhos.append(rho)
    return (float(np.mean(rhos)) if rhos else None), len(rhos)


def onnx_runner(path, threads=2):
    """An ONNX depth file as `score`'s `run` (fme's preprocessing: depth.to_input)."""
    import depth
    import evaluate

    sess = evaluate.session(path, threads)
    name = sess.get_inputs()[0].name
    shape = sess.get_inputs()[0].shape
    if list(shape[2:]) != [data.NET_H, data.NET_W]:
        raise SystemExit(f"{path}: takes {shape[3]}x{shape[2]} input but FME_NET gives {data.NET_W}x{data.NET_H}; "
                         f"run with FME_NET={shape[3]}x{shape[2]}")
    return lambda im: sess.run(None, {name: depth.to_input(im)[None]})[0].reshape(shape[2] // 2, shape[3] // 2)


def image_size(path):
    """(w, h) from the file's header, without decoding it."""
    with Image.open(path) as im:
        return im.size


def load_real_source(folder, source, split, min_boxes, limit=0):
    """One source's split ("train" / "val", real.held_out) as (images, fish), keeping only images with
    at least `min_boxes` fish inside the frame (labels and header read first: most images are skipped
    undecoded). Images are resized to the input as fme does."""
    mw, mh = data.NET_W // 2, data.NET_H // 2
    imgs, fish = [], []
    for img_path, lab_path in real.yolo_items(folder):
        stem = os.path.splitext(os.path.basename(img_path))[0]
        if held_out_split(source, stem) != split:
            continue
        w, h = image_size(img_path)
        f = inside_fish(real.read_yolo_labels(lab_path, w, h), w, h, mw, mh)
        if len(f) < min_boxes:
            continue
        bgr = cv2.imread(img_path, cv2.IMREAD_COLOR)
        if bgr is None:
            raise SystemExit(f"{img_path}: unreadable image")
        imgs.append(cv2.resize(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), (data.NET_W, data.NET_H),
                               interpolation=cv2.INTER_LINEAR))
        fish.append(f)
        if limit and len(imgs) >= limit:
            break
    return real.stacked(imgs), fish


def held_out_split(source, stem):
    return "val" if real.held_out(source, stem) else "train"


def load_real(root, split, min_boxes=MIN_BOXES, limit=0):
    """{source: (images, fish)} over the pool's sources (real.sources: the excluded ones left out)."""
    return {s: load_real_source(os.path.join(root, s), s, split, min_boxes, limit) for s in real.sources(root)}


def load_renders(root, every=5, limit=0):
    """Held-out renders (fme sequences under root, true boxes from gt) as (images, fish). 640x384 renders
    resize to the input without padding, so boxes in input pixels keep their ranks and centres."""
    images, boxes, _, _ = data.load_many(root, every=every, with_depth=False, limit=limit)
    mw, mh = data.NET_W // 2, data.NET_H // 2
    return images, [inside_fish(b, data.NET_W, data.NET_H, mw, mh) for b in boxes]


def score_file(path, sets, log, tag):
    """{set name: {"rho", "images"}} of one ONNX file on each (images, fish) set, logged on one line;
    "real" pools every set but "renders" (a mean over their images: one figure for the real sources)."""
    run = onnx_runner(path)
    out, pooled = {}, [0.0, 0]
    for name, (images, fish) in sets.items():
        rho, n = score(run, images, fish)
        out[name] = {"rho": None if rho is None else round(rho, 4), "images": n}
        if name != "renders" and n:
            pooled[0] += rho * n
            pooled[1] += n
    out["real"] = {"rho": round(pooled[0] / pooled[1], 4) if pooled[1] else None, "images": pooled[1]}
    log(f"{tag}: " + ", ".join(f"{k} {fmt(v['rho'])} (n={v['images']})" for k, v in out.items()))
    return out


def fmt(rho):
    return "-" if rho is None else f"{rho:+.3f}"
