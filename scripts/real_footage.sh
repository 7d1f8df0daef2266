#!/usr/bin/env bash
# The "Real footage" table of docs/accuracy.md: a detector pair (default the bundled models) on a real
# MOTChallenge sequence (default ../shared/realfish/mf25-seq2, the EVALUATION sequence: measure only),
# with the shipped schedule and no tuning: detection and tracking scores, activity in BL/s with the
# pipeline's boxes and with the true boxes, and the depth network's consistency.
#   bash scripts/real_footage.sh [DET_MODEL] [SEQ]
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/fme}
DET=${1:-models/fish_det_int8.onnx}
SEQ=${2:-../shared/realfish/mf25-seq2}
[ -x "$BIN" ] || { echo "real_footage: build fme first (make build)" >&2; exit 2; }
[ -d "$SEQ" ] || { echo "real_footage: $SEQ: no such sequence" >&2; exit 2; }
py() { python3 -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({k: d.get(k) for k in sys.argv[1:]}))" "$@"; }
echo "detector $DET on $SEQ"
"$BIN" eval --sequence "$SEQ" --boxes model --depth model --det-model "$DET" --json \
  | py detection mota idf1 mean_activity_bls mean_activity_mps mean_fish depth_consistency depth_consistency_frames activity_frames unlike_fish_share
"$BIN" eval --sequence "$SEQ" --boxes gt --depth model --det-model "$DET" --json \
  | py mean_activity_bls mean_activity_mps mean_fish depth_consistency activity_frames
