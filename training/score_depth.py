#!/usr/bin/env python3
"""fme's depth consistency (training/consistency.py; `fme eval`'s depth_consistency) of depth ONNX
files on each real source's held-out split (real.py) and on held-out renders, one line per file:

    python score_depth.py ../models/fish_depth_fp32.onnx ../models/fish_depth_int8.onnx [/tmp/fme-depth-real/*.onnx]
        [--real DIR] [--renders DATA/val] [--limit N]

FME_NET defaults to 480x288, the bundled depth network's input. Nothing here reads mf25-seq2.
"""
import os

os.environ.setdefault("FME_NET", "480x288")  # before `data` reads it: the depth network's input size

import argparse  # noqa: E402

import consistency  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def held_out_sets(real_root, renders, limit=0):
    """{name: (images, fish)}: each real source's held-out split, then the held-out renders ('' : none)."""
    sets = consistency.load_real(real_root, "val", limit=limit)
    if renders:
        sets["renders"] = consistency.load_renders(renders, limit=limit)
    return sets


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("models", nargs="+")
    ap.add_argument("--real", default=os.environ.get("REAL_DATA", os.path.join(HERE, "..", "..", "shared", "realfish", "train")))
    ap.add_argument("--renders", default="/tmp/fme-train-data/val", help="held-out render sequences ('': none)")
    ap.add_argument("--limit", type=int, default=0, help="at most N images per source (N render sequences)")
    args = ap.parse_args()
    sets = held_out_sets(args.real, args.renders, args.limit)
    print("held out: " + ", ".join(f"{k} {len(v[0])} images with >= {consistency.MIN_BOXES} fish inside"
                                   for k, v in sets.items()), flush=True)
    for path in args.models:
        consistency.score_file(path, sets, lambda m: print(m, flush=True), path)


if __name__ == "__main__":
    main()
