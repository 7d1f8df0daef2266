#!/usr/bin/env bash
# Conformance of fme's ONNX decoding with real exports: exports YOLO11n (Ultralytics,
# yolo11n.yaml) and Depth Anything V2 Small (transformers config), random weights, into
# $FME_CONFORMANCE_DIR (default /tmp/fme-conformance, outside the repo: ~120 MB), then runs
# tests/infer_conformance.rs against them. Needs the Python stack of training/requirements.txt in
# $VENV (default /tmp/venv-infer; created if missing, a ~6 GB torch install from PyPI).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-/tmp/venv-infer}
export FME_CONFORMANCE_DIR=${FME_CONFORMANCE_DIR:-/tmp/fme-conformance}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q -r training/requirements.txt
fi
bash scripts/setup.sh
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Ultralytics writes its export next to the working directory; keep that out of the repo.
(cd "$work" && "$VENV/bin/python" "$OLDPWD/scripts/onnx_conformance.py" "$FME_CONFORMANCE_DIR")
cargo test --test infer_conformance -- --ignored --nocapture
