#!/usr/bin/env python3
"""Cross-check fme's MOT metrics against py-motmetrics 1.4.0 on its bundled TUD files.

Usage: /tmp/venv-mm/bin/python scripts/check_motmetrics.py [path/to/fme]
(venv outside the repo: python3 -m venv /tmp/venv-mm && /tmp/venv-mm/bin/pip install
 'motmetrics==1.4.0' 'numpy<2' pandas scipy). The TUD files are read from the installed wheel and
never copied into the project. Exit code 1 if any metric differs by more than 1e-3.
"""
import json
import os
import subprocess
import sys

import motmetrics as mm

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
print(f"largest difference: {worst:.3e} ({'OK' if worst <= 1e-3 else 'FAIL'}, tolerance 1e-3)")
sys.exit(0 if worst <= 1e-3 else 1)
