#!/usr/bin/env python3
"""Per-frame cost of detector layouts against the bundled int8 detector, measured in the same run
(evaluate.time_models: the files take turns, so a busy machine slows all alike).

    FME_NET=480x288 python cost.py --arch mnv2 [--arch mnv2_sep] [--files A_int8.onnx ...] [--threads 1 2]

Each --arch is exported with its initial weights (random neck and head; the cost does not depend on
the values) and quantised as the recipes do (quant.quantize, u8s8, float stem), on random calibration
frames; --files are timed as they are. Prints ms (median, p90) and the ratio to models/fish_det_int8.onnx.
"""
import argparse
import os
import tempfile

import numpy as np
import torch

import data
import det
import evaluate
import quant

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--arch", action="append", default=[])
    ap.add_argument("--files", nargs="*", default=[])
    ap.add_argument("--bundled", default=os.path.join(HERE, "..", "models", "fish_det_int8.onnx"))
    ap.add_argument("--threads", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=evaluate.ROUNDS)
    args = ap.parse_args()
    torch.set_num_threads(1)
    tmp = tempfile.mkdtemp(prefix="fme-cost-")
    paths = [os.path.abspath(args.bundled)]
    rng = np.random.default_rng(0)
    calib = [rng.random((3, data.NET_H, data.NET_W), dtype=np.float32) for _ in range(8)]
    for arch in args.arch:
        model = det.build(arch, 2).eval()
        fp32 = os.path.join(tmp, f"{arch}_fp32.onnx")
        det.export(model, fp32, data.NET_H, data.NET_W)
        int8 = os.path.join(tmp, f"{arch}_int8.onnx")
        quant.quantize(fp32, int8, calib, "images", float_stem=True)
        print(f"{arch}: {sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters, {int8}", flush=True)
        paths += [fp32, int8]
    paths += [os.path.abspath(f) for f in args.files]
    for th in args.threads:
        ms = evaluate.time_models(paths, th, rounds=args.rounds)
        base = ms[paths[0]][0]
        for p in paths:
            print(f"{th} thread(s): {p}: {ms[p][0]:.2f} ms (p90 {ms[p][1]:.2f}), {ms[p][0] / base:.2f}x bundled int8",
                  flush=True)


if __name__ == "__main__":
    main()
