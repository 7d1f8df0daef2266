#!/usr/bin/env python3
"""Score calibration of a detector for fme's tracker: a copy of a detector ONNX file whose scores are
mapped so that its true fish score as the bundled detector's do on the same held-out renders.

fme's tracker starts a track only from a detection scoring `tracker.new_track_threshold` (0.8) or
more, and treats `track_threshold` (0.5) as "high"; both were set with the bundled detector, whose
true detections on the held-out renders score 0.86 at the median. A detector trained on real fish
is less sure of itself (a median of 0.69 there for the pretrained candidates), so few of its fish
ever start a track, whatever its precision and recall. The map is Platt's form on the score's logit,

    s' = sigmoid(a * logit(s) + (1 - a) * logit(c)),

with its fixed point at the detector's confidence threshold c (`detector.confidence`, 0.3): the
boxes above c and their order are unchanged, so detection precision and recall at c are exactly
the same, and only the scale the tracker reads moves. `a` matches the median logit of the true
detections (IoU >= 0.5) on the held-out render sequences to the reference detector's. It is
appended to the graph (the output keeps its [1, 5, N] layout, so the file stays a drop-in) and
recorded in the file's metadata (`fme.score_map`).

    FME_NET=480x288 python calibrate.py IN.onnx OUT.onnx [--ref ../models/fish_det_int8.onnx]
        [--renders /tmp/fme-train-data/val] [--conf 0.3] [--slope A]
"""
import argparse
import json
import os

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

import data
import evaluate

HERE = os.path.dirname(os.path.abspath(__file__))
EPS = 1e-6
KEY = "fme.score_map"  # the map's metadata entry: {"a", "conf", "map"}


def logit(p):
    p = np.clip(p, EPS, 1 - EPS)
    return np.log(p) - np.log1p(-p)


def true_scores(path, images, boxes, conf, nms_iou=0.5):
    """Scores of the detections (at `conf` and above) that are true positives by the P / R matching
    (`evaluate.match_found`)."""
    sess = evaluate.session(path, threads=2)
    inp = sess.get_inputs()[0]
    h, w = inp.shape[2], inp.shape[3]
    out = []
    for img, g in zip(images, boxes):
        img, g = at_size(img, g, w, h)
        d, sc = evaluate.decode(sess.run(None, {inp.name: evaluate.det_input(img)})[0], conf, nms_iou)
        out.append(sc[evaluate.match_found(d, evaluate.clip_gt(g, w, h))[4]])
    return np.concatenate(out).astype(np.float64) if out else np.zeros(0)


def at_size(img, g, w, h):
    """A network-input frame and its boxes letterboxed again to a w x h input, as fme would feed that
    detector (`data.letterbox`): the reference detector may take another input size."""
    ih, iw = img.shape[:2]
    if (iw, ih) == (w, h):
        return img, g
    gain, _nw, _nh, padx, pady = data.letterbox_params(iw, ih, w, h)
    return data.letterbox(img, w, h), data.boxes_to_net(g.astype(np.float32), (gain, padx, pady))


def fit(scores, ref_scores, conf):
    """`a` that moves the median true-detection logit onto the reference's (1: already alike), and a
    report of both. ValueError where there is nothing to fit on."""
    lc = float(logit(conf))
    if len(scores) == 0 or len(ref_scores) == 0:
        raise ValueError(f"no true detections at conf {conf} to fit on ({len(scores)}, reference {len(ref_scores)})")
    num, den = float(np.median(logit(ref_scores))) - lc, float(np.median(logit(scores))) - lc
    if den <= 0 or num <= 0:
        raise ValueError(f"the true detections' median score is not above conf {conf}")
    a = num / den
    after = apply_map(scores, a, conf)
    share = lambda v: round(float((v >= 0.8).mean()), 3)
    return a, {"a": round(a, 4), "b": round((1 - a) * lc, 4), "conf": conf, "true_detections": int(len(scores)),
               "reference": {"median": round(float(np.median(ref_scores)), 3), "share_ge_0_8": share(ref_scores)},
               "before": {"median": round(float(np.median(scores)), 3), "share_ge_0_8": share(scores)},
               "after": {"median": round(float(np.median(after)), 3), "share_ge_0_8": share(after)}}


def apply_map(scores, a, conf):
    """The map in numpy, as the graph computes it."""
    return 1.0 / (1.0 + np.exp(-(a * logit(scores) + (1 - a) * logit(conf))))


def append_map(src, dst, a, conf):
    """Writes `src` with the map on row 4 (the score) of its [1, 5, N] output."""
    m = onnx.load(src)
    props = {p.key: p.value for p in m.metadata_props}
    if KEY in props:
        raise SystemExit(already_calibrated(src, props[KEY]))
    b = (1 - a) * float(logit(conf))
    g = m.graph
    out = g.output[0]
    raw = out.name + "_uncalibrated"
    for n in g.node:
        n.output[:] = [raw if o == out.name else o for o in n.output]
        n.input[:] = [raw if i == out.name else i for i in n.input]
    c = lambda name, v, dt=np.float32: numpy_helper.from_array(np.asarray(v, dt), name)
    g.initializer.extend([c("cal_split", [4, 1], np.int64), c("cal_lo", EPS), c("cal_hi", 1 - EPS), c("cal_one", 1.0),
                          c("cal_a", a), c("cal_b", b)])
    nodes = [
        helper.make_node("Split", [raw, "cal_split"], ["cal_boxes", "cal_s"], axis=1),
        helper.make_node("Clip", ["cal_s", "cal_lo", "cal_hi"], ["cal_sc"]),
        helper.make_node("Log", ["cal_sc"], ["cal_log_s"]),
        helper.make_node("Sub", ["cal_one", "cal_sc"], ["cal_1ms"]),
        helper.make_node("Log", ["cal_1ms"], ["cal_log_1ms"]),
        helper.make_node("Sub", ["cal_log_s", "cal_log_1ms"], ["cal_logit"]),
        helper.make_node("Mul", ["cal_logit", "cal_a"], ["cal_ax"]),
        helper.make_node("Add", ["cal_ax", "cal_b"], ["cal_z"]),
        helper.make_node("Sigmoid", ["cal_z"], ["cal_s2"]),
        helper.make_node("Concat", ["cal_boxes", "cal_s2"], [out.name], axis=1),
    ]
    g.node.extend(nodes)
    dims = [d.dim_value for d in out.type.tensor_type.shape.dim]
    g.value_info.append(helper.make_tensor_value_info(raw, TensorProto.FLOAT, dims))
    note = {"a": a, "conf": conf, "map": f"sigmoid({a:.4f} * logit(s) + {b:.4f})"}
    onnx.helper.set_model_props(m, {**props, KEY: json.dumps(note)})
    onnx.checker.check_model(m)
    onnx.save(m, dst)


def score_map_of(path):
    """(a, conf) of a calibrated file's map (its `fme.score_map` metadata), or None."""
    props = {p.key: p.value for p in onnx.load(path, load_external_data=False).metadata_props}
    if KEY not in props:
        return None
    try:
        m = json.loads(props[KEY])
        return float(m["a"]), float(m["conf"])
    except (ValueError, KeyError, TypeError) as e:
        raise SystemExit(f"calibrate: {path}: unreadable {KEY} metadata {props[KEY]!r} ({e})")


def already_calibrated(path, note):
    return f"calibrate: {path} is already calibrated ({note}); calibrate its *_uncalibrated.onnx"


def map_pair(out_dir, stem, a, conf):
    """The map appended to OUT/STEM_{int8,fp32}.onnx in place; the uncalibrated files are kept as
    STEM_{int8,fp32}_uncalibrated.onnx (what `train_real.py --init` may go on from)."""
    for kind in ("int8", "fp32"):
        path = os.path.join(out_dir, f"{stem}_{kind}.onnx")
        raw = os.path.join(out_dir, f"{stem}_{kind}_uncalibrated.onnx")
        os.replace(path, raw)
        append_map(raw, path, a, conf)


def calibrate_pair(out_dir, stem, images, boxes, conf=0.3, ref=None, log=print):
    """The recipe's last step: `a` fitted on OUT/STEM_int8.onnx (the shipped file) against `ref`
    (default the bundled file) and appended to the pair (`map_pair`). Returns the report; where
    nothing can be fitted (a detector that finds no fish yet) the pair stays as it is, and is said so."""
    ref = ref or os.path.join(HERE, "..", "models", f"{stem}_int8.onnx")
    s = true_scores(os.path.join(out_dir, f"{stem}_int8.onnx"), images, boxes, conf)
    try:
        a, report = fit(s, true_scores(ref, images, boxes, conf), conf)
    except ValueError as e:
        log(f"calibrate: not calibrated: {e}")
        return {"skipped": str(e)}
    report["reference"]["file"] = os.path.basename(ref)
    map_pair(out_dir, stem, a, conf)
    log(f"calibrate: a = {a:.3f}; true detections on the held-out renders: median score "
        f"{report['before']['median']} -> {report['after']['median']} (reference {report['reference']['median']}), "
        f"share >= 0.8 {report['before']['share_ge_0_8']} -> {report['after']['share_ge_0_8']}")
    return report


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("out")
    ap.add_argument("--ref", default=os.path.join(HERE, "..", "models", "fish_det_int8.onnx"))
    ap.add_argument("--renders", default="/tmp/fme-train-data/val", help="held-out render sequences")
    ap.add_argument("--conf", type=float, default=0.3, help="as fme's [detector] confidence: the map's fixed point")
    ap.add_argument("--slope", type=float, default=None, help="use this `a` instead of fitting it")
    args = ap.parse_args()
    if (done := score_map_of(args.model)) is not None:  # before the slow part
        raise SystemExit(already_calibrated(args.model, f"a, conf = {done}"))
    images, boxes, _, seqs = data.load_many(args.renders, every=5, with_depth=False)
    s = true_scores(args.model, images, boxes, args.conf)
    if args.slope is None:
        try:
            a, report = fit(s, true_scores(args.ref, images, boxes, args.conf), args.conf)
        except ValueError as e:
            raise SystemExit(f"calibrate: {args.model}: {e}")
        report["reference"]["file"] = os.path.basename(args.ref)
    else:
        a, report = args.slope, {"a": args.slope, "conf": args.conf}
    report["fitted_on"] = f"{len(seqs)} held-out render sequences, {len(images)} frames"
    append_map(args.model, args.out, a, args.conf)
    check = true_scores(args.out, images, boxes, args.conf)
    if len(check) != len(s) or np.abs(check - apply_map(s, a, args.conf)).max() > 1e-3:
        raise SystemExit(f"calibrate: {args.out} does not score as the map says ({len(check)} vs {len(s)} true detections)")
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
