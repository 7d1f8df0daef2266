#!/usr/bin/env python3
"""Checks fme's distance correlation against PyPI `dcor` (the reference implementation of
Szekely's statistic) to 1e-9 on a set of vectors: random, nonlinear, constant-free, tied values,
and (optionally) a real `fme eval --series` file.

Setup (outside the repository):  python3 -m venv /tmp/venv-dcor && /tmp/venv-dcor/bin/pip install dcor numpy
Run:  /tmp/venv-dcor/bin/python scripts/check_distcorr.py [SERIES.csv ...]
"""
import csv
import os
import subprocess
import sys
import tempfile

import dcor
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def fme_dcor(x, y):
    with tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False) as f:
        for a, b in zip(x, y):
            f.write(f"{float(a)!r},{float(b)!r}\n")
        path = f.name
    try:
        out = subprocess.run(
            ["cargo", "run", "--quiet", "--example", "distcorr", "--", path],
            cwd=ROOT, check=True, capture_output=True, text=True,
        )
        return float(out.stdout.strip())
    finally:
        os.unlink(path)


def cases():
    rng = np.random.default_rng(12345)
    n = 500
    x = rng.normal(size=n)
    yield "independent normal", x, rng.normal(size=n)
    yield "quadratic + noise", x, x**2 + 0.3 * rng.normal(size=n)
    t = np.linspace(0, 30, 900)
    true = 0.5 + 0.2 * np.sin(t / 3)
    yield "speed-like series", true, true + 0.03 * rng.normal(size=t.size)
    yield "ties", np.round(x, 1), np.round(x**3, 0)
    yield "small n", np.array([1.0, 2.0, 4.0]), np.array([0.5, 0.1, 0.9])


def series_cases(paths):
    for p in paths:
        x, y = [], []
        with open(p) as f:
            for row in csv.DictReader(f):
                if row["true_mps"] and row["activity_mps"]:
                    x.append(float(row["true_mps"]))
                    y.append(float(row["activity_mps"]))
        yield os.path.basename(p), np.array(x), np.array(y)


def main():
    worst = 0.0
    for name, x, y in list(cases()) + list(series_cases(sys.argv[1:])):
        ref = float(dcor.distance_correlation(x, y))
        got = fme_dcor(x, y)
        diff = abs(ref - got)
        worst = max(worst, diff)
        print(f"{name:22s} n={len(x):4d}  dcor={ref:.12f}  fme={got:.12f}  |diff|={diff:.2e}")
    print(f"dcor {dcor.__version__}: worst |diff| = {worst:.2e} (tolerance 1e-9)")
    return 0 if worst <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
