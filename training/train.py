#!/usr/bin/env python3
"""Trains, exports, quantises and evaluates fme's bundled models (docs/training.md; figures in docs/accuracy.md).

    python train.py --data DATA_DIR --models ../models [--det-epochs N] [--depth-epochs N]
    python train.py --data DATA_DIR --requantize [--skip depth]   # re-quantise the fp32 files only
    python train.py --data DATA_DIR --reexport [--skip depth]     # rebuild the fp32 graphs from their weights, re-quantise

DATA_DIR/train and DATA_DIR/val hold fme sequences (made by train.sh with `fme synth`).
Writes models/fish_det_{fp32,int8}.onnx, models/fish_depth_{fp32,int8}.onnx and
training/metrics.json (quality on the held-out sequences, timings, training time).
"""
import argparse
import json
import os
import shutil
import time

import numpy as np
import onnx
import torch
from onnxruntime.quantization import QuantType

import data
import depth
import det
import evaluate
import quant

HERE = os.path.dirname(os.path.abspath(__file__))


def parse_crop(text, net_w, net_h, flag="--depth-crop"):
    """'WxH' -> (w, h), checked against the network input; '' -> None. `flag` names the option in errors."""
    if not text:
        return None
    w, h = data.parse_size(text, flag)
    if w % 32 or h % 32 or w > net_w or h > net_h:
        raise SystemExit(f"{flag} {text!r}: width and height must be multiples of 32 within the "
                         f"{net_w}x{net_h} input")
    return w, h


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--models", default=os.path.join(HERE, "..", "models"))
    ap.add_argument("--det-epochs", type=int, default=12)
    ap.add_argument("--depth-epochs", type=int, default=10)
    ap.add_argument("--budget-s", type=float, default=1500, help="detector training time budget, seconds")
    ap.add_argument("--depth-budget-s", type=float, default=None, help="depth training budget (default: --budget-s)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--every", type=int, default=3, help="use every n-th training frame")
    ap.add_argument("--train-seqs", type=int, default=0,
                    help="train on the first N training sequences in seed order (0: all of them)")
    ap.add_argument("--depth-focus", type=float, default=depth.FOCUS_WEIGHT,
                    help="weight of the depth loss's focus term on fish and reference cubes (0: off)")
    ap.add_argument("--depth-crop", default="",
                    help="WxH: train the depth network on random windows of that size (multiples of 32)")
    ap.add_argument("--depth-crop-until", type=float, default=1.0,
                    help="with --depth-crop: fraction of the run after which whole frames are used")
    ap.add_argument("--det-crop", default="",
                    help="WxH (multiples of 32): train the detector on random windows of that size (default: whole frames)")
    ap.add_argument("--det-arch", default="full", choices=sorted(det.ARCHS),
                    help="detector layout (det.ARCHS): full; slim (one stride-8 block less, no stride-4 head conv); "
                         "no_head_conv (only the latter)")
    ap.add_argument("--det-sub", type=int, default=2,
                    help="detector sub-cells per stride-4 cell and axis (2: heat map and boxes at stride 2)")
    ap.add_argument("--det-teacher", default="",
                    help="an fp32 FishDet ONNX file (e.g. ../models/fish_det_fp32.onnx) to distil the detector from")
    ap.add_argument("--kd-weight", type=float, default=None,
                    help="with --det-teacher: weight of the distillation loss (default 1)")
    ap.add_argument("--metrics", default=os.path.join(HERE, "metrics.json"))
    ap.add_argument("--recipe", default="",
                    help="the training/Makefile target that ran this (train.sh's RECIPE), for the model cards")
    ap.add_argument("--skip", default="", help="comma list of stages to skip: det,depth")
    ap.add_argument("--requantize", action="store_true",
                    help="do not train: quantise and measure the fp32 files already in --models again, keeping "
                         "their training record from --metrics")
    ap.add_argument("--reexport", action="store_true",
                    help="like --requantize, but first rebuild the fp32 files' graphs as an export does now, from "
                         "their own weights (detector: det.py's export graph; depth: depth.fast_tail)")
    args = ap.parse_args()
    args.requantize = args.requantize or args.reexport
    if args.kd_weight is not None and not args.det_teacher:
        raise SystemExit(f"--kd-weight {args.kd_weight}: only with --det-teacher (the distillation it weights)")
    args.kd_weight = 1.0 if args.kd_weight is None else args.kd_weight
    depth_crop = parse_crop(args.depth_crop, data.NET_W, data.NET_H)  # before the data loads
    det_crop = parse_crop(args.det_crop, data.NET_W, data.NET_H, "--det-crop")
    if not 0.0 < args.depth_crop_until <= 1.0:
        raise SystemExit(f"--depth-crop-until {args.depth_crop_until}: expected a fraction in (0, 1]")
    torch.set_num_threads(args.threads)
    skip = set(filter(None, args.skip.split(",")))
    os.makedirs(args.models, exist_ok=True)
    metrics_path = args.metrics
    metrics = json.load(open(metrics_path)) if os.path.exists(metrics_path) else {}
    log, log_lines = run_log()

    t0 = time.time()
    # Depth maps only when the depth network trains (the detector run at 288 sequences would hold ~0.3 GB).
    tr_images, tr_boxes, tr_depth, tr_seqs = data.load_many(os.path.join(args.data, "train"), every=args.every,
                                                               with_depth="depth" not in skip and not args.requantize,
                                                               limit=args.train_seqs)
    va_paths = data.list_sequences(os.path.join(args.data, "val"))
    va_images, va_boxes, _, _ = data.load_many(os.path.join(args.data, "val"), every=5, with_depth=False)
    log(f"data: {len(tr_images)} training frames from {len(tr_seqs)} sequences, {len(va_images)} held-out frames "
        f"from {len(va_paths)} sequences ({time.time() - t0:.0f} s)")
    data_info = {
        "train_sequences": [os.path.basename(s["path"]) for s in tr_seqs],
        "val_sequences": [os.path.basename(s) for s in va_paths],
        "train_frames": int(len(tr_images)),
        "val_frames": int(len(va_images)),
        "train_seeds": seeds_of(s["path"] for s in tr_seqs),
        "val_seeds": seeds_of(va_paths),
    }
    calib_idx = np.random.default_rng(1).choice(len(tr_images), size=min(64, len(tr_images)), replace=False)

    if "det" not in skip:
        fp32 = os.path.join(args.models, "fish_det_fp32.onnx")
        if args.requantize:
            res = training_record(metrics, "detector", fp32, log)
            if args.reexport:
                det.export(det.from_onnx(fp32, args.det_sub), fp32, data.NET_H, data.NET_W)
                log(f"detector: re-exported {fp32} from its own weights")
        else:
            # Read before training: the teacher may be the very file this run overwrites.
            teacher = det.from_onnx(args.det_teacher, args.det_sub) if args.det_teacher else None
            t1 = time.time()
            model, epochs_run = det.train(tr_images, tr_boxes, args.det_epochs, log=log,
                                          time_budget_s=args.budget_s, sub=args.det_sub, crop=det_crop,
                                          arch=args.det_arch, teacher=teacher, kd_weight=args.kd_weight)
            train_s = time.time() - t1
            det.export(model, fp32, data.NET_H, data.NET_W)
            res = {"train_seconds": round(train_s, 1), "epochs": args.det_epochs, "epochs_run": epochs_run,
                   "autocast": "bf16" if det.use_bf16() else "fp32",
                   "input": [data.NET_W, data.NET_H],
                   "output_stride": model.stride,
                   "arch": args.det_arch,
                   "data": data_info,
                   "params_m": round(sum(p.numel() for p in model.parameters()) / 1e6, 2),
                   "budget_s": args.budget_s}
            if args.recipe:
                res["recipe"] = args.recipe
            if det_crop:
                res["train_crop"] = list(det_crop)
            if teacher is not None:
                res["teacher"] = {"file": os.path.basename(args.det_teacher), "kd_weight": args.kd_weight}
        calib = [tr_images[i].astype(np.float32).transpose(2, 0, 1) / 255.0 for i in calib_idx]
        res["float_stem"] = True
        paths, ms = quantize_and_time(args.models, "fish_det", fp32, calib, "images", res, float_stem=True)
        for tag, path in paths.items():
            sess = evaluate.session(path)
            sweep = evaluate.sweep_conf(sess, va_images, va_boxes)
            res[tag] = {
                "size_mb": round(os.path.getsize(path) / 1e6, 2),
                "ms_1_thread": ms[1][path],
                "ms_2_threads": ms[2][path],
                "quality": sweep,
            }
            best = max(sweep, key=lambda m: 2 * m["precision"] * m["recall"] / max(m["precision"] + m["recall"], 1e-9))
            log(f"det {tag}: {res[tag]['size_mb']} MB, 2 threads {res[tag]['ms_2_threads'][0]:.2f} ms, "
                f"1 thread {res[tag]['ms_1_thread'][0]:.2f} ms, best F1 at conf {best['conf']}: "
                f"P {best['precision']:.3f} R {best['recall']:.3f}")
        metrics["detector"] = res
        pick(args.models, "fish_det", res, log)

    if "depth" not in skip:
        fp32 = os.path.join(args.models, "fish_depth_fp32.onnx")
        if args.requantize:
            res = training_record(metrics, "depth", fp32, log)
            if args.reexport and depth.fast_tail(fp32):
                log(f"depth: rewrote the graph tail of {fp32} (depth.fast_tail)")
        else:
            t1 = time.time()
            focus = None
            if args.depth_focus > 0:
                tr_refs = [s["refs"] for s in tr_seqs for _ in s["frames"]]
                focus = depth.focus_masks(tr_boxes, tr_refs, tr_depth.shape[1:], (data.NET_H, data.NET_W))
                log(f"depth: focus term weight {args.depth_focus} on {focus.mean() * 100:.1f}% of the pixels")
            model, epochs_run = depth.train(tr_images, tr_depth, args.depth_epochs, log=log,
                                            time_budget_s=args.depth_budget_s or args.budget_s, focus=focus,
                                            focus_weight=args.depth_focus, crop=depth_crop,
                                            crop_until=args.depth_crop_until)
            train_s = time.time() - t1
            depth.export(model, fp32, data.NET_H, data.NET_W)
            res = {"train_seconds": round(train_s, 1), "epochs": args.depth_epochs, "epochs_run": epochs_run,
                   "autocast": "bf16" if det.use_bf16() else "fp32",
                   "data": data_info,
                   "input": [data.NET_W, data.NET_H], "focus_weight": args.depth_focus,
                   "budget_s": args.depth_budget_s or args.budget_s}
            if args.recipe:
                res["recipe"] = args.recipe
            if depth_crop:
                res["train_crop"] = list(depth_crop)
                res["train_crop_until"] = args.depth_crop_until
        calib = [depth.to_input(tr_images[i]) for i in calib_idx]
        paths, ms = quantize_and_time(args.models, "fish_depth", fp32, calib, "image", res)
        for tag, path in paths.items():
            sess = evaluate.session(path)
            q = evaluate.eval_depth(sess, va_paths)
            res[tag] = {
                "size_mb": round(os.path.getsize(path) / 1e6, 2),
                "ms_1_thread": ms[1][path],
                "ms_2_threads": ms[2][path],
                "quality": q,
            }
            log(f"depth {tag}: {res[tag]['size_mb']} MB, 2 threads {res[tag]['ms_2_threads'][0]:.2f} ms, "
                f"1 thread {res[tag]['ms_1_thread'][0]:.2f} ms, RMSE {q['rmse_m']} m, delta<1.25 {q['delta_1.25']} "
                f"(n={q['n']})")
        metrics["depth"] = res
        pick(args.models, "fish_depth", res, log)

    if not args.requantize or "torch" not in metrics:  # the training run's torch, not a re-quantisation's
        metrics["torch"] = torch.__version__
    logs = metrics.get("log") if isinstance(metrics.get("log"), dict) else {}
    run = "+".join(st for st in ("det", "depth") if st not in skip) or "none"
    logs[run + (" reexport" if args.reexport else " requantize" if args.requantize else "")] = log_lines
    metrics["log"] = logs
    with open(metrics_path, "w") as f:
        json.dump(metrics, f, indent=1)
    log(f"done in {time.time() - t0:.0f} s; metrics in {metrics_path}")
    if os.path.abspath(args.models) == os.path.abspath(os.path.join(HERE, "..", "models")):
        import cards

        cards.main_with(metrics)


def quantize_and_time(models, stem, fp32, calib, input_name, res, **quant_args):
    """Writes <stem>_int8_u8s8.onnx and <stem>_int8_s8s8.onnx from `fp32`, records in `res` how many
    upsamples each had rewritten and where and how the files were timed; returns {tag: path} of the
    three files and their timings {threads: {path: (median, p90) ms}}, the files taking turns."""
    for tag, act in (("u8s8", QuantType.QUInt8), ("s8s8", QuantType.QInt8)):
        out = os.path.join(models, f"{stem}_int8_{tag}.onnx")
        res[f"int8_{tag}_upsamples_rewritten"] = quant.quantize(fp32, out, calib, input_name, act, **quant_args)
    res["timed_on"], res["timing"] = evaluate.cpu_name(), evaluate.TIMING
    paths = {tag: os.path.join(models, f"{stem}_{tag}.onnx") for tag in ("fp32", "int8_u8s8", "int8_s8s8")}
    return paths, {th: evaluate.time_models(list(paths.values()), th) for th in (1, 2)}


# What a measurement re-computes; everything else in a model's metrics is its training record.
MEASURED_KEYS = ("fp32", "int8_u8s8", "int8_s8s8", "int8_kept", "float_stem", "timed_on", "timing",
                 "int8_u8s8_upsamples_rewritten", "int8_s8s8_upsamples_rewritten")


def training_record(metrics, key, fp32, log):
    """For --requantize: the training record of the fp32 file already in place (from the metrics of
    the run that trained it), without the measurements that are about to be repeated."""
    if not os.path.exists(fp32):
        raise SystemExit(f"--requantize: {fp32} does not exist (train it first)")
    if key not in metrics or "train_seconds" not in metrics[key]:
        raise SystemExit(f"--requantize: the metrics file has no training record for the {key} ({fp32})")
    dims = [d.dim_value for d in onnx.load(fp32).graph.input[0].type.tensor_type.shape.dim]
    if dims[2:] != [data.NET_H, data.NET_W]:
        raise SystemExit(f"--requantize: {fp32} takes {dims[3]}x{dims[2]} input but FME_NET gives "
                         f"{data.NET_W}x{data.NET_H}; run with FME_NET={dims[3]}x{dims[2]}")
    log(f"{key}: re-quantising {fp32} (not trained again; training record kept)")
    return {k: v for k, v in metrics[key].items() if k not in MEASURED_KEYS}


def seeds_of(paths):
    seeds = sorted(int(json.load(open(os.path.join(s, "meta.json"))).get("seed", -1)) for s in paths)
    return f"{seeds[0]}..{seeds[-1]}" if seeds else "none"


def pick(models, stem, res, log):
    """Keeps the faster int8 variant (2 threads) as <stem>_int8.onnx; removes the other."""
    a, b = res["int8_u8s8"], res["int8_s8s8"]
    tag = "u8s8" if a["ms_2_threads"][0] <= b["ms_2_threads"][0] else "s8s8"
    shutil.copyfile(os.path.join(models, f"{stem}_int8_{tag}.onnx"), os.path.join(models, f"{stem}_int8.onnx"))
    for t in ("u8s8", "s8s8"):
        os.remove(os.path.join(models, f"{stem}_int8_{t}.onnx"))
    res["int8_kept"] = tag
    log(f"{stem}: kept int8 {tag}")


def run_log():
    """The recipes' log: `log(msg)` prints at once and keeps the line for metrics.json's "log"."""
    lines = []

    def log(msg):
        print(msg, flush=True)
        lines.append(msg)

    return log, lines


def finish(out, stem, res, log, log_lines, t0, then=None):
    """The recipes' common end: keeps the faster int8 variant, runs `then()` (a last step on the kept
    pair), writes OUT/metrics.json (with the torch version and the log) and logs where the files are."""
    pick(out, stem, res, log)
    if then is not None:
        then()
    res["torch"] = torch.__version__
    res["log"] = log_lines
    with open(os.path.join(out, "metrics.json"), "w") as f:
        json.dump(res, f, indent=1)
    log(f"done in {time.time() - t0:.0f} s: {stem}_fp32.onnx, {stem}_int8.onnx ({res['int8_kept']}), metrics.json "
        f"in {out}")


if __name__ == "__main__":
    main()
