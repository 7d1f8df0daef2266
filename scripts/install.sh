#!/usr/bin/env bash
# Installs fme the way the systemd unit expects it (`make install`; docs/deployment.md#installing):
#   PREFIX/bin/fme                            the executable, stripped
#   PREFIX/share/fme/models/*.onnx            the bundled models (int8 and fp32)
#   PREFIX/lib/fme/libonnxruntime.so          ONNX Runtime (from make setup's .ort/lib)
#   PREFIX/lib/systemd/system/fme.service     the unit, its paths rewritten for PREFIX
#   PREFIX/share/doc/fme/                     README, docs/ and boards/README.md (the unit's Documentation=)
#   /etc/fme/fme.toml                         BOARD's configuration (boards/BOARD.toml; default config/fme.toml),
#                                             only when none is there: a commissioned box keeps its own
# Usage: scripts/install.sh BINARY   with PREFIX (default /usr/local), DESTDIR (default empty: the live
# system), BOARD, STRIP (default strip; `true` to keep symbols).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${1:?usage: scripts/install.sh BINARY (e.g. target/release/fme)}
PREFIX=${PREFIX:-/usr/local}
DESTDIR=${DESTDIR:-}
BOARD=${BOARD:-}
STRIP=${STRIP:-strip}
case "$PREFIX" in /*) ;; *) echo "install: PREFIX=$PREFIX must be an absolute path" >&2; exit 2 ;; esac
[ -x "$BIN" ] || { echo "install: $BIN: no such executable (run make build first)" >&2; exit 2; }
ORT="$ROOT/.ort/lib/libonnxruntime.so"
[ -e "$ORT" ] || { echo "install: $ORT missing (run make setup first)" >&2; exit 2; }
if [ -n "$BOARD" ]; then
  CONFIG="$ROOT/boards/$BOARD.toml"
  [ -f "$CONFIG" ] || { echo "install: BOARD=$BOARD: no boards/$BOARD.toml (see boards/README.md)" >&2; exit 2; }
else
  CONFIG="$ROOT/config/fme.toml"
fi

D="$DESTDIR$PREFIX"
install -d "$D/bin" "$D/share/fme/models" "$D/lib/fme" "$D/lib/systemd/system" "$D/share/doc/fme/docs" \
  "$D/share/doc/fme/boards"
install -m 755 "$BIN" "$D/bin/fme"
"$STRIP" "$D/bin/fme"
install -m 644 "$ROOT"/models/fish_det_int8.onnx "$ROOT"/models/fish_det_fp32.onnx \
  "$ROOT"/models/fish_depth_int8.onnx "$ROOT"/models/fish_depth_fp32.onnx "$D/share/fme/models/"
install -m 644 "$(readlink -f "$ORT")" "$D/lib/fme/libonnxruntime.so"
install -m 644 "$ROOT/README.md" "$D/share/doc/fme/"
install -m 644 "$ROOT"/docs/*.md "$D/share/doc/fme/docs/"
install -m 644 "$ROOT/boards/README.md" "$D/share/doc/fme/boards/"
# The unit names the executable, the library and the README by absolute path: point them at PREFIX.
sed -e "s|/usr/local/bin/fme|$PREFIX/bin/fme|g" \
    -e "s|/usr/local/lib/fme/|$PREFIX/lib/fme/|g" \
    -e "s|file:///usr/share/doc/fme/|file://$PREFIX/share/doc/fme/|g" \
    "$ROOT/systemd/fme.service" > "$D/lib/systemd/system/fme.service"
chmod 644 "$D/lib/systemd/system/fme.service"
if [ -e "$DESTDIR/etc/fme/fme.toml" ]; then
  echo "install: $DESTDIR/etc/fme/fme.toml exists: kept (the new default is $CONFIG)"
else
  install -D -m 644 "$CONFIG" "$DESTDIR/etc/fme/fme.toml"
fi
echo "install: fme in $D (unit: $D/lib/systemd/system/fme.service, config: $DESTDIR/etc/fme/fme.toml)"
if [ -z "$DESTDIR" ]; then
  echo "next: fme config check /etc/fme/fme.toml && systemctl daemon-reload && systemctl enable --now fme"
fi
