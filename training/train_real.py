#!/usr/bin/env python3
"""Trains the detector on real labelled fish images and fme's renders, exports and quantises it,
and reports precision / recall per source on each source's held-out split (docs/training.md
"Real footage"; `make -C training real`).

    python train_real.py --real ../../shared/realfish/train --synth DATA --out DIR [--budget-s S]
    python train_real.py --real ... --synth DATA --init DIR/stage1/fish_det_fp32.onnx --lr 5e-4 --seed 1 --out DIR
    python train_real.py --finetune DIR [DIR ...] --base ../models/fish_det_fp32.onnx --out OUT
    python train_real.py --real ... --synth DATA --arch mnv2 --average A_fp32.onnx B_fp32.onnx ... --out DIR

The renders (DATA/train, DATA/val: sequences `fme synth` wrote, as train.sh makes them) keep the
detector's synthetic quality; the real pool teaches it real fish. Writes OUT/fish_det_fp32.onnx,
OUT/fish_det_int8.onnx and OUT/metrics.json (training record, per-source P / R at several
confidences, timings). Nothing here reads the evaluation sequence mf25-seq2.

Fine-tuning (`make -C training finetune DATA=DIR`): starts from --base (the bundled fp32 detector),
trains on DIR's training part for --budget-s seconds at a lower learning rate, and reports P / R on
DIR's held-out part (real.held_out: blocks of frames, not single frames) before and after.

Averaging (`--average`): no training; the weights of two or more fp32 exports of one layout that
went on from the same stage are averaged element by element (a "model soup", Wortsman et al.
2022), then exported, quantised, scored and calibrated as a trained stage is.
"""
import argparse
import os
import time

import numpy as np
import torch

import calibrate
import data
import det
import evaluate
import real
from train import finish, quantize_and_time, run_log

HERE = os.path.dirname(os.path.abspath(__file__))
CONFS = (0.2, 0.25, 0.3, 0.35, 0.4, 0.5)
# Oversampling per source (copies per epoch): the aquarium's large close fish and the zebrafish tank
# are the closest to a farm tank, and few.
REPEAT = {"aquarium": 2, "zebrafish-lab": 3}


# Held-out renders' frame step: the swarm renders every 5th frame, the fewer close-fish ones every 3rd.
VAL_EVERY = {"renders": 5, "renders-close": 3}


def load_renders(synth, prefix, limit, val_every):
    """The renders of SYNTH/<prefix>train (the first `limit` sequences, all with 0; every 3rd frame)
    and their held-out SYNTH/<prefix>val: (images, boxes, (val images, val boxes), counts)."""
    t_imgs, t_boxes, _, t_seqs = data.load_many(os.path.join(synth, prefix + "train"), every=3, with_depth=False,
                                                limit=limit)
    v_imgs, v_boxes, _, v_seqs = data.load_many(os.path.join(synth, prefix + "val"), every=val_every,
                                                with_depth=False)
    info = {"train_sequences": len(t_seqs), "train_frames": int(len(t_imgs)),
            "val_sequences": len(v_seqs), "val_frames": int(len(v_imgs))}
    return t_imgs, t_boxes, (v_imgs, v_boxes), info


def fmt(x):
    return "-" if x is None else f"{x:.2f}"


def per_source_quality(path, val, nms_iou, log, tag):
    """{source: [P/R per confidence]} of one ONNX file on each held-out split."""
    sess = evaluate.session(path)
    out = {}
    for name, (images, boxes) in val.items():
        if len(images) == 0:
            continue
        out[name] = [dict(m, n_images=len(images), n_boxes=int(sum(len(b) for b in boxes)))
                     for m in evaluate.eval_detector_confs(sess, images, boxes, CONFS, nms_iou)]
        at = {m["conf"]: m for m in out[name]}
        log(f"{tag} {name}: " + ", ".join(f"conf {c}: P {at[c]['precision']:.3f} R {at[c]['recall']:.3f}"
                                          for c in (0.25, 0.3, 0.4)))
        log(f"{tag} {name}: recall at conf 0.3 by long side (px, n): " + ", ".join(
            f"{lab} ({k}) {'-' if r is None else f'{r:.2f}'}" for lab, k, r in at[0.3]["by_size"]))
        g = at[0.3]["geometry"]
        log(f"{tag} {name}: boxes at conf 0.3: long side / true {fmt(g['long_ratio'])}, false positives "
            f"over 2+ fish {fmt(g['merged'])}, inside one fish {fmt(g['fragment'])}")
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", default=os.environ.get("REAL_DATA", os.path.join(HERE, "..", "..", "shared", "realfish", "train")))
    ap.add_argument("--synth", default="", help="folder with train/ and val/ fme sequences (renders); empty: none")
    ap.add_argument("--synth-seqs", type=int, default=240, help="training render sequences used")
    ap.add_argument("--close-seqs", type=int, default=0,
                    help="close-fish render sequences used (SYNTH/close-train, render.sh gen_close; their "
                         "held-out SYNTH/close-val is scored as `renders-close`)")
    ap.add_argument("--finetune", nargs="*", default=None, help="fine-tune on these folders instead")
    ap.add_argument("--base", default=os.path.join(HERE, "..", "models", "fish_det_fp32.onnx"))
    ap.add_argument("--init", default="", help="an fp32 detector to go on training from (the recipe's second stage)")
    ap.add_argument("--average", nargs="+", default=None, metavar="FP32",
                    help="train nothing: average these fp32 exports' weights (one layout, one common start)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--arch", default="full", choices=sorted(det.ARCHS) + sorted(det.PRETRAINED_ARCHS),
                    help="layout: det.ARCHS from random weights, or det.PRETRAINED_ARCHS (mnv2: a pretrained "
                         "MobileNetV2 body, training/pretrained.py fetches its weights)")
    ap.add_argument("--weights", default=None, help="pretrained body weights for mnv2 (default: pretrained.py's file)")
    ap.add_argument("--body-lr-mult", type=float, default=0.25, help="mnv2: the body's learning rate, times --lr")
    ap.add_argument("--freeze-frac", type=float, default=0.1, help="mnv2: the body frozen for this share of the run")
    ap.add_argument("--freeze-blocks", type=int, default=3,
                    help="mnv2: the stem and this many first blocks (strides 2 and 4) never train")
    ap.add_argument("--epochs", type=int, default=40)
    ap.add_argument("--budget-s", type=float, default=4000)
    ap.add_argument("--lr", type=float, default=None, help="default 2e-3 (3e-4 when fine-tuning)")
    ap.add_argument("--zoom", type=float, default=0.35, help="share of real frames enlarged (det.zoom_in)")
    ap.add_argument("--max-zoom", type=float, default=2.5)
    ap.add_argument("--fish-zoom", type=float, default=0.0,
                    help="a further share of frames enlarged around one fish (det.zoom_to_fish)")
    ap.add_argument("--nms-iou", type=float, default=0.5, help="as fme's [detector] nms_iou")
    ap.add_argument("--conf", type=float, default=0.3,
                    help="as fme's [detector] confidence: the score map's fixed point (calibrate.py)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--limit", type=int, default=0, help="at most N images per source (smoke tests)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    log, log_lines = run_log()

    t0 = time.time()
    finetune = args.finetune is not None
    if args.average is not None and (finetune or args.init or len(args.average) < 2):
        raise SystemExit("--average: name two or more fp32 exports, and no --finetune or --init (it trains nothing)")
    if finetune:
        if not args.finetune:
            raise SystemExit("--finetune: name at least one folder (make -C training finetune DATA=DIR)")
        train_sets, val = {}, {}
        for folder in args.finetune:
            for name, v in real.load_any(folder, "train").items():
                train_sets[f"{os.path.basename(os.path.abspath(folder))}/{name}"] = v
            for name, v in real.load_any(folder, "val").items():
                val[f"{os.path.basename(os.path.abspath(folder))}/{name}"] = v
        if sum(len(v[0]) for v in train_sets.values()) == 0:
            raise SystemExit(f"{' '.join(args.finetune)}: no training images after the held-out split")
        if sum(len(v[0]) for v in val.values()) == 0:
            log("finetune: no held-out images (too few frames for a held-out block); P / R on the training part")
            val = train_sets
        sources = {}
    else:
        sources = {s: open(os.path.join(args.real, s, "SOURCE.md")).readline().strip("# \n")
                   for s in real.sources(args.real)}
        train_sets = real.load_pool(args.real, "train", args.limit)
        val = real.load_pool(args.real, "val", args.limit)
    imgs, boxes, color = [], [], []
    for name, (im, bx) in train_sets.items():
        k = 1 if finetune else REPEAT.get(name, 1)
        for _ in range(k):
            imgs.append(im)
            boxes.extend(bx)
            color.extend([True] * len(im))
    n_real = sum(len(b) for b in imgs)
    synth_info = None
    if args.synth and not finetune:
        def add(t_imgs, t_boxes):
            imgs.append(t_imgs)
            boxes.extend(t_boxes)
            color.extend([False] * len(t_imgs))

        *t, val["renders"], synth_info = load_renders(args.synth, "", args.synth_seqs, VAL_EVERY["renders"])
        add(*t)
        if args.close_seqs > 0:
            *t, val["renders-close"], synth_info["close"] = load_renders(
                args.synth, "close-", args.close_seqs, VAL_EVERY["renders-close"])
            add(*t)
    images = np.concatenate(imgs)
    log(f"data: {n_real} real training images ({', '.join(f'{k} {len(v[0])}' for k, v in train_sets.items())}), "
        f"{len(images) - n_real} renders; held out: {', '.join(f'{k} {len(v[0])}' for k, v in val.items())} "
        f"({time.time() - t0:.0f} s)")

    init = det.from_onnx(args.base, 2) if finetune else det.from_onnx(args.init, 2, args.arch) if args.init else None
    fp32 = os.path.join(args.out, "fish_det_fp32.onnx")
    before = None
    if finetune:
        before = per_source_quality(args.base, val, args.nms_iou, log, "before")
    lr = args.lr if args.lr is not None else (3e-4 if finetune else 2e-3)
    t1 = time.time()
    if args.average:
        try:
            model, epochs_run = det.average(args.average, args.arch), 0
        except ValueError as e:
            raise SystemExit(f"--{e}") from None
        log(f"average: {len(args.average)} exports: {', '.join(args.average)}")
    else:
        model, epochs_run = det.train(images, boxes, args.epochs, lr=lr, log=log, time_budget_s=args.budget_s,
                                      sub=2, arch=args.arch, zoom=args.zoom, max_zoom=args.max_zoom,
                                      fish_zoom=args.fish_zoom, color=np.array(color),
                                      init=init, seed=args.seed, body_lr_mult=args.body_lr_mult,
                                      freeze_frac=args.freeze_frac, weights=args.weights,
                                      freeze_blocks=args.freeze_blocks)
    train_s = time.time() - t1
    det.export(model, fp32, data.NET_H, data.NET_W)
    res = {"train_seconds": round(train_s, 1), "epochs": args.epochs, "epochs_run": epochs_run, "lr": lr,
           "autocast": ("bf16" if det.use_bf16() else "fp32") if args.arch not in det.PRETRAINED_ARCHS
           else ("bf16" if os.environ.get("FME_BF16") == "1" else "fp32"), "input": [data.NET_W, data.NET_H],
           "output_stride": model.stride, "arch": "finetuned" if finetune else args.arch,
           "budget_s": args.budget_s, "zoom": args.zoom, "max_zoom": args.max_zoom,
           "fish_zoom": args.fish_zoom, "float_stem": True,
           "params_m": round(sum(p.numel() for p in model.parameters()) / 1e6, 2),
           "data": {"real_train": {k: len(v[0]) for k, v in train_sets.items()},
                    "held_out": {k: len(v[0]) for k, v in val.items()}, "renders": synth_info,
                    "repeat": REPEAT if not finetune else {}, "sources": sources,
                    "excluded": sorted(real.EXCLUDED) if not finetune else [],
                    "held_out_percent": real.HELD_OUT_PERCENT}}
    if args.init and not finetune:
        res["init"] = args.init
    if args.average:
        res["averaged"] = [os.path.abspath(p) for p in args.average]
    if args.arch in det.PRETRAINED_ARCHS and not finetune and not args.init and not args.average:
        import pretrained
        w = args.weights or pretrained.weights_path()
        res["pretrained"] = {"weights": w, "source": torch.load(w, map_location="cpu").get("source"),
                             "body_lr_mult": args.body_lr_mult, "freeze_frac": args.freeze_frac,
                             "freeze_blocks": args.freeze_blocks}
    res["seed"] = args.seed
    if finetune:
        res["base"] = os.path.basename(args.base)
        res["before"] = before
    calib_idx = np.random.default_rng(1).choice(len(images), size=min(64, len(images)), replace=False)
    calib = [images[i].astype(np.float32).transpose(2, 0, 1) / 255.0 for i in calib_idx]
    paths, ms = quantize_and_time(args.out, "fish_det", fp32, calib, "images", res, float_stem=True)
    for tag, path in paths.items():
        res[tag] = {"size_mb": round(os.path.getsize(path) / 1e6, 2), "ms_1_thread": ms[1][path],
                    "ms_2_threads": ms[2][path], "quality": per_source_quality(path, val, args.nms_iou, log, tag)}
    def calibrate_scores():
        # After P / R: the map keeps every box and its order above fme's confidence, so they hold. A
        # fine-tune keeps its base's map (the training graph has none).
        if not finetune and "renders" in val:
            res["score_map"] = calibrate.calibrate_pair(args.out, "fish_det", *val["renders"], conf=args.conf, log=log)
        elif finetune and (base_map := calibrate.score_map_of(args.base)) is not None:
            calibrate.map_pair(args.out, "fish_det", *base_map)
            res["score_map"] = {"a": base_map[0], "conf": base_map[1], "from": os.path.basename(args.base)}

    finish(args.out, "fish_det", res, log, log_lines, t0, calibrate_scores)


if __name__ == "__main__":
    main()
