#!/usr/bin/env python3
"""Writes tiny fake sequences in the fme sequence layout, only to smoke-test this pipeline's code
paths (`train.sh --smoke`) before/without `fme synth`. Never used for the bundled models."""
import json
import os
import sys

import cv2
import numpy as np


def write_seq(root, seed, frames=6, w=640, h=384, nfish=20):
    rng = np.random.default_rng(seed)
    os.makedirs(os.path.join(root, "img1"), exist_ok=True)
    os.makedirs(os.path.join(root, "gt"), exist_ok=True)
    os.makedirs(os.path.join(root, "depth"), exist_ok=True)
    fx = fy = 500.0
    cx, cy = w / 2, h / 2
    # Camera looks along world +y (world z up): p_cam = R p_world + t.
    R = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    t = [0, 1.5, 0]
    yy, xx = np.mgrid[0:h, 0:w]
    bg_z = 2.0 + 4.0 * (1 - yy / h)
    refs = []
    for i in range(10):
        u, v = rng.uniform(40, w - 40), rng.uniform(h * 0.5, h - 20)
        z = 2.0 + 4.0 * (1 - v / h)
        pc = np.array([(u - cx) * z / fx, (v - cy) * z / fy, z])
        pw = np.array([pc[0], pc[2], -(pc[1] - 1.5)])
        refs.append({"id": i + 1, "size_m": 0.1, "center_w": list(pw), "front_face_center_w": list(pw)})
    fish = [(rng.uniform(60, w - 60), rng.uniform(40, h - 40), rng.uniform(1.5, 5.0), rng.uniform(-3, 3),
             rng.uniform(-2, 2)) for _ in range(nfish)]
    gt, world = [], []
    for f in range(1, frames + 1):
        img = np.stack([20 + 20 * yy / h, 80 + 40 * xx / w, 110 + 30 * yy / h], -1).astype(np.float32)
        z = bg_z.copy()
        for k, (u0, v0, zf, du, dv) in enumerate(sorted(fish, key=lambda q: -q[2])):
            u, v = u0 + du * f, v0 + dv * f
            a, b = 60 / zf, 20 / zf
            m = ((xx - u) / a) ** 2 + ((yy - v) / b) ** 2 < 1
            img[m] = (200 - 15 * zf, 190 - 15 * zf, 170 - 10 * zf)
            z[m] = zf
            gt.append(f"{f},{k + 1},{u - a:.2f},{v - b:.2f},{2 * a:.2f},{2 * b:.2f},1,1,1.0")
            pc = np.array([(u - cx) * zf / fx, (v - cy) * zf / fy, zf])
            world.append(f"{f},{k + 1},{pc[0]:.4f},{pc[2]:.4f},{-(pc[1] - 1.5):.4f},0,0,0,0.5,1.0")
        img += rng.normal(0, 3, img.shape)
        cv2.imwrite(os.path.join(root, "img1", f"{f:06d}.jpg"), np.clip(img, 0, 255).astype(np.uint8)[:, :, ::-1])
        cv2.imwrite(os.path.join(root, "depth", f"{f:06d}.png"), (z * 1000).astype(np.uint16))
    open(os.path.join(root, "gt", "gt.txt"), "w").write("\n".join(gt) + "\n")
    open(os.path.join(root, "gt", "world.csv"), "w").write(
        "frame,id,x,y,z,vx,vy,vz,length_m,visibility\n" + "\n".join(world) + "\n")
    open(os.path.join(root, "seqinfo.ini"), "w").write(
        f"[Sequence]\nname=smoke{seed}\nimDir=img1\nframeRate=30\nseqLength={frames}\nimWidth={w}\nimHeight={h}\n"
        "imExt=.jpg\n")
    meta = {"fps": 30, "width": w, "height": h, "frames": frames, "seed": seed, "preset": "smoke",
            "generator": {"name": "smoke", "version": "0"},
            "camera": {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "distortion": [0] * 5,
                       "world_to_camera": {"rotation": R, "translation": t}},
            "water": {"type": "I"}, "reference_objects": refs}
    json.dump(meta, open(os.path.join(root, "meta.json"), "w"))


if __name__ == "__main__":
    out = sys.argv[1]
    for i in range(4):
        write_seq(os.path.join(out, "train", f"smoke-{i}"), i)
    for i in range(2):
        write_seq(os.path.join(out, "val", f"smoke-v{i}"), 100 + i)
