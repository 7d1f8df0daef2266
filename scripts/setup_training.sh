#!/usr/bin/env bash
# Installs the training Python stack (training/requirements.txt) into VENV (default /tmp/venv-infer),
# idempotently: an existing venv that imports what training/ needs is left alone; a missing or broken
# one is (re)installed from PyPI. Used by `make test` (the fine-tuning test) and training/*.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-/tmp/venv-infer}
check() { "$VENV/bin/python" -c "import torch, onnx, onnxruntime, cv2, numpy" >/dev/null 2>&1; }
if [ -x "$VENV/bin/python" ] && check; then
  echo "setup-training: ok ($VENV)" >&2
  exit 0
fi
echo "setup-training: installing training/requirements.txt into $VENV (about 6 GB, a few minutes)" >&2
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/pip" install -q --disable-pip-version-check -r training/requirements.txt
check || { echo "setup-training: $VENV still cannot import torch/onnx/onnxruntime/cv2" >&2; exit 1; }
echo "setup-training: ok ($VENV)" >&2
