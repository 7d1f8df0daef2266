"""Real camera images with human fish boxes for the detector (docs/training.md "Real footage").

The pool (default `../shared/realfish/train`, `REAL_DATA` or `--real` elsewhere) holds one folder per
source, each with `images/*.jpg`, `labels/*.txt` (YOLO: `0 cx cy w h`, normalised; an empty file is
an image without fish) and a `SOURCE.md` (origin, licence). A fine-tuning folder may also be a
MOTChallenge sequence (`seqinfo.ini`, `img1/`, `gt/gt.txt`: a black-box recording or CVAT's
"MOT 1.1" export) or a CVAT "YOLO 1.1" export (`obj_train_data/*.jpg` with a `.txt` beside each).

Every image is letterboxed to the detector's input (data.NET_W x data.NET_H, as fme does) and its
boxes go with it as (x, y, w, h, visibility 1) in input pixels, the layout data.load_sequence gives
the renders, so det.train takes both alike.

The held-out split is by *group*, not by image: consecutive frames of one clip look alike, so a
random image split would score the detector on near-copies of its training frames.
"""
import configparser
import os
import re
import zlib

import cv2
import numpy as np

import data

# Partial labels (most school members unboxed) and no licence: never in the shipped model's training.
EXCLUDED = {"jp-piers-partial"}
# Share of each source's groups held out (by a hash of the group name: stable across runs and machines).
HELD_OUT_PERCENT = 12
# Share of a recording's frames (its last ones) held out when fine-tuning on it.
MOT_HELD_OUT = 0.15
IMAGE_EXT = (".jpg", ".jpeg", ".png", ".bmp")


def group_of(source, stem):
    """The unit of the held-out split: a DeepFish clip (name before `_fNNNNNN`), a run of 25
    consecutive export indices of the coastal camera, 10 of the aquarium's photo numbers, 12 of the
    zebrafish video's frames; otherwise the stem (a frame of a recording: its block of 150 frames)."""
    if source == "deepfish":
        m = re.match(r"(.*)_f\d{6}", stem)
        return m.group(1) if m else stem
    m = re.search(r"(\d+)", stem)
    if not m:
        return stem
    n = int(m.group(1))
    block = {"coastcam-rf": 25, "aquarium": 10, "zebrafish-lab": 12}.get(source, 150)
    return f"{stem[:m.start()]}{n // block}"


def held_out(source, stem, percent=HELD_OUT_PERCENT):
    return zlib.crc32(f"{source}/{group_of(source, stem)}".encode()) % 100 < percent


def sources(root):
    """The pool's source folders (those with images/ and labels/), sorted; EXCLUDED left out."""
    if not os.path.isdir(root):
        raise SystemExit(f"real image pool {root!r}: no such folder (set REAL_DATA or --real)")
    out = [d for d in sorted(os.listdir(root))
           if os.path.isdir(os.path.join(root, d, "images")) and os.path.isdir(os.path.join(root, d, "labels"))]
    return [d for d in out if d not in EXCLUDED]


def read_yolo_labels(path, w, h):
    """YOLO label file -> [K, 5] (x, y, w, h, vis=1) in image pixels. A missing file is an image
    without fish (CVAT writes none for unlabelled frames); a malformed line stops with its place."""
    out = []
    if os.path.exists(path):
        with open(path) as f:
            for n, line in enumerate(f, 1):
                v = line.split()
                if not v:
                    continue
                if len(v) < 5:
                    raise SystemExit(f"{path}:{n}: expected 'class cx cy w h', got {line.strip()!r}")
                try:
                    cx, cy, bw, bh = (float(a) for a in v[1:5])
                except ValueError:
                    raise SystemExit(f"{path}:{n}: not numbers: {line.strip()!r}")
                out.append(((cx - bw / 2) * w, (cy - bh / 2) * h, bw * w, bh * h, 1.0))
    return np.array(out, np.float32).reshape(-1, 5)


def letterboxed(path):
    """The image at `path` letterboxed to the network input, and (gain, padx, pady) to map its boxes."""
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise SystemExit(f"{path}: unreadable image")
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    h, w = rgb.shape[:2]
    gain, _nw, _nh, padx, pady = data.letterbox_params(w, h)
    return data.letterbox(rgb), (w, h), (gain, padx, pady)


def stacked(imgs):
    """[N, H, W, 3] uint8 of the network-size images (N may be 0)."""
    return np.stack(imgs) if imgs else np.zeros((0, data.NET_H, data.NET_W, 3), np.uint8)


def yolo_items(folder):
    """(image path, label path) of a YOLO folder: `images/` + `labels/`, or CVAT's YOLO 1.1 export
    (`obj_train_data/` or any folder with label files beside the images)."""
    img_dir, lab_dir = os.path.join(folder, "images"), os.path.join(folder, "labels")
    if os.path.isdir(img_dir):
        names = sorted(n for n in os.listdir(img_dir) if n.lower().endswith(IMAGE_EXT))
        return [(os.path.join(img_dir, n), os.path.join(lab_dir, os.path.splitext(n)[0] + ".txt")) for n in names]
    out = []
    for dirpath, _dirs, files in os.walk(folder):
        for n in sorted(files):
            if n.lower().endswith(IMAGE_EXT):
                out.append((os.path.join(dirpath, n), os.path.join(dirpath, os.path.splitext(n)[0] + ".txt")))
    return sorted(out)


def load_yolo(folder, source, split=None, limit=0):
    """Images and boxes of one YOLO folder at the network size. split: None (all), "train" or "val"
    (the held-out groups). Returns (images [N,H,W,3] uint8, boxes list, stems)."""
    imgs, boxes, stems = [], [], []
    for img_path, lab_path in yolo_items(folder):
        stem = os.path.splitext(os.path.basename(img_path))[0]
        if split is not None and held_out(source, stem) != (split == "val"):
            continue
        im, (w, h), lb = letterboxed(img_path)
        imgs.append(im)
        boxes.append(data.boxes_to_net(read_yolo_labels(lab_path, w, h), lb))
        stems.append(stem)
        if limit and len(imgs) >= limit:
            break
    return stacked(imgs), boxes, stems


def seqinfo(seq, key):
    """A number from seqinfo.ini's [Sequence] section (0 when the file or the key is absent)."""
    ini = configparser.ConfigParser()
    ini.read(os.path.join(seq, "seqinfo.ini"))
    return float(ini.get("Sequence", key, fallback="0") or 0)


def seq_length(seq):
    """seqinfo.ini's seqLength (0 when absent): frames past it are not part of the sequence."""
    return int(seqinfo(seq, "seqLength"))


def frame_rate(seq):
    """seqinfo.ini's frameRate (0 when absent)."""
    return seqinfo(seq, "frameRate")


def read_mot_gt(seq, with_ids=False):
    """frame -> [(x, y, w, h, 1.0)] in source pixels of a MOTChallenge sequence's gt/gt.txt
    (frame, id, x, y, w, h, not-ignored, ...; CVAT MOT 1.1 rows marked ignored, 7th column 0, are
    left out), each with its id as a sixth value when `with_ids`. A missing file or a malformed row
    is an error that names it."""
    gt = {}
    gt_path = os.path.join(seq, "gt", "gt.txt")
    if not os.path.exists(gt_path):
        raise SystemExit(f"{seq}: no gt/gt.txt (label the recording first: docs/training.md)")
    with open(gt_path) as f:
        for n, line in enumerate(f, 1):
            v = line.strip().split(",")
            if len(v) < 6:
                if line.strip():
                    raise SystemExit(f"{gt_path}:{n}: expected 'frame,id,x,y,w,h,...', got {line.strip()!r}")
                continue
            if len(v) >= 7 and v[6].strip() == "0":
                continue
            try:
                fr = int(float(v[0]))
                row = (float(v[2]), float(v[3]), float(v[4]), float(v[5]), 1.0)
                gt.setdefault(fr, []).append(row + (int(float(v[1])),) if with_ids else row)
            except ValueError:
                raise SystemExit(f"{gt_path}:{n}: not numbers: {line.strip()!r}")
    return gt


def load_mot(seq, split=None, every=1):
    """A MOTChallenge folder (a black-box recording or CVAT's MOT 1.1 export) at the network size:
    frames with a gt row, or every frame when the sequence has a gt file (an unlabelled frame of a
    labelled sequence is an image without fish). CVAT MOT rows: frame, id, x, y, w, h, not-ignored,
    class, visibility; rows marked ignored (7th column 0) are dropped. The held-out split is the
    last MOT_HELD_OUT of the frames: one stretch of the recording, never the neighbours of a
    training frame."""
    gt = read_mot_gt(seq)
    n_max = seq_length(seq)
    img_dir = os.path.join(seq, "img1")
    names = sorted(n for n in os.listdir(img_dir) if n.lower().endswith(IMAGE_EXT) and n[0].isdigit())
    if n_max:
        names = [n for n in names if int(os.path.splitext(n)[0]) <= n_max]
    first_val = int(len(names) * (1.0 - MOT_HELD_OUT))
    imgs, boxes, stems = [], [], []
    for i, name in enumerate(names):
        fr = int(os.path.splitext(name)[0])
        if i % every:
            continue
        stem = f"{os.path.basename(seq)}_{fr:06d}"
        if split is not None and (i >= first_val) != (split == "val"):
            continue
        im, _wh, lb = letterboxed(os.path.join(img_dir, name))
        imgs.append(im)
        boxes.append(data.boxes_to_net(np.array(gt.get(fr, []), np.float32).reshape(-1, 5), lb))
        stems.append(stem)
    return stacked(imgs), boxes, stems


def load_any(folder, split=None, every=1):
    """A fine-tuning folder: MOTChallenge sequences (anything with seqinfo.ini or gt/gt.txt below it)
    and YOLO folders. Returns {name: (images, boxes)}; an empty result stops with a message."""
    out = {}
    for dirpath, dirs, files in os.walk(folder):
        if "img1" in dirs and os.path.exists(os.path.join(dirpath, "gt", "gt.txt")):
            out[os.path.relpath(dirpath, folder)] = load_mot(dirpath, split, every)[:2]
            dirs[:] = []
        elif "images" in dirs and "labels" in dirs:
            name = os.path.relpath(dirpath, folder)
            out[name] = load_yolo(dirpath, os.path.basename(dirpath), split)[:2]
            dirs[:] = []
        elif any(f.endswith(".txt") and os.path.splitext(f)[0] + ".jpg" in files for f in files):
            name = os.path.relpath(dirpath, folder)
            out[name] = load_yolo(dirpath, "cvat", split)[:2]
            dirs[:] = []
    if not out:
        raise SystemExit(f"{folder}: no MOTChallenge sequence (img1/ + gt/gt.txt) or YOLO folder "
                         "(images/ + labels/, or CVAT's obj_train_data/) found")
    return out


def load_pool(root, split, limit=0):
    """{source: (images, boxes)} of the pool's split ("train" or "val")."""
    return {s: load_yolo(os.path.join(root, s), s, split, limit)[:2] for s in sources(root)}
