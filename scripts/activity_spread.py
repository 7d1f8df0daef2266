#!/usr/bin/env python3
"""How far one activity reading on a real sequence can be trusted, and where its error comes from.

On a sequence without speed truth (a real tank) the activity with the detector's boxes is judged
against the same pipeline with the true boxes. One such reading moves with details that do not
change the detection or tracking scores, so this runs the pipeline (`fme eval --boxes tracker
--depth model`, the shipped schedule) on detection files that take the detector apart:

- `true`: every true box (the reference);
- `found`: the true boxes of the fish the detector finds (its true positives): which fish;
- `found+jN`: the same, each box moved by N(0, 0.5 px) with seed N: how stable the reading is;
- `detector`: the detector's boxes (this script's decode: fme's letterbox, confidence, NMS);
- `detector+jN`: the same with the half-pixel jitter;
and, for reference, `fme eval --boxes model` (fme's own decode) and `--boxes gt`. Then which fish
the detector finds: the true boxes' speed in the image and size, found against missed, and the
recall by fifths of each (where the true boxes have identities and seqinfo.ini a frame rate).

    python scripts/activity_spread.py DET.onnx [--sequence SEQ] [--jitter 5] [--work DIR] [--json]

Needs the training venv (onnxruntime, opencv: scripts/setup_training.sh) and a built fme. The
network input size is read from the model. On ../shared/realfish/mf25-seq2 (the default, the
evaluation sequence) this is a measurement only: nothing may be chosen or tuned with it.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np
import onnxruntime as ort

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "training"))


def net_size(path):
    shape = ort.InferenceSession(path, providers=["CPUExecutionProvider"]).get_inputs()[0].shape
    return int(shape[3]), int(shape[2])


def detections(model, seq, conf, nms_iou):
    """{variant: rows} of the detector on every frame: its boxes, and the true boxes it finds."""
    import evaluate
    import real
    sess = evaluate.session(model)
    name = sess.get_inputs()[0].name
    gt = real.read_mot_gt(seq, with_ids=True)
    n = real.seq_length(seq) or max(gt, default=0)
    out = {"true": [], "found": [], "detector": [], "looks": []}
    for fr in range(1, n + 1):
        path = os.path.join(seq, "img1", f"{fr:06d}.jpg")
        if not os.path.exists(path):
            raise SystemExit(f"{path}: missing (seqinfo.ini says {n} frames)")
        im, _wh, (gain, px, py) = real.letterboxed(path)
        d, sc = evaluate.decode(sess.run(None, {name: evaluate.det_input(im)})[0], conf, nms_iou)
        g = np.array(gt.get(fr, []), np.float64).reshape(-1, 6)
        gn = g[:, :5].copy()
        gn[:, 0], gn[:, 1], gn[:, 2:4] = g[:, 0] * gain + px, g[:, 1] * gain + py, g[:, 2:4] * gain
        _tp, _fp, found, _req, hit = evaluate.match_found(d, gn)
        for b, f in zip(g, found):
            out["true"].append((fr, b[:4], 1.0))
            out["looks"].append((fr, int(b[5]), b[:4], bool(f)))
        for dn, s, h in zip(d, sc, hit):
            out["detector"].append((fr, np.array([(dn[0] - px) / gain, (dn[1] - py) / gain, dn[2] / gain,
                                                  dn[3] / gain]), float(s)))
            if h:
                out["found"].append((fr, g[int(np.argmax(evaluate.iou_one(dn, gn[:, :4])))][:4], float(s)))
    return out


def selection(looks, fps, span_s=0.1):
    """Which fish the detector finds: each true box's speed in the image (its centre's move over
    +-`span_s`, in its own long sides per second; boxes without both neighbours left out) and long
    side, and the recall by fifths of each. A reading from the fish found is biased as they are."""
    looks = [x for x in looks if x[1] >= 0]  # id -1: no identity, so no speed
    by_id = {}
    for fr, i, b, _f in looks:
        by_id.setdefault(i, {})[fr] = b
    k = max(1, round(span_s * fps))
    rows = []
    for fr, i, b, f in looks:
        a, c = by_id[i].get(fr - k), by_id[i].get(fr + k)
        if a is None or c is None:
            continue
        move = np.hypot(c[0] + c[2] / 2 - a[0] - a[2] / 2, c[1] + c[3] / 2 - a[1] - a[3] / 2)
        rows.append((move * fps / (2 * k) / max(b[2], b[3]), max(b[2], b[3]), f))
    if not rows:
        return None
    r = np.array(rows, np.float64)
    out = {"boxes": len(r)}
    for name, sel in (("found", r[:, 2] == 1), ("missed", r[:, 2] == 0)):
        out[name] = {"boxes": int(sel.sum()), "mean_bls": float(r[sel, 0].mean()) if sel.any() else None,
                     "median_long_px": float(np.median(r[sel, 1])) if sel.any() else None}
    for name, col in (("recall_by_speed", 0), ("recall_by_long_side", 1)):
        order = r[np.argsort(r[:, col], kind="stable")]
        out[name] = [{"from": float(p[0, col]), "to": float(p[-1, col]), "recall": float(p[:, 2].mean())}
                     for p in np.array_split(order, 5) if len(p)]
    return out


def write_variant(work, seq, name, rows, jitter_seed=None):
    d = os.path.join(work, name)
    os.makedirs(os.path.join(d, "det"), exist_ok=True)
    # Everything but det/: the variant is read as the sequence is (its meta.json, calibration, depth/).
    for x in sorted(set(os.listdir(seq)) - {"det"}):
        link = os.path.join(d, x)
        if not os.path.lexists(link):
            os.symlink(os.path.join(os.path.abspath(seq), x), link)
    rng = np.random.default_rng(jitter_seed) if jitter_seed is not None else None
    with open(os.path.join(d, "det", "det.txt"), "w") as f:
        for fr, b, s in rows:
            if rng is not None:
                b = b + rng.normal(0.0, 0.5, 4)
            f.write(f"{fr},-1,{b[0]:.2f},{b[1]:.2f},{b[2]:.2f},{b[3]:.2f},{s:.3f},-1,-1,-1\n")
    return d


KEYS = ("mean_activity_bls", "fit_failures", "activity_frames", "mota", "idf1")


def fme_eval(fme, seq, boxes, det_model):
    cmd = [fme, "eval", "--sequence", seq, "--boxes", boxes, "--depth", "model", "--threads", "1", "--json"]
    if det_model:
        cmd += ["--det-model", det_model]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {r.returncode}: {r.stderr.strip()[-400:]}")
    d = json.loads(r.stdout)
    return {k: d.get(k) for k in KEYS}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", help="the detector ONNX file (int8, as shipped)")
    ap.add_argument("--sequence", default=os.path.join(ROOT, "..", "shared", "realfish", "mf25-seq2"))
    ap.add_argument("--jitter", type=int, default=5, help="jittered runs of each box source")
    ap.add_argument("--conf", type=float, default=0.3, help="detector.confidence (fme's default)")
    ap.add_argument("--nms-iou", type=float, default=0.5, help="detector.nms_iou (fme's default)")
    ap.add_argument("--work", default="/tmp/fme-activity-spread")
    ap.add_argument("--fme", default=os.path.join(ROOT, "target", "release", "fme"))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    for p, what in ((args.model, "model"), (args.fme, "fme binary (make build)")):
        if not os.path.exists(p):
            raise SystemExit(f"{p}: no such {what}")
    if not os.path.isfile(os.path.join(args.sequence, "gt", "gt.txt")):
        raise SystemExit(f"{args.sequence}: not a MOTChallenge sequence with gt/gt.txt")
    os.environ["FME_NET"] = "%dx%d" % net_size(args.model)
    rows = detections(args.model, args.sequence, args.conf, args.nms_iou)
    runs = {"fme --boxes gt": fme_eval(args.fme, args.sequence, "gt", None),
            "fme --boxes model": fme_eval(args.fme, args.sequence, "model", args.model)}
    for name in ("true", "found", "detector"):
        runs[name] = fme_eval(args.fme, write_variant(args.work, args.sequence, name, rows[name]), "tracker", None)
        if name == "true":
            continue
        for k in range(1, args.jitter + 1):
            d = write_variant(args.work, args.sequence, f"{name}+j{k}", rows[name], k)
            runs[f"{name}+j{k}"] = fme_eval(args.fme, d, "tracker", None)
    import real
    fps = real.frame_rate(args.sequence)
    sel = selection(rows["looks"], fps) if fps > 0 else None
    summary = {}
    for name in ("found", "detector"):
        every = [r["mean_activity_bls"] for k, r in runs.items() if k.split("+")[0] == name]
        v = [a for a in every if a is not None]
        summary[name] = {"min": min(v, default=None), "max": max(v, default=None), "runs": len(v),
                         "of": len(every)}
    if args.json:
        print(json.dumps({"model": args.model, "sequence": args.sequence, "runs": runs, "spread": summary,
                          "selection": sel}, indent=1))
        return
    ref = runs["true"]["mean_activity_bls"]
    print(f"{args.model} on {args.sequence} (activity in BL/s; error against `true`, "
          f"{'-' if ref is None else f'{ref:.3f}'})")
    print(f"{'boxes':<20} {'BL/s':>7} {'error':>7} {'fit fails':>9} {'MOTA':>6} {'IDF1':>6}")
    def err(a):
        return f"{100 * (a / ref - 1):+6.1f}%" if a is not None and ref else "      -"

    for k, r in runs.items():
        a = r["mean_activity_bls"]
        mota, idf1 = (("-" if x is None else f"{x:.3f}") for x in (r["mota"], r["idf1"]))
        bls = "      -" if a is None else f"{a:7.3f}"
        print(f"{k:<20} {bls} {err(a)} {r['fit_failures']:>9} {mota:>6} {idf1:>6}")
    for name, s in summary.items():
        if s["min"] is None:
            print(f"{name}: no activity reading")
            continue
        print(f"{name}: {s['min']:.3f}-{s['max']:.3f} BL/s over the {s['runs']} of {s['of']} runs with a reading "
              f"({err(s['min']).strip()} to "
              f"{err(s['max']).strip()})")
    if sel:
        def group(g):
            return "none" if g["mean_bls"] is None else f"{g['mean_bls']:.3f} (median long side {g['median_long_px']:.0f} px)"

        print(f"which fish are found ({sel['boxes']} true boxes with a speed): image speed, long sides/s, "
              f"found {group(sel['found'])} against missed {group(sel['missed'])}")
        for name, unit in (("recall_by_speed", "long sides/s"), ("recall_by_long_side", "px")):
            print(f"  recall by fifths of {name[10:].replace('_', ' ')} ({unit}): " + ", ".join(
                f"{q['from']:.2f}-{q['to']:.2f} {q['recall']:.2f}" for q in sel[name]))


if __name__ == "__main__":
    main()
