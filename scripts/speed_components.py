#!/usr/bin/env python3
"""Splits the swarm-speed error of an `fme eval --boxes gt --tracks FILE.csv` run into its lateral
part (box motion scaled by the fitted depth) and its along-ray part (the change of depth).

Each fish's 1 s chord in camera coordinates, P = z * (x, y, 1), is
    P1 - P0 = zbar * (r1 - r0) + (z1 - z0) * rbar     (zbar, rbar: means of the two ends),
so the chord can be rebuilt with the estimated or the true depth in either term. Truth comes from
the sequence's gt/world.csv (needs ground-truth ids, so `--boxes gt`). Rows printed, swarm speed per
frame against the true mean |v| of the visible fish half a span earlier:
    as estimated        both terms from fme's depth (should match fme eval's RMSE closely)
    true depth          both terms from the true camera z
    est. lateral term   fme's depth in the lateral term, the true depth change
    est. depth change   the true depth in the lateral term, fme's depth change
    no depth change     fme's lateral term alone (what the along-ray motion is worth)

Usage: python3 scripts/speed_components.py SEQUENCE_DIR TRACKS.csv [SPAN_S]   (standard library only)
"""
import csv
import json
import math
import sys


def main():
    seq, tracks_csv = sys.argv[1], sys.argv[2]
    span = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
    meta = json.load(open(f"{seq}/meta.json"))
    cam = meta["camera"]
    rot, tr = cam["world_to_camera"]["rotation"], cam["world_to_camera"]["translation"]
    fx, fy, cx, cy, fps = cam["fx"], cam["fy"], cam["cx"], cam["cy"], meta["fps"]
    if any(cam.get("distortion", [])):
        sys.exit(f"{seq}/meta.json: the camera has lens distortion {cam['distortion']}; this script assumes none")

    true_z, speeds = {}, {}
    for r in csv.DictReader(open(f"{seq}/gt/world.csv")):
        p = [float(r[k]) for k in "xyz"]
        z = sum(rot[2][i] * p[i] for i in range(3)) + tr[2]
        frame, fid = int(r["frame"]), int(r["id"])
        true_z[(frame, fid)] = z
        if float(r["visibility"]) > 0:
            speeds.setdefault(frame, []).append(math.sqrt(sum(float(r[k]) ** 2 for k in ("vx", "vy", "vz"))))
    true_mean = {f: sum(v) / len(v) for f, v in speeds.items()}

    rows = {}
    for r in csv.DictReader(open(tracks_csv)):
        if r["depth_m"]:
            rows.setdefault(int(r["id"]), []).append(
                (int(r["frame"]), float(r["t"]), float(r["u"]), float(r["v"]), float(r["depth_m"])))

    names = ["as estimated", "true depth", "est. lateral term", "est. depth change", "no depth change"]
    per_frame = {n: {} for n in names}
    for fid, track in rows.items():
        track.sort()
        for k, (f1, t1, u1, v1, z1) in enumerate(track):
            j = k
            while j > 0 and t1 - track[j - 1][1] <= span + 1e-9:
                j -= 1
            f0, t0, u0, v0, z0 = track[j]
            if j == k or (f0, fid) not in true_z or (f1, fid) not in true_z:
                continue
            r0 = ((u0 - cx) / fx, (v0 - cy) / fy, 1.0)
            r1 = ((u1 - cx) / fx, (v1 - cy) / fy, 1.0)
            dt = t1 - t0

            def speed(zbar, dz):
                return math.sqrt(sum((zbar * (r1[i] - r0[i]) + dz * 0.5 * (r0[i] + r1[i])) ** 2 for i in range(3))) / dt

            tz0, tz1 = true_z[(f0, fid)], true_z[(f1, fid)]
            for name, s in zip(names, (speed(0.5 * (z0 + z1), z1 - z0), speed(0.5 * (tz0 + tz1), tz1 - tz0),
                                       speed(0.5 * (z0 + z1), tz1 - tz0), speed(0.5 * (tz0 + tz1), z1 - z0),
                                       speed(0.5 * (z0 + z1), 0.0))):
                per_frame[name].setdefault(f1, []).append(s)

    lag = round(span * fps / 2)
    print(f"{'chord built from':20s} {'RMSE m/s':>9s} {'bias':>8s} {'slope':>6s} {'offset':>7s}")
    for name in names:
        pairs = [(sum(v) / len(v), true_mean[f - lag]) for f, v in sorted(per_frame[name].items()) if f - lag in true_mean]
        if len(pairs) < 2:
            print(f"{name:20s} too few frames")
            continue
        n = len(pairs)
        e = [p[0] for p in pairs]
        t = [p[1] for p in pairs]
        rmse = math.sqrt(sum((a - b) ** 2 for a, b in pairs) / n)
        bias = sum(a - b for a, b in pairs) / n
        tm, em = sum(t) / n, sum(e) / n
        stt = sum((x - tm) ** 2 for x in t)
        slope = sum((x - tm) * (y - em) for x, y in zip(t, e)) / stt if stt > 0 else float("nan")
        print(f"{name:20s} {rmse:9.4f} {bias:+8.4f} {slope:6.2f} {em - slope * tm:+7.3f}")


if __name__ == "__main__":
    main()
