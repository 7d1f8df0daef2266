#!/usr/bin/env bash
# The development set of the "detections look unlike fish" rule (docs/accuracy.md, "Detections unlike
# fish"): real video clips from ../shared/realfish/train/deepfish turned into temporary MOTChallenge
# folders under OUT (default /tmp/fme-devset), read at measurement time and never copied into the repo.
#   bash scripts/familiarity_devset.sh [OUT]
# A clip is the file-name prefix up to `_fNNNNNN`; its frames are cut into runs where successive frame
# numbers differ by at most 15, and each run of at least 56 frames with fish is one sequence, named
# CLIP_fSTART. Frames are numbered consecutively (a dropped frame shortens the time a little), and the
# frame rate is 25 Hz: an ASSUMPTION, the export does not say. gt/gt.txt holds the YOLO boxes, each
# row its own id (there are no track ids: read `fme eval`'s detection scores, not its tracking scores;
# the flag does not use the truth). The images are symlinks.
set -euo pipefail
cd "$(dirname "$0")/.."
SRC=${SRC:-../shared/realfish/train/deepfish}
OUT=${1:-/tmp/fme-devset}
[ -d "$SRC/images" ] && [ -d "$SRC/labels" ] || { echo "familiarity_devset: $SRC: no images/ and labels/" >&2; exit 2; }
case "$(realpath -m "$OUT")" in
  "$(pwd)"/*) echo "familiarity_devset: $OUT is inside the repository; use a folder outside it" >&2; exit 2 ;;
esac
python3 - "$(realpath "$SRC")" "$OUT" <<'EOF'
import collections, json, os, re, shutil, sys

src, out = sys.argv[1], sys.argv[2]
MAX_GAP, MIN_FRAMES, FPS, W, H = 15, 56, 25, 360, 202
clips = collections.defaultdict(list)
for f in os.listdir(os.path.join(src, "images")):
    m = re.match(r"(.*)_f(\d{6})_[0-9a-f]+\.jpg$", f)
    if m:
        clips[m.group(1)].append((int(m.group(2)), f))

def boxes(f):
    with open(os.path.join(src, "labels", f[:-4] + ".txt")) as fh:
        return [list(map(float, ln.split()[1:5])) for ln in fh if len(ln.split()) >= 5]

os.makedirs(out, exist_ok=True)
made = []
for clip, frames in sorted(clips.items()):
    frames.sort()
    runs, cur = [], [frames[0]]
    for a, b in zip(frames, frames[1:]):
        if b[0] - a[0] > MAX_GAP:
            runs.append(cur)
            cur = []
        cur.append(b)
    runs.append(cur)
    for run in runs:
        if len(run) < MIN_FRAMES or not any(boxes(f) for _, f in run):
            continue
        name = f"{clip}_f{run[0][0]:06d}"
        d = os.path.join(out, name)
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(os.path.join(d, "img1"))
        os.makedirs(os.path.join(d, "gt"))
        rows = []
        for i, (_, f) in enumerate(run, 1):
            os.symlink(os.path.join(src, "images", f), os.path.join(d, "img1", f"{i:06d}.jpg"))
            for cx, cy, w, h in boxes(f):
                rows.append(f"{i},{len(rows) + 1},{(cx - w / 2) * W:.2f},{(cy - h / 2) * H:.2f},{w * W:.2f},{h * H:.2f},1,-1,-1,-1\n")
        with open(os.path.join(d, "gt", "gt.txt"), "w") as fh:
            fh.writelines(rows)
        with open(os.path.join(d, "seqinfo.ini"), "w") as fh:
            fh.write(f"[Sequence]\nname={name}\nimDir=img1\nframeRate={FPS}\nseqLength={len(run)}\n"
                     f"imWidth={W}\nimHeight={H}\nimExt=.jpg\n")
        meta = {
            "fps": float(FPS), "width": W, "height": H, "frames": len(run), "seed": 0, "preset": "real",
            "generator": {"name": "familiarity_devset.sh (real footage, no calibration)", "version": "1"},
            "camera": {"fx": W / 2, "fy": W / 2, "cx": W / 2, "cy": H / 2, "distortion": [0, 0, 0, 0, 0],
                       "world_to_camera": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                           "translation": [0, 0, 0]}},
            "water": {"type": "unknown"}, "reference_objects": [],
        }
        with open(os.path.join(d, "meta.json"), "w") as fh:
            json.dump(meta, fh, indent=2)
        made.append((name, len(run), len(rows)))
for name, n, b in made:
    print(f"{out}/{name}\t{n} frames\t{b} boxes")
EOF
