#!/usr/bin/env bash
# The real-fish detector recipe (`make -C training real`): trains the detector on the real labelled
# images of REAL_DATA (default ../shared/realfish/train, one folder per source, YOLO labels) and on
# fme's renders, on the CPU, for BUDGET_S seconds of training (default 4,000: about 75 minutes in all
# on the 2-core machine), then exports, quantises and reports P / R per source on each source's
# held-out split (training/real.py says how the split is made).
# Writes OUT (default /tmp/fme-real-det): fish_det_fp32.onnx, fish_det_int8.onnx, metrics.json. To
# bundle the result: copy both files into models/ and re-measure (docs/training.md "Real footage").
# Environment: VENV, FME_BIN, DATA (renders, shared with train.sh), SYNTH_SEQS (render sequences,
# default 240), ARCH (det.ARCHS, default full), NICE, TRAIN_ARGS (more train_real.py options).
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/.." && pwd)
VENV=${VENV:-/tmp/venv-infer}
DATA=$(realpath -m "${DATA:-/tmp/fme-train-data}")
OUT=$(realpath -m "${OUT:-/tmp/fme-real-det}")
REAL_DATA=$(realpath -m "${REAL_DATA:-$ROOT/../shared/realfish/train}")
BUDGET_S=${BUDGET_S:-4000}
SYNTH_SEQS=${SYNTH_SEQS:-240}
ARCH=${ARCH:-full}
NICE=${NICE:-10}
FRAMES=${FRAMES:-24}
[ -d "$REAL_DATA" ] || { echo "train_real.sh: REAL_DATA=$REAL_DATA: no such folder" >&2; exit 2; }
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q -r "$HERE/requirements.txt"
fi
if [ -z "${FME_BIN:-}" ]; then
  (cd "$ROOT" && cargo build --release --locked --bin fme)
  FME_BIN="$ROOT/target/release/fme"
fi
# shellcheck source=render.sh
source "$HERE/render.sh"
gen train 1000 "$SYNTH_SEQS"
gen val 9000 14
cd "$HERE"
FME_NET=480x288 nice -n "$NICE" "$VENV/bin/python" train_real.py --real "$REAL_DATA" --synth "$DATA" \
  --synth-seqs "$SYNTH_SEQS" --out "$OUT" --budget-s "$BUDGET_S" --arch "$ARCH" ${TRAIN_ARGS:-}
