#!/usr/bin/env python3
"""Fine-tunes the depth network so that it holds on real frames (docs/training.md "Depth on real
frames"; `make -C training depth-real`):

    python train_depth_real.py --synth DATA --real ../../shared/realfish/train --out DIR [--budget-s S]
    python train_depth_real.py ... --scratch            # random weights instead of the bundled network

The network was trained only on renders, and on real footage it orders fish against their box sizes.
There is no depth truth for real images, but within one image a fish whose box is clearly longer is
most likely nearer. So each step mixes two losses:
- the renders' loss (depth.ssi_loss with the focus term, on the data train.py uses), with a share of
  the renders given a "real look" (colour cast, haze, blur, noise: `real_look`), which keeps the
  metric depth fme fits on the reference cubes;
- a pairwise ranking loss on the real labelled images (real.py's pool, its training split): for two
  fish of one image, both inside the frame, whose long sides differ by at least --ratio, the log
  inverse depth (3x3 mean at the map pixel of each box centre) at the longer one should exceed the
  shorter one's by --margin (a smooth hinge: temp * softplus((margin - d) / temp)). Weight --rank-weight.

Reports fme's depth consistency (training/consistency.py) on each real source's held-out split and on
held-out renders, and the renders' metric RMSE / delta<1.25 after the reference fit (evaluate.eval_depth),
for the bundled files and the new ones, fp32 and int8. Writes OUT/fish_depth_fp32.onnx,
OUT/fish_depth_int8.onnx and OUT/metrics.json. Never reads the evaluation sequence mf25-seq2.
"""
import os

os.environ.setdefault("FME_NET", "480x288")  # before `data` reads it: the bundled depth network's input

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

import consistency  # noqa: E402
import data  # noqa: E402
import depth  # noqa: E402
import evaluate  # noqa: E402
import real  # noqa: E402
from det import lr_at, train_forward, use_bf16  # noqa: E402
from score_depth import held_out_sets  # noqa: E402
from train import finish, quantize_and_time, run_log  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
EVAL_SEQUENCE = "mf25-seq2"


def pairs_of(fish, ratio):
    """[P, 2] index pairs (longer, shorter) of one image's fish whose long sides differ by >= ratio."""
    long = fish[:, 2]
    a, b = np.nonzero(long[:, None] >= ratio * long[None, :])
    return np.stack([a, b], 1).astype(np.int64)


def real_training_set(root, ratio, limit, log):
    """The pool's training split as (images, fish, pairs), only images with at least one pair."""
    imgs, fish, pairs, counts = [], [], [], {}
    for source, (im, fs) in consistency.load_real(root, "train", min_boxes=2, limit=limit).items():
        kept = 0
        for i, f in enumerate(fs):
            p = pairs_of(f, ratio)
            if len(p):
                imgs.append(im[i])
                fish.append(f)
                pairs.append(p)
                kept += 1
        counts[source] = kept
    log(f"real: {sum(counts.values())} training images with a pair of fish >= {ratio}x apart in length "
        f"({', '.join(f'{k} {v}' for k, v in counts.items())}), {sum(len(p) for p in pairs)} pairs")
    return real.stacked(imgs), fish, pairs, counts


def real_look(im, rng):
    """A render made to look more like underwater camera footage: a colour cast (per-channel gains),
    haze towards a water colour, a slight blur and sensor noise. float32 [H, W, 3] in, out."""
    im = im * rng.uniform(0.75, 1.15, 3).astype(np.float32)
    water = rng.uniform([20, 60, 50], [90, 150, 140]).astype(np.float32)
    a = rng.uniform(0.0, 0.35)
    im = (1 - a) * im + a * water
    s = rng.uniform(0.0, 1.3)
    if s > 0.3:
        im = cv2.GaussianBlur(im, (0, 0), s)
    return im + rng.normal(0, rng.uniform(0, 6), im.shape).astype(np.float32)


def jitter(im, rng):
    """Brightness and contrast jitter (as depth.train), on a float image, clipped to [0, 255]."""
    return np.clip(im * rng.uniform(0.85, 1.15) + rng.uniform(-10, 10), 0, 255)


def synth_batch(idx, images, depth_m, focus, rng, look):
    """Network inputs, disparity, valid mask and focus map of render frames `idx` (flipped at random;
    a share `look` through `real_look`)."""
    xs, ds, fs = [], [], []
    for j in idx:
        im, d = images[j].astype(np.float32), depth_m[j]
        f = focus[j] if focus is not None else None
        if rng.random() < 0.5:
            im, d = im[:, ::-1], d[:, ::-1]
            f = f[:, ::-1] if f is not None else None
        if rng.random() < look:
            im = real_look(np.ascontiguousarray(im), rng)
        xs.append(depth.to_input(jitter(im, rng)))
        ds.append(np.ascontiguousarray(d))
        if f is not None:
            fs.append(np.ascontiguousarray(f))
    z = torch.from_numpy(np.stack(ds))
    mask = z > 0.05
    disp = torch.where(mask, 1.0 / z.clamp(min=0.05), torch.zeros_like(z))
    return np.stack(xs), disp, mask, (torch.from_numpy(np.stack(fs)) if fs else None)


def real_batch(idx, images, fish, rng):
    """Network inputs and fish (centres in map pixels, mirrored with the image) of real images `idx`."""
    mw = data.NET_W // 2
    xs, fs = [], []
    for j in idx:
        im, f = images[j].astype(np.float32), fish[j]
        if rng.random() < 0.5:
            im, f = im[:, ::-1], f.copy()
            f[:, 0] = mw - f[:, 0]
        xs.append(depth.to_input(jitter(im, rng)))
        fs.append(f)
    return np.stack(xs), fs


def rank_loss(pred, fish, pairs, margin, temp):
    """Mean over images of the pairs' smooth hinge on the log inverse depth difference (longer fish
    minus shorter), each fish read as the 3x3 mean around its centre's map pixel. Also returns the
    share of pairs in the right order (a training-time check)."""
    lp = torch.log(pred.clamp(min=1e-4))[:, None]
    lp = F.avg_pool2d(lp, 3, 1, 1, count_include_pad=False)[:, 0]
    h, w = lp.shape[1:]
    losses, right, total = [], 0, 0
    for k, (f, p) in enumerate(zip(fish, pairs)):
        x = torch.from_numpy(np.clip(f[:, 0].astype(np.int64), 0, w - 1))
        y = torch.from_numpy(np.clip(f[:, 1].astype(np.int64), 0, h - 1))
        s = lp[k, y, x]
        d = s[p[:, 0]] - s[p[:, 1]]
        losses.append((temp * F.softplus((margin - d) / temp)).mean())
        right += int((d > 0).sum())
        total += len(d)
    return torch.stack(losses).mean(), right / max(total, 1)


def cycle(n, rng):
    """Endless shuffled indices 0..n-1 (a new permutation each pass)."""
    while True:
        yield from rng.permutation(n)


def train(model, synth, real_set, args, log, fine_tune):
    """The mixed-loss loop: per step a batch of renders and one of real images in one forward pass.
    The schedule (det.lr_at) runs over --epochs of the renders or the time budget, whichever ends first.
    Returns the number of steps run."""
    images, depth_m, focus = synth
    r_images, r_fish, r_pairs = real_set
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    model = model.to(memory_format=torch.channels_last)
    bf16 = use_bf16()
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    n, bs, br = len(images), args.batch, args.real_batch if len(r_images) else 0
    steps = args.epochs * math.ceil(n / bs)
    real_idx = cycle(len(r_images), rng) if br else None
    log(f"train: {'fine-tune (norms frozen)' if fine_tune else 'from scratch'}, {'bf16' if bf16 else 'fp32'}, "
        f"{bs} renders + {br} real images a step, lr {args.lr}, rank weight {args.rank_weight}, "
        f"budget {args.budget_s} s or {steps} steps")
    t0, step, frac = time.time(), 0, lr_at(opt, args.lr, 0.0, 0.0, args.budget_s)
    while frac < 1.0:
        model.train()
        if fine_tune:
            depth.freeze_norms(model)
        sums = np.zeros(4)
        perm = rng.permutation(n)
        for i in range(0, n, bs):
            xs, disp, mask, fm = synth_batch(perm[i:i + bs], images, depth_m, focus, rng, args.real_look)
            if br:
                idx = [next(real_idx) for _ in range(br)]
                xr, fr = real_batch(idx, r_images, r_fish, rng)
                xs = np.concatenate([xs, xr])
            pred = train_forward(model, torch.from_numpy(xs), bf16)
            l_s = depth.ssi_loss(pred[:len(disp)], disp, mask, focus=fm, focus_weight=args.focus)
            l_r, right = rank_loss(pred[len(disp):], fr, [r_pairs[j] for j in idx], args.margin, args.temp) \
                if br else (torch.zeros(()), 0.0)
            loss = l_s + args.rank_weight * l_r
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            sums += (l_s.item(), l_r.item(), right, 1)
            frac = lr_at(opt, args.lr, step / steps, time.time() - t0, args.budget_s)
            if frac >= 1.0:
                break
        k = max(sums[3], 1)
        log(f"step {step}: renders loss {sums[0] / k:.4f}, rank loss {sums[1] / k:.4f}, real pairs in order "
            f"{sums[2] / k:.3f} ({time.time() - t0:.0f} s)")
    model.eval()
    return step


def load_synth(args, log):
    """The renders train.py's depth stage uses: DATA/train frames, depth maps and focus masks."""
    images, boxes, depth_m, seqs = data.load_many(os.path.join(args.synth, "train"), every=args.every,
                                                  with_depth=True, limit=args.synth_seqs)
    focus = None
    if args.focus > 0:
        refs = [s["refs"] for s in seqs for _ in s["frames"]]
        focus = depth.focus_masks(boxes, refs, depth_m.shape[1:], (data.NET_H, data.NET_W))
    log(f"renders: {len(images)} training frames from {len(seqs)} sequences")
    return (images, depth_m, focus), len(seqs)


def check_input(path):
    """Stops unless `path` takes the FME_NET input this run trains at."""
    import onnx

    dims = [d.dim_value for d in onnx.load(path).graph.input[0].type.tensor_type.shape.dim]
    if dims[2:] != [data.NET_H, data.NET_W]:
        raise SystemExit(f"{path} takes {dims[3]}x{dims[2]} input but FME_NET gives {data.NET_W}x{data.NET_H}; "
                         f"run with FME_NET={dims[3]}x{dims[2]}")


def measure(paths, sets, val_seqs, log, tag):
    """{file tag: {"consistency": ..., "renders_metric": ...}} of ONNX files (fme's consistency per set,
    eval_depth's RMSE / delta<1.25 on the held-out renders after the reference fit)."""
    out = {}
    for t, p in paths.items():
        out[t] = {"consistency": consistency.score_file(p, sets, log, f"{tag} {t}")}
        if val_seqs:
            q = evaluate.eval_depth(evaluate.session(p), val_seqs)
            out[t]["renders_metric"] = q
            log(f"{tag} {t}: renders RMSE {q['rmse_m']:.3f} m, delta<1.25 {q['delta_1.25']:.3f} (n={q['n']})")
    return out


def parse_args():
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", default=os.environ.get("REAL_DATA", os.path.join(HERE, "..", "..", "shared", "realfish", "train")))
    ap.add_argument("--synth", default="/tmp/fme-train-data", help="folder with train/ and val/ fme sequences")
    ap.add_argument("--synth-seqs", type=int, default=240, help="training render sequences used (0: all)")
    ap.add_argument("--every", type=int, default=3, help="every n-th frame of the training renders")
    ap.add_argument("--out", required=True)
    ap.add_argument("--base", default=os.path.join(HERE, "..", "models", "fish_depth_fp32.onnx"),
                    help="fp32 depth network to start from (and to report as 'before')")
    ap.add_argument("--base-int8", default=os.path.join(HERE, "..", "models", "fish_depth_int8.onnx"))
    ap.add_argument("--scratch", action="store_true", help="start from random weights instead of --base")
    ap.add_argument("--rank-weight", type=float, default=1.0, help="weight of the real images' ranking loss")
    ap.add_argument("--ratio", type=float, default=1.4, help="long-side ratio that makes a pair")
    ap.add_argument("--margin", type=float, default=0.05, help="wanted log inverse depth difference of a pair")
    ap.add_argument("--temp", type=float, default=0.05, help="smoothness of the ranking hinge")
    ap.add_argument("--focus", type=float, default=depth.FOCUS_WEIGHT, help="renders' focus term weight")
    ap.add_argument("--real-look", type=float, default=0.5, help="share of renders given real_look")
    ap.add_argument("--batch", type=int, default=8, help="renders a step")
    ap.add_argument("--real-batch", type=int, default=8, help="real images a step (0: renders only)")
    ap.add_argument("--epochs", type=int, default=30, help="passes over the renders at most")
    ap.add_argument("--budget-s", type=float, default=1800)
    ap.add_argument("--lr", type=float, default=None, help="default 3e-4 (2e-3 with --scratch)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--limit", type=int, default=0, help="at most N images per real source and N render "
                                                          "sequences (smoke tests)")
    args = ap.parse_args()
    if EVAL_SEQUENCE in os.path.realpath(args.real).split(os.sep):
        raise SystemExit(f"--real {args.real}: {EVAL_SEQUENCE} is the evaluation sequence, never training data")
    if args.lr is None:
        args.lr = 2e-3 if args.scratch else 3e-4
    if args.limit:
        args.synth_seqs = min(args.synth_seqs or args.limit, args.limit)
    return args


def main():
    args = parse_args()
    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    log, log_lines = run_log()

    t0 = time.time()
    check_input(args.base)
    synth, n_seqs = load_synth(args, log)
    r_images, r_fish, r_pairs, r_counts = real_training_set(args.real, args.ratio, args.limit, log)
    sets = held_out_sets(args.real, os.path.join(args.synth, "val"), args.limit)
    val_seqs = data.list_sequences(os.path.join(args.synth, "val"))[:args.limit or None]
    log("held out: " + ", ".join(f"{k} {len(v[0])}" for k, v in sets.items()) + f" ({time.time() - t0:.0f} s)")
    before = measure({"fp32": args.base, "int8": args.base_int8}, sets, val_seqs, log, "before")

    model = depth.FishDepth() if args.scratch else depth.from_onnx(args.base)
    t1 = time.time()
    steps = train(model, synth, (r_images, r_fish, r_pairs), args, log, fine_tune=not args.scratch)
    train_s = time.time() - t1
    fp32 = os.path.join(args.out, "fish_depth_fp32.onnx")
    depth.export(model, fp32, data.NET_H, data.NET_W)

    # Calibration on renders and real frames alike: the int8 file runs on real footage.
    rng = np.random.default_rng(1)
    calib = [depth.to_input(synth[0][i]) for i in rng.choice(len(synth[0]), min(32, len(synth[0])), replace=False)]
    if len(r_images):
        calib += [depth.to_input(r_images[i]) for i in rng.choice(len(r_images), min(32, len(r_images)), replace=False)]
    res = {"train_seconds": round(train_s, 1), "steps": steps, "init": "scratch" if args.scratch else
           os.path.basename(args.base), "input": [data.NET_W, data.NET_H], "autocast": "bf16" if use_bf16() else "fp32",
           "args": {k: v for k, v in vars(args).items() if k not in ("out",)},
           "data": {"render_sequences": n_seqs, "render_frames": int(len(synth[0])), "real_train": r_counts,
                    "real_pairs": int(sum(len(p) for p in r_pairs)),
                    "held_out": {k: len(v[0]) for k, v in sets.items()}, "excluded": sorted(real.EXCLUDED),
                    "held_out_percent": real.HELD_OUT_PERCENT},
           "before": before}
    paths, ms = quantize_and_time(args.out, "fish_depth", fp32, calib, "image", res)
    after = measure(paths, sets, val_seqs, log, "after")
    for tag, path in paths.items():
        res[tag] = dict(after[tag], size_mb=round(os.path.getsize(path) / 1e6, 2), ms_1_thread=ms[1][path],
                        ms_2_threads=ms[2][path])
    finish(args.out, "fish_depth", res, log, log_lines, t0)


if __name__ == "__main__":
    main()
