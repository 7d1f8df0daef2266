#!/usr/bin/env python3
"""Cross-check fme's MOT metrics against py-motmetrics 1.4.0 on its bundled TUD files.

Usage: /tmp/venv-mm/bin/python scripts/check_motmetrics.py [path/to/fme]
(venv outside the repo: python3 -m venv /tmp/venv-mm && /tmp/venv-mm/bin/pip install
 'motmetrics==1.4.0' 'numpy<2' pandas scipy). The TUD files are read from the installed wheel and
never copied into the project. Exit code 1 if any metric differs by more than 1e-3.
HOTA is checked against TrackEval's HOTA.eval_sequence (PyPI `trackeval==1.3.0` in the same venv:
`pip install trackeval==1.3.0 && pip install 'numpy<2'`, since motmetrics 1.4.0 needs numpy<2;
skipped with a note when it is not installed) on the same files, with IoU similarity.
"""
import json
import os
import subprocess
import sys

import motmetrics as mm
import numpy as np


def trackeval_hota(gt_path, hyp_path):
    """HOTA, DetA, AssA of TrackEval on raw MOT files (no MOTChallenge preprocessing)."""
    from trackeval.datasets._base_dataset import _BaseDataset
    from trackeval.metrics import HOTA

    def load(p):
        rows = np.loadtxt(p, delimiter=",", ndmin=2)
        return rows
    g, h = load(gt_path), load(hyp_path)
    frames = range(1, int(max(g[:, 0].max(), h[:, 0].max())) + 1)
    gmap = {v: i for i, v in enumerate(sorted(set(g[:, 1])))}
    hmap = {v: i for i, v in enumerate(sorted(set(h[:, 1])))}
    data = {"gt_ids": [], "tracker_ids": [], "similarity_scores": []}
    for f in frames:
        gf, hf = g[g[:, 0] == f], h[h[:, 0] == f]
        data["gt_ids"].append(np.array([gmap[v] for v in gf[:, 1]], dtype=int))
        data["tracker_ids"].append(np.array([hmap[v] for v in hf[:, 1]], dtype=int))
        data["similarity_scores"].append(_BaseDataset._calculate_box_ious(gf[:, 2:6], hf[:, 2:6], box_format="xywh"))
    data.update(num_gt_dets=len(g), num_tracker_dets=len(h), num_gt_ids=len(gmap), num_tracker_ids=len(hmap),
                num_timesteps=len(frames))
    res = HOTA().eval_sequence(data)
    return {k: float(np.mean(res[k])) for k in ("HOTA", "DetA", "AssA")}

FME = sys.argv[1] if len(sys.argv) > 1 else "target/release/fme"
DATA = os.path.join(os.path.dirname(mm.__file__), "data")
KEYS = [  # (motmetrics name, fme json key)
    ("mota", "mota"), ("motp", "motp"), ("idf1", "idf1"), ("idp", "idp"), ("idr", "idr"),
    ("recall", "recall"), ("precision", "precision"), ("num_switches", "num_switches"),
    ("num_false_positives", "num_false_positives"), ("num_misses", "num_misses"),
    ("num_objects", "num_objects"), ("mostly_tracked", "mostly_tracked"),
    ("partially_tracked", "partially_tracked"), ("mostly_lost", "mostly_lost"),
    ("num_fragmentations", "num_fragmentations"),
]
worst = 0.0
print(f"{'sequence':16} {'metric':20} {'motmetrics':>12} {'fme':>12} {'diff':>10}")
for seq in ["TUD-Campus", "TUD-Stadtmitte"]:
    gt_path, hyp_path = os.path.join(DATA, seq, "gt.txt"), os.path.join(DATA, seq, "test.txt")
    acc = mm.utils.compare_to_groundtruth(mm.io.loadtxt(gt_path), mm.io.loadtxt(hyp_path), "iou", distth=0.5)
    ref = mm.metrics.create().compute(acc, metrics=[k for k, _ in KEYS], name=seq)
    out = subprocess.run([FME, "track", "--gt", gt_path, "--hyp", hyp_path, "--json"],
                         check=True, capture_output=True, text=True).stdout
    ours = json.loads(out)
    for mk, fk in KEYS:
        a, b = float(ref[mk].iloc[0]), float(ours[fk])
        worst = max(worst, abs(a - b))
        print(f"{seq:16} {mk:20} {a:12.6f} {b:12.6f} {abs(a - b):10.2e}")
try:
    import trackeval  # noqa: F401
    have_te = True
except ImportError:
    have_te = False
    print("trackeval not installed: HOTA not checked")
if have_te:
    for seq in ["TUD-Campus", "TUD-Stadtmitte"]:
        gt_path, hyp_path = os.path.join(DATA, seq, "gt.txt"), os.path.join(DATA, seq, "test.txt")
        ref = trackeval_hota(gt_path, hyp_path)
        ours = json.loads(subprocess.run([FME, "track", "--gt", gt_path, "--hyp", hyp_path, "--json"],
                                         check=True, capture_output=True, text=True).stdout)
        for rk, fk in (("HOTA", "hota"), ("DetA", "deta"), ("AssA", "assa")):
            a, b = ref[rk], float(ours[fk])
            worst = max(worst, abs(a - b))
            print(f"{seq:16} {rk + ' (TrackEval)':20} {a:12.6f} {b:12.6f} {abs(a - b):10.2e}")
print(f"largest difference: {worst:.3e} ({'OK' if worst <= 1e-3 else 'FAIL'}, tolerance 1e-3)")
sys.exit(0 if worst <= 1e-3 else 1)
