"""Quality of the exported ONNX models on held-out sequences, computed the way fme uses them.

Detector: letterboxed input, the model's YOLO-layout output, greedy class-aware NMS (IoU 0.7, as
fme's default), boxes clipped to the frame; precision and recall at IoU 0.5 against gt/gt.txt
boxes clipped to the frame. GT boxes with visibility >= VIS_REQUIRED must be found; less visible
ones are "don't care" (a detection on them is neither a true nor a false positive).

Depth: per frame, the relative map is fitted to metric depth in disparity space with the
reference cubes of meta.json (front-face centres, paper eq. 1-2, least squares s * r + t = 1/z),
then depth at each visible fish (GT box centre, 3x3 median) is compared with the camera z of its
body centre (gt/world.csv): RMSE and delta < 1.25.
"""
import os

import numpy as np
import onnxruntime as ort

import data

VIS_REQUIRED = 0.5


def session(path, threads=2, spin=False):
    """An ONNX Runtime CPU session; idle worker threads sleep unless `spin` (fme's default is to sleep)."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    if not spin:
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def random_feed(sess):
    """A fixed random input for timing `sess` (dynamic dimensions as 1)."""
    i = sess.get_inputs()[0]
    x = np.random.default_rng(0).random([d if isinstance(d, int) else 1 for d in i.shape], dtype=np.float32)
    return {i.name: x}


def iou_one(b, bs):
    x0 = np.maximum(b[0], bs[:, 0])
    y0 = np.maximum(b[1], bs[:, 1])
    x1 = np.minimum(b[0] + b[2], bs[:, 0] + bs[:, 2])
    y1 = np.minimum(b[1] + b[3], bs[:, 1] + bs[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = b[2] * b[3] + bs[:, 2] * bs[:, 3] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-9), 0.0)


def decode(out, conf, iou=0.7, max_det=300, W=data.NET_W, H=data.NET_H):
    """Same rule as fme's decode_yolo + nms + clip_to_frame (one class)."""
    o = out[0]
    s = o[4:].max(0)
    keep = np.nonzero(s >= conf)[0]
    b = np.stack([o[0, keep] - o[2, keep] / 2, o[1, keep] - o[3, keep] / 2, o[2, keep], o[3, keep]], 1)
    sc = s[keep]
    order = np.argsort(-sc, kind="stable")
    b, sc = b[order], sc[order]
    kept = []
    for i in range(len(b)):
        if len(kept) >= max_det:
            break
        if kept and (iou_one(b[i], b[kept]) > iou).any():
            continue
        kept.append(i)
    b, sc = b[kept], sc[kept]
    x0 = np.clip(b[:, 0], 0, W)
    y0 = np.clip(b[:, 1], 0, H)
    x1 = np.clip(b[:, 0] + b[:, 2], 0, W)
    y1 = np.clip(b[:, 1] + b[:, 3], 0, H)
    b = np.stack([x0, y0, x1 - x0, y1 - y0], 1)
    ok = (b[:, 2] > 0) & (b[:, 3] > 0)
    return b[ok], sc[ok]


def clip_gt(g, W=data.NET_W, H=data.NET_H):
    x0 = np.clip(g[:, 0], 0, W)
    y0 = np.clip(g[:, 1], 0, H)
    x1 = np.clip(g[:, 0] + g[:, 2], 0, W)
    y1 = np.clip(g[:, 1] + g[:, 3], 0, H)
    out = np.stack([x0, y0, x1 - x0, y1 - y0, g[:, 4]], 1)
    return out[(out[:, 2] >= 1) & (out[:, 3] >= 1)]


def match(dets, gt, thr=0.5):
    """Returns (tp, fp, fn) with don't-care GT (visibility < VIS_REQUIRED)."""
    tp, fp, found, req, _ = match_found(dets, gt, thr)
    return tp, fp, int(req.sum() - found.sum())


def match_found(dets, gt, thr=0.5):
    """`match`'s greedy matching (in the detections' order, by score from `decode`): (tp, fp, which
    required GT boxes were found, which are required, which detections are true positives)."""
    req = gt[:, 4] >= VIS_REQUIRED
    used = np.zeros(len(gt), bool)
    hit = np.zeros(len(dets), bool)
    tp = fp = 0
    for i, d in enumerate(dets):
        if len(gt) == 0:
            fp += 1
            continue
        ious = iou_one(d, gt[:, :4])
        ious[used] = -1
        # Prefer a required GT, then a don't-care one.
        cand_req = np.where(req, ious, -1)
        j = int(np.argmax(cand_req))
        if cand_req[j] >= thr:
            used[j] = hit[i] = True
            tp += 1
            continue
        cand = np.where(~req, ious, -1)
        j = int(np.argmax(cand)) if len(cand) else 0
        if len(cand) and cand[j] >= thr:
            used[j] = True  # don't care
            continue
        fp += 1
    return tp, fp, req & used, req, hit


def det_input(img):
    """An HWC uint8 frame at the network's size as the detector's [1, 3, H, W] input in 0..1."""
    return img.astype(np.float32).transpose(2, 0, 1)[None] / 255.0


def eval_detector(sess, images, boxes, conf=0.25, iou=0.7):
    name = sess.get_inputs()[0].name
    tp = fp = fn = 0
    for img, g in zip(images, boxes):
        out = sess.run(None, {name: det_input(img)})[0]
        d, _ = decode(out, conf, iou)
        a, b, c = match(d, clip_gt(g))
        tp, fp, fn = tp + a, fp + b, fn + c
    p = tp / max(tp + fp, 1)
    r = tp / max(tp + fn, 1)
    return {"precision": p, "recall": r, "tp": tp, "fp": fp, "fn": fn, "conf": conf}


SIZE_EDGES = (16, 48, 128)  # long side in network pixels: small, medium, large, very large (a close fish)
SIZE_LABELS = ("<16", "16-48", "48-128", ">=128")


def eval_detector_confs(sess, images, boxes, confs, iou=0.7):
    """`eval_detector` at each of `confs`, the network run once per image (the same numbers), each
    with `by_size`: [label, required true boxes, recall] by the box's long side (SIZE_EDGES). The
    aggregate hides which fish a detector misses; real tanks and cages show fish longer than 128 px,
    which the training images rarely have. And `geometry` (`box_geometry`): how the boxes are drawn,
    which moves the activity through the fish ruler even where P / R hold."""
    name = sess.get_inputs()[0].name
    counts = [[0, 0, 0] for _ in confs]
    geo = [Geometry() for _ in confs]
    n_size = np.zeros(len(SIZE_LABELS), int)
    hit_size = np.zeros((len(confs), len(SIZE_LABELS)), int)
    for img, g in zip(images, boxes):
        out = sess.run(None, {name: det_input(img)})[0]
        gt = clip_gt(g)
        size = np.searchsorted(SIZE_EDGES, np.maximum(gt[:, 2], gt[:, 3]), side="right")
        n_size += np.bincount(size[gt[:, 4] >= VIS_REQUIRED], minlength=len(SIZE_LABELS))
        for i, (c, k) in enumerate(zip(confs, counts)):
            d, _ = decode(out, c, iou)
            a, b, found, req, hit = match_found(d, gt)
            k[0], k[1], k[2] = k[0] + a, k[1] + b, k[2] + int(req.sum() - found.sum())
            hit_size[i] += np.bincount(size[found], minlength=len(SIZE_LABELS))
            geo[i].add(d, hit, gt)
    return [{"precision": tp / max(tp + fp, 1), "recall": tp / max(tp + fn, 1), "tp": tp, "fp": fp, "fn": fn,
             "conf": c, "by_size": [[lab, int(n), float(h / n) if n else None]
                                    for lab, n, h in zip(SIZE_LABELS, n_size, hits)],
             "geometry": g.summary()}
            for c, (tp, fp, fn), hits, g in zip(confs, counts, hit_size, geo)]


class Geometry:
    """How a detector draws its boxes against the true ones. The activity with the fish as the ruler
    scales with the boxes' size (a box 1.3x the fish reads the fish 1.3x nearer, its speed 1/1.3),
    so a detector can hold P / R and still move the index (docs/lab-notes, "box geometry"):
    - `long_ratio`: median long side of a true-positive box over its true box's (IoU 0.5 allows
      about 0.7-1.4);
    - `merged`: share of false positives holding the centres of two or more true boxes (one box
      over fish that overlap: too long, too slow);
    - `fragment`: share of false positives at least 70 % inside one true box and under half its area
      (a head, tail or flank: too short, too fast)."""

    def __init__(self):
        self.ratios, self.fp, self.merged, self.fragment = [], 0, 0, 0

    def add(self, dets, hit, gt):
        if len(gt) == 0:
            self.fp += len(dets)
            return
        cx, cy = gt[:, 0] + gt[:, 2] / 2, gt[:, 1] + gt[:, 3] / 2
        for d, h in zip(dets, hit):
            if h:
                j = int(np.argmax(iou_one(d, gt[:, :4])))
                self.ratios.append(max(d[2], d[3]) / max(gt[j, 2], gt[j, 3]))
                continue
            self.fp += 1
            inside = (cx >= d[0]) & (cx <= d[0] + d[2]) & (cy >= d[1]) & (cy <= d[1] + d[3])
            if inside.sum() >= 2:
                self.merged += 1
                continue
            ix = np.clip(np.minimum(d[0] + d[2], gt[:, 0] + gt[:, 2]) - np.maximum(d[0], gt[:, 0]), 0, None)
            iy = np.clip(np.minimum(d[1] + d[3], gt[:, 1] + gt[:, 3]) - np.maximum(d[1], gt[:, 1]), 0, None)
            share = ix * iy / max(d[2] * d[3], 1e-9)
            if ((share >= 0.7) & (d[2] * d[3] < 0.5 * gt[:, 2] * gt[:, 3])).any():
                self.fragment += 1

    def summary(self):
        return {"long_ratio": float(np.median(self.ratios)) if self.ratios else None,
                "merged": self.merged / self.fp if self.fp else None,
                "fragment": self.fragment / self.fp if self.fp else None}


def sweep_conf(sess, images, boxes, confs=(0.2, 0.25, 0.3, 0.35, 0.4, 0.5)):
    return [eval_detector(sess, images, boxes, c) for c in confs]


def world_rows(seq):
    rows = {}
    path = os.path.join(seq, "gt", "world.csv")
    with open(path) as f:
        next(f)
        for line in f:
            v = line.strip().split(",")
            rows.setdefault(int(v[0]), {})[int(v[1])] = (float(v[2]), float(v[3]), float(v[4]), float(v[9]))
    return rows


def sample(m, u, v, r=1):
    h, w = m.shape
    x, y = int(u), int(v)
    if not (0 <= x < w and 0 <= y < h):
        return None
    win = m[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1]
    return float(np.median(win))


def eval_depth(sess, seq_paths, every=5):
    """Depth RMSE / delta<1.25 at fish centres after the per-frame reference fit."""
    name = sess.get_inputs()[0].name
    errs, ratios = [], []
    fits_failed = 0
    for seq in seq_paths:
        s = data.load_sequence(seq, every=every, with_depth=False)
        meta = s["meta"]
        cam = meta["camera"]
        R = np.array(cam["world_to_camera"]["rotation"])
        t = np.array(cam["world_to_camera"]["translation"])
        sw, sh = s["src_size"]
        world = world_rows(seq)
        refs = [(u, v, z) for u, v, z, _r in data.project_references(meta)]
        for img, fr in zip(s["images"], s["frames"]):
            x = data_input(img)
            m = sess.run(None, {name: x})[0]
            m = m.reshape(m.shape[-2], m.shape[-1])
            kx, ky = m.shape[1] / sw, m.shape[0] / sh
            rr, dd = [], []
            for u, v, z in refs:
                r = sample(m, u * kx, v * ky)
                if r is not None:
                    rr.append(r)
                    dd.append(1.0 / z)
            if len(rr) < 2:
                fits_failed += 1
                continue
            A = np.stack([rr, np.ones(len(rr))], 1)
            (sc, sh_), *_ = np.linalg.lstsq(A, np.array(dd), rcond=None)
            if sc <= 0:
                fits_failed += 1
                continue
            for fid, (bx, by, bw, bh, vis) in gt_ids(seq, fr).items():
                if vis < VIS_REQUIRED or fid not in world.get(fr, {}):
                    continue
                wx, wy, wz, _ = world[fr][fid]
                pc = R @ np.array([wx, wy, wz]) + t
                cx = np.clip(bx + bw / 2, 0, sw - 1)
                cy = np.clip(by + bh / 2, 0, sh - 1)
                r = sample(m, cx * kx, cy * ky)
                if r is None:
                    continue
                disp = sc * r + sh_
                if disp <= 1e-3:
                    continue
                z = 1.0 / disp
                errs.append(z - pc[2])
                ratios.append(max(z / pc[2], pc[2] / z))
    errs = np.array(errs)
    ratios = np.array(ratios)
    return {
        "rmse_m": float(np.sqrt(np.mean(errs ** 2))) if len(errs) else None,
        "delta_1.25": float(np.mean(ratios < 1.25)) if len(ratios) else None,
        "n": int(len(errs)),
        "frames_without_fit": fits_failed,
    }


_GT_CACHE = {}


def gt_ids(seq, fr):
    if seq not in _GT_CACHE:
        rows = {}
        with open(os.path.join(seq, "gt", "gt.txt")) as f:
            for line in f:
                v = line.strip().split(",")
                rows.setdefault(int(v[0]), {})[int(v[1])] = tuple(float(a) for a in (v[2], v[3], v[4], v[5], v[8]))
        _GT_CACHE[seq] = rows
    return _GT_CACHE[seq].get(fr, {})


def data_input(img_u8):
    from depth import to_input

    return to_input(img_u8)[None].astype(np.float32)


def cpu_name():
    """The CPU the timings ran on, for the model cards: its model name and the int8/bf16 extensions
    that change ONNX Runtime's and oneDNN's speed most."""
    try:
        with open("/proc/cpuinfo") as f:
            text = f.read()
    except OSError:
        return "unknown CPU"
    name = next((ln.split(":", 1)[1].strip() for ln in text.splitlines() if ln.startswith("model name")), "unknown CPU")
    flags = set(next((ln.split(":", 1)[1].split() for ln in text.splitlines() if ln.startswith("flags")), []))
    ext = [e for f, e in (("amx_tile", "AMX"), ("avx512_vnni", "AVX-512 VNNI"), ("avx512_bf16", "AVX-512 BF16")) if f in flags]
    return f"{name} ({', '.join(ext)})" if ext else name


ROUNDS, RUNS, WARMUP = 10, 10, 5
TIMING = (f"median of {ROUNDS * RUNS} runs after {WARMUP} warm-ups "
          f"(the three files taking turns, {ROUNDS} rounds of {RUNS})")


def time_models(paths, threads, rounds=ROUNDS, runs=RUNS, warmup=WARMUP):
    """{path: (median, 90th percentile) ms} of one frame per run. The files take turns round by round, so
    a shared machine's slow spells fall on all of them alike and the table compares them fairly."""
    import time

    feeds = []
    for path in paths:
        sess = session(path, threads)
        feed = random_feed(sess)
        for _ in range(warmup):
            sess.run(None, feed)
        feeds.append((sess, feed))
    ts = [[] for _ in paths]
    for _ in range(rounds):
        for (sess, feed), t in zip(feeds, ts):
            for _ in range(runs):
                t0 = time.perf_counter()
                sess.run(None, feed)
                t.append((time.perf_counter() - t0) * 1000)
    return {p: (float(np.median(t)), float(np.percentile(t, 90))) for p, t in zip(paths, ts)}
