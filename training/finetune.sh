#!/usr/bin/env bash
# Fine-tunes the bundled detector on a farm's own labelled frames (`make -C training finetune DATA=DIR`;
# docs/training.md "Train on your own cage"):
#   DATA   one or more folders (space-separated): black-box recordings or MOTChallenge folders whose
#          gt/gt.txt came from CVAT's "MOT 1.1" export, or CVAT "YOLO 1.1" exports (obj_train_data/)
#          or images/ + labels/ folders
#   OUT    where the new model pair and metrics.json go (default /tmp/fme-finetuned)
#   BASE   the detector to start from (default models/fish_det_fp32.onnx)
#   BUDGET_S  seconds of training (default 900); VENV (default /tmp/venv-infer)
# Prints P / R on the held-out part of DATA (the last 15 % of each recording's frames; 12 % of the
# YOLO images by group) before and after, and writes OUT/fish_det_{fp32,int8}.onnx.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/.." && pwd)
VENV=${VENV:-/tmp/venv-infer}
OUT=$(realpath -m "${OUT:-/tmp/fme-finetuned}")
BASE=$(realpath -m "${BASE:-$ROOT/models/fish_det_fp32.onnx}")
BUDGET_S=${BUDGET_S:-900}
[ -n "${DATA:-}" ] || { echo "finetune: set DATA=DIR (a labelled recording or CVAT export; docs/training.md)" >&2; exit 2; }
dirs=()
for d in $DATA; do
  [ -d "$d" ] || { echo "finetune: DATA folder $d does not exist" >&2; exit 2; }
  dirs+=("$(realpath "$d")")
done
[ -f "$BASE" ] || { echo "finetune: BASE=$BASE: no such model" >&2; exit 2; }
VENV="$VENV" bash "$ROOT/scripts/setup_training.sh"
cd "$HERE"
FME_NET=480x288 "$VENV/bin/python" train_real.py --finetune "${dirs[@]}" --base "$BASE" --out "$OUT" \
  --budget-s "$BUDGET_S" ${TRAIN_ARGS:-}
echo "finetune: install with: cp $OUT/fish_det_int8.onnx /var/lib/fme/models/ (then [detector] model), after checking it with fme eval"
