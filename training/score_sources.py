#!/usr/bin/env python3
"""P / R of a detector ONNX file on each real source's held-out split (real.py) and on the renders'
held-out sequences, the way train_real.py scores its own output (fme's letterbox, NMS 0.5, IoU 0.5):

    FME_NET=480x288 python score_sources.py ../models/fish_det_int8.onnx [--real DIR] [--renders DATA/val]
        [--close-renders DATA/close-val]
"""
import argparse
import os

import data
import real
from train_real import VAL_EVERY, per_source_quality

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("--real", default=os.environ.get("REAL_DATA", os.path.join(HERE, "..", "..", "shared", "realfish", "train")))
    ap.add_argument("--renders", default="/tmp/fme-train-data/val", help="held-out render sequences ('' : none)")
    ap.add_argument("--close-renders", default="/tmp/fme-train-data/close-val",
                    help="held-out close-fish render sequences (render.sh gen_close; '' or absent: none)")
    ap.add_argument("--nms-iou", type=float, default=0.5)
    args = ap.parse_args()
    val = real.load_pool(args.real, "val")
    if args.renders:
        images, boxes, _, _ = data.load_many(args.renders, every=VAL_EVERY["renders"], with_depth=False)
        val["renders"] = (images, boxes)
    if args.close_renders and os.path.isdir(args.close_renders):
        images, boxes, _, _ = data.load_many(args.close_renders, every=VAL_EVERY["renders-close"], with_depth=False)
        val["renders-close"] = (images, boxes)
    per_source_quality(args.model, val, args.nms_iou, print, os.path.basename(args.model))

if __name__ == "__main__":
    main()
