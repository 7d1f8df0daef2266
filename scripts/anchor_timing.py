#!/usr/bin/env python3
"""Times the reference models beside fme's bundled int8 networks, turn by turn, on this machine.

The speed targets (detector <= 5 ms, depth <= 10 ms, int8, 2 threads) were set beside anchors
measured on another machine (../shared/research/onnx-timings.md: a 2-vCPU Sapphire Rapids KVM guest,
ONNX Runtime 1.31.1, default session options). Those anchors are rebuilt here the same way (YOLO11n
with nc=1 from Ultralytics' yolo11n.yaml, random weights, opset 17, at 320 and 640; the 320 one
quantised U8S8 QDQ per channel, MinMax on 20 random frames, the DFL/decode tail in float) and take
turns with the bundled files, round by round, so a slow spell of a shared machine falls on all rows
alike (each turn starts after a 60 ms pause and two untimed runs). Anchors run with ONNX Runtime's
default options (worker threads spinning), as measured there; fme's networks both as fme runs them
(workers sleeping) and spinning.

Printed: each row's median / 10th / 90th percentile (ms), each anchor's ratio to its published time,
and fme's networks divided by the U8S8 anchor's ratio (the nearest kind of work: uint8 convolutions)
as an estimate of their time on the anchors' machine. CPU steal (/proc/stat) over each thread count's
rounds is printed too. Needs training/requirements.txt (scripts/anchor_timing.sh makes the venv).
"""
import argparse
import json
import os
import shutil
import sys
import tempfile
import time

import numpy as np
import onnxruntime as ort

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "training"))
import evaluate  # noqa: E402  (training/: session options and the timing input, as the model cards use)

# ms, median of 50 runs after 5 warm-ups, onnx-timings.md (YOLO11n nc=1 rows).
ANCHORS = {("yolo11n_320_fp32", 2): 9.55, ("yolo11n_320_fp32", 1): 15.2,
           ("yolo11n_640_fp32", 2): 37.3, ("yolo11n_640_fp32", 1): 62.7,
           ("yolo11n_320_u8s8", 2): 7.52, ("yolo11n_320_u8s8", 1): 9.96}


def export_anchors(out):
    """The three anchor files in `out`, exported and quantised on the first run and kept for the next ones."""
    out = os.path.abspath(out)
    paths = {n: os.path.join(out, f"{n}.onnx") for n in ("yolo11n_320_fp32", "yolo11n_640_fp32", "yolo11n_320_u8s8")}
    if all(os.path.exists(p) for p in paths.values()):
        return paths
    import torch
    import ultralytics
    from ultralytics import YOLO

    import quant

    os.makedirs(out, exist_ok=True)
    cfg = open(os.path.join(os.path.dirname(ultralytics.__file__), "cfg/models/11/yolo11.yaml")).read()
    if "nc: 80" not in cfg:
        raise SystemExit("anchor_timing: Ultralytics' yolo11.yaml has no 'nc: 80' line to set to 1")
    torch.manual_seed(0)
    here = os.getcwd()
    with tempfile.TemporaryDirectory() as work:
        # The file name carries the scale ("n"); Ultralytics writes its export into the working directory.
        os.chdir(work)
        try:
            with open("yolo11n.yaml", "w") as f:
                f.write(cfg.replace("nc: 80", "nc: 1"))
            for size in (320, 640):
                shutil.move(YOLO("yolo11n.yaml").export(format="onnx", imgsz=size, dynamic=False, simplify=True,
                                                        opset=17), paths[f"yolo11n_{size}_fp32"])
        finally:
            os.chdir(here)
    rng = np.random.default_rng(0)
    calib = [rng.random((3, 320, 320), dtype=np.float32) for _ in range(20)]
    name = evaluate.session(paths["yolo11n_320_fp32"]).get_inputs()[0].name
    quant.quantize(paths["yolo11n_320_fp32"], paths["yolo11n_320_u8s8"], calib, name, upsample_rewrite=False)
    return paths


def steal_and_total():
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return v[7], sum(v)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="/tmp/fme-anchors", help="folder for the anchor ONNX files")
    ap.add_argument("--models", default=os.path.join(ROOT, "models"), help="folder with fme's int8 files")
    ap.add_argument("--rounds", type=int, default=12)
    ap.add_argument("--runs", type=int, default=10, help="runs per row and round (the 640 anchor: a third)")
    ap.add_argument("--json", help="also write the results here")
    a = ap.parse_args()
    anchors = export_anchors(a.out)
    rows = [(n, p, True) for n, p in anchors.items()]
    for net in ("fish_det", "fish_depth"):
        p = os.path.join(a.models, f"{net}_int8.onnx")
        if not os.path.exists(p):
            raise SystemExit(f"anchor_timing: {p} not found")
        rows += [(f"{net}_int8", p, False), (f"{net}_int8_spinning", p, True)]
    result = {"cpu": evaluate.cpu_name(), "ort": ort.__version__, "rounds": a.rounds, "runs": a.runs, "threads": {}}
    print(f"{evaluate.cpu_name()}, ONNX Runtime {ort.__version__}")
    for threads in (2, 1):
        sessions = []
        for n, p, spin in rows:
            s = evaluate.session(p, threads, spin)
            sessions.append((n, s, evaluate.random_feed(s)))
        for _, s, feed in sessions:
            for _ in range(5):
                s.run(None, feed)
        ts = {n: [] for n, _, _ in sessions}
        st0, tot0 = steal_and_total()
        for _ in range(a.rounds):
            for n, s, feed in sessions:
                # A spinning session's worker keeps a vCPU busy for ~40 ms after its last run (measured here),
                # which slowed the next row's 2-thread runs by a fifth: let it stop. The first runs after a
                # pause wake the idle vCPU and are not timed either.
                time.sleep(0.06)
                for _ in range(2):
                    s.run(None, feed)
                for _ in range(max(1, a.runs // 3) if "640" in n else a.runs):
                    t0 = time.perf_counter()
                    s.run(None, feed)
                    ts[n].append((time.perf_counter() - t0) * 1e3)
        st1, tot1 = steal_and_total()
        stats = {n: {"median": float(np.median(t)), "p10": float(np.percentile(t, 10)),
                     "p90": float(np.percentile(t, 90))} for n, t in ts.items()}
        for (n, th), ms in ANCHORS.items():
            if th == threads:
                stats[n]["published"] = ms
                stats[n]["ratio"] = stats[n]["median"] / ms
        u8 = stats["yolo11n_320_u8s8"]["ratio"]
        for n in stats:
            if n.startswith("fish_"):
                stats[n]["at_anchor_machine"] = stats[n]["median"] / u8
        steal = 100.0 * (st1 - st0) / max(1, tot1 - tot0)
        result["threads"][threads] = {"rows": stats, "steal_pct": steal}
        print(f"{threads} thread(s), {a.rounds} rounds, CPU steal {steal:.1f}%")
        for n, s in stats.items():
            extra = (f"  published {s['published']:.2f}, ratio {s['ratio']:.2f}" if "ratio" in s
                     else f"  / u8s8 ratio = {s['at_anchor_machine']:.2f}")
            print(f"  {n:26s} {s['median']:7.2f} ms (p10 {s['p10']:.2f}, p90 {s['p90']:.2f}){extra}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
