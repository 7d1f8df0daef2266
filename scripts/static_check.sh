#!/usr/bin/env bash
# The static binary of `make static` on its own: `ldd` finds nothing dynamic, and it
# runs the bundled recording from an empty directory with only its configuration beside it: no
# models/ folder, no .ort/lib, an empty environment. The default model paths must resolve to the
# models embedded in the executable, the pipeline must measure activity, and a host name must
# resolve (static glibc: /etc/hosts through the built-in `files` service).
#
# Usage: scripts/static_check.sh [BINARY]   (default: target/static/fme)
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=${1:-$repo/target/static/fme}
fail() { echo "static_check: $*" >&2; exit 1; }

[ -x "$bin" ] || fail "$bin: no such executable (run \`make static\`)"
ldd_out=$(ldd "$bin" 2>&1 || true)
case "$ldd_out" in
  *"not a dynamic executable"* | *"statically linked"*) ;;
  *) fail "$bin is dynamically linked; ldd says: $ldd_out" ;;
esac
if readelf -d "$bin" 2>/dev/null | grep -q '(NEEDED)'; then
  fail "$bin needs shared libraries: $(readelf -d "$bin" | grep '(NEEDED)' | tr -s ' ')"
fi
if readelf -l "$bin" 2>/dev/null | grep -q 'INTERP'; then
  fail "$bin asks for a program interpreter (dynamic loader)"
fi

dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cp "$bin" "$dir/fme"
mkdir "$dir/config"
cp "$repo/config/fme.toml" "$dir/config/"
cp -r "$repo/tests/data/swarm20" "$dir/recording"
cd "$dir"
run() { env -i PATH=/usr/bin:/bin HOME="$dir" "$@"; }

version=$(run ./fme --version)
[[ $version == *"backend tract, default models fp32, embedded"* ]] || fail "fme --version says \"$version\", not the tract backend with embedded fp32 models"

# localhost:0 goes through getaddrinfo (and /etc/hosts); port 0 takes any free port.
if ! run ./fme run --config config/fme.toml --source recording --max-frames 60 --fast \
  --modbus-listen localhost:0 --series series.csv >out.txt 2>&1; then
  cat out.txt >&2
  fail "fme run on the bundled recording failed (output above)"
fi
embedded=$(grep -c "using the copy embedded in the executable" out.txt || true)
[ "$embedded" -eq 2 ] || { cat out.txt >&2; fail "expected the detector and the depth network from the embedded models, saw $embedded"; }
grep -q "60 processed" out.txt || { cat out.txt >&2; fail "expected 60 processed frames"; }
grep -q "modbus tcp server on 127.0.0.1:" out.txt || { cat out.txt >&2; fail "localhost did not resolve to 127.0.0.1"; }

# series.csv: frame,t,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,latency_s,too_few_fish,uncalibrated
[ -s series.csv ] || fail "no series.csv written"
rows=$(($(wc -l <series.csv) - 1))
measured=$(awk -F, 'NR > 1 && $3 != "" && $3 > 0 && $10 == 0 { n++ } END { print n + 0 }' series.csv)
[ "$rows" -eq 60 ] || fail "series.csv has $rows frames, expected 60"
# A fish counts once tracked for 1 s (30 frames), so about the last 29 frames carry a value.
[ "$measured" -ge 20 ] || { cat series.csv >&2; fail "only $measured calibrated activity values in series.csv"; }

size=$(stat -c %s "$dir/fme")
echo "static_check: ok: $version; $((size / 1048576)) MiB; ldd: $(echo "$ldd_out" | tr -s ' \t' ' ' | sed 's/^ //'); 60 frames from an empty directory, $measured activity values"
