#!/usr/bin/env bash
# The depth network on real frames (`make -C training depth-real`; docs/training.md "Depth on real
# frames"): fine-tunes the bundled fp32 depth network (TRAIN_ARGS="--base FP32 --base-int8 INT8" for another: the
# bundled files came from the synthetic-only network of `make -C training bundled`) on fme's renders (the scale- and shift-invariant
# loss, a share given a real look) and a ranking loss on the real labelled images of REAL_DATA (default
# ../shared/realfish/train: the longer of two fish in one image should be nearer), for BUDGET_S seconds
# of training (default 1,800: about 35 minutes in all on the 2-core CPU with the renders present), then
# exports, quantises and scores it: fme's depth consistency per real source's held-out split and on
# held-out renders, bundled files against the new ones.
# Writes OUT (default /tmp/fme-depth-real): fish_depth_fp32.onnx, fish_depth_int8.onnx, metrics.json.
# To bundle the result: copy both files into models/ and re-measure with `fme eval` on real footage.
# Environment: VENV, FME_BIN, DATA (renders, shared with train.sh and train_real.sh), SYNTH_SEQS (render
# sequences, default 240), THREADS (default 2), NICE (default 10), TRAIN_ARGS (more train_depth_real.py
# options, e.g. --rank-weight 2 or --scratch).
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/.." && pwd)
VENV=${VENV:-/tmp/venv-infer}
DATA=$(realpath -m "${DATA:-/tmp/fme-train-data}")
OUT=$(realpath -m "${OUT:-/tmp/fme-depth-real}")
REAL_DATA=$(realpath -m "${REAL_DATA:-$ROOT/../shared/realfish/train}")
BUDGET_S=${BUDGET_S:-1800}
SYNTH_SEQS=${SYNTH_SEQS:-240}
THREADS=${THREADS:-2}
NICE=${NICE:-10}
FRAMES=${FRAMES:-24}
[ -d "$REAL_DATA" ] || { echo "train_depth_real.sh: REAL_DATA=$REAL_DATA: no such folder" >&2; exit 2; }
VENV="$VENV" bash "$ROOT/scripts/setup_training.sh"
# Render only what is missing (the sequences train.sh and train_real.sh rendered are reused).
# shellcheck source=render.sh
source "$HERE/render.sh"
real_recipe_renders "$SYNTH_SEQS"
cd "$HERE"
FME_NET=480x288 nice -n "$NICE" "$VENV/bin/python" train_depth_real.py --real "$REAL_DATA" --synth "$DATA" \
  --synth-seqs "$SYNTH_SEQS" --budget-s "$BUDGET_S" --threads "$THREADS" --out "$OUT" ${TRAIN_ARGS:-}
