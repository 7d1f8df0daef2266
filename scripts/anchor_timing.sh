#!/usr/bin/env bash
# The reference models (YOLO11n, random weights, as in ../shared/research/onnx-timings.md) timed
# turn by turn with the bundled int8 networks: how this machine compares with the one the issue's
# anchors came from (scripts/anchor_timing.py). Needs the Python stack of training/requirements.txt in
# $VENV (default /tmp/venv-infer; created if missing, a ~6 GB torch install from PyPI). A benchmark,
# not a test: nothing here is in make test or CI. Arguments go to the Python script (--rounds, --json...).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
VENV=${VENV:-/tmp/venv-infer}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q -r "$root/training/requirements.txt"
fi
exec "$VENV/bin/python" "$root/scripts/anchor_timing.py" "$@"
