"""Reads fme sequences (MOTChallenge + fme extras, see crates/edge/src/sequence) into compact numpy caches.

Frames are resized to the network size (NET_W x NET_H; 640x384 sequences halve exactly, so the
Ultralytics letterbox is a plain resize with no padding). Boxes are scaled the same way. Depth
PNGs (16-bit, millimetres, 0 = no data) are kept at the depth-network output size.
"""
import json
import os

import cv2
import numpy as np


def parse_size(text, what):
    """'WxH' -> (w, h) positive ints; anything else stops with a message naming `what`."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"{what} {text!r}: expected WxH, e.g. 320x192")
    if w <= 0 or h <= 0:
        raise SystemExit(f"{what} {text!r}: width and height must be positive")
    return w, h


# Network input (letterbox of 640x384 without padding). FME_NET=WxH overrides it for one training run
# (train.sh trains the detector and the depth network in separate runs, each at its own size).
NET_W, NET_H = parse_size(os.environ.get("FME_NET", "320x192"), "FME_NET")
DEPTH_OUT_W, DEPTH_OUT_H = NET_W // 2, NET_H // 2  # depth network output (half the input)


def list_sequences(root):
    """Every folder under root that holds a seqinfo.ini (sorted)."""
    out = []
    for dirpath, _dirs, files in os.walk(root):
        if "seqinfo.ini" in files:
            out.append(dirpath)
    return sorted(out)


def letterbox_params(w, h, net_w=None, net_h=None):
    """(gain, nw, nh, padx, pady) of a w x h image letterboxed to the network input (NET_W x NET_H
    unless given), as fme does."""
    net_w, net_h = net_w or NET_W, net_h or NET_H
    gain = min(net_w / w, net_h / h)
    nw, nh = round(w * gain), round(h * gain)
    padx = round((net_w - nw) / 2 - 0.1)
    pady = round((net_h - nh) / 2 - 0.1)
    return gain, nw, nh, padx, pady


def letterbox(img_rgb, net_w=None, net_h=None):
    h, w = img_rgb.shape[:2]
    net_w, net_h = net_w or NET_W, net_h or NET_H
    gain, nw, nh, padx, pady = letterbox_params(w, h, net_w, net_h)
    out = np.full((net_h, net_w, 3), 114, np.uint8)
    out[pady:pady + nh, padx:padx + nw] = cv2.resize(img_rgb, (nw, nh), interpolation=cv2.INTER_LINEAR)
    return out


def boxes_to_net(b, lb):
    """Boxes (x, y, w, h, ...) in source pixels -> network input pixels, for the letterbox
    lb = (gain, padx, pady) of `letterbox_params`."""
    gain, padx, pady = lb
    b = b.copy()
    b[:, 0] = b[:, 0] * gain + padx
    b[:, 1] = b[:, 1] * gain + pady
    b[:, 2:4] *= gain
    return b


def read_gt(path):
    """frame -> list of (x, y, w, h, visibility) in source pixels."""
    boxes = {}
    if not os.path.exists(path):
        return boxes
    with open(path) as f:
        for line in f:
            v = line.strip().split(",")
            if len(v) < 9:
                continue
            fr = int(v[0])
            boxes.setdefault(fr, []).append((float(v[2]), float(v[3]), float(v[4]), float(v[5]), float(v[8])))
    return boxes


def load_sequence(seq, every=1, with_depth=True):
    """Returns dict with images [N,H,W,3] uint8 (network size), boxes (list of [K,5] arrays in
    network pixels: x,y,w,h,vis), depth [N,DH,DW] float32 metres (0 = none), meta, frame ids."""
    meta = json.load(open(os.path.join(seq, "meta.json")))
    gt = read_gt(os.path.join(seq, "gt", "gt.txt"))
    frames = sorted(f for f in os.listdir(os.path.join(seq, "img1")) if f[0].isdigit())
    imgs, boxes, depths, ids = [], [], [], []
    for i, name in enumerate(frames):
        if i % every:
            continue
        fr = int(os.path.splitext(name)[0])
        bgr = cv2.imread(os.path.join(seq, "img1", name), cv2.IMREAD_COLOR)
        if bgr is None:
            raise IOError(f"{seq}/img1/{name}: unreadable image")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        h, w = rgb.shape[:2]
        gain, _nw, _nh, padx, pady = letterbox_params(w, h)
        imgs.append(letterbox(rgb))
        boxes.append(boxes_to_net(np.array(gt.get(fr, []), np.float32).reshape(-1, 5), (gain, padx, pady)))
        ids.append(fr)
        if with_depth:
            dpath = os.path.join(seq, "depth", os.path.splitext(name)[0] + ".png")
            d = cv2.imread(dpath, cv2.IMREAD_UNCHANGED)
            if d is None:
                raise IOError(f"{dpath}: unreadable depth PNG")
            d = d.astype(np.float32) / 1000.0
            # Nearest resize keeps "0 = no data" from bleeding into valid pixels.
            depths.append(cv2.resize(d, (DEPTH_OUT_W, DEPTH_OUT_H), interpolation=cv2.INTER_NEAREST))
    out = {
        "images": np.stack(imgs),
        "refs": reference_footprints(meta, gain, padx, pady),
        "boxes": boxes,
        "meta": meta,
        "frames": ids,
        "src_size": (w, h),
        "path": seq,
    }
    if with_depth:
        out["depth"] = np.stack(depths)
    return out


def project_references(meta):
    """Each reference cube in front of the camera (meta.json): its front-face centre in source
    pixels, its camera depth z (m) and its half-size in pixels, as (u, v, z, half_px)."""
    cam = meta["camera"]
    rot = np.array(cam["world_to_camera"]["rotation"])
    tr = np.array(cam["world_to_camera"]["translation"])
    out = []
    for ro in meta.get("reference_objects", []):
        pc = rot @ np.array(ro["front_face_center_w"]) + tr
        if pc[2] <= 0.05:
            continue
        u = cam["fx"] * pc[0] / pc[2] + cam["cx"]
        v = cam["fy"] * pc[1] / pc[2] + cam["cy"]
        out.append((u, v, pc[2], 0.5 * ro["size_m"] * cam["fx"] / pc[2]))
    return out


def reference_footprints(meta, gain, padx, pady):
    """The reference cubes' front-face centres and half-sizes, (u, v, radius) in network input
    pixels (the camera is fixed, so one list serves every frame of a sequence)."""
    return [(u * gain + padx, v * gain + pady, r * gain) for u, v, _z, r in project_references(meta)]


def load_many(root, every=1, with_depth=True, limit=0):
    """Every sequence under root (the first `limit` in seed order when limit > 0)."""
    paths = list_sequences(root)
    seqs = [load_sequence(s, every, with_depth) for s in (paths[:limit] if limit > 0 else paths)]
    images = np.concatenate([s["images"] for s in seqs])
    boxes = [b for s in seqs for b in s["boxes"]]
    depth = np.concatenate([s["depth"] for s in seqs]) if with_depth else None
    return images, boxes, depth, seqs
