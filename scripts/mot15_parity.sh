#!/usr/bin/env bash
# Parity of `fme track --preset sort` with SORT's own output on the 11 mot15 sequences:
# each sort.txt is used as ground truth; target MOTA >= 99% on every sequence.
# Usage: scripts/mot15_parity.sh [fme binary] [mot15 dir]
set -euo pipefail
FME=${1:-target/release/fme}
DIR=${2:-$(cd "$(dirname "$0")/../.." && pwd)/shared/benchmarks/mot15}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
printf '%-16s %s\n' sequence "$("$FME" track --hyp /dev/null --gt /dev/null | head -1)"
fail=0
for d in "$DIR"/*/; do
  seq=$(basename "$d")
  [ -f "$d/det.txt" ] || continue
  line=$("$FME" track --preset sort --det "$d/det.txt" --out "$TMP/$seq.txt" --gt "$d/sort.txt" | tail -1)
  printf '%-16s %s\n' "$seq" "$line"
  mota=$(echo "$line" | awk '{print $2}')
  awk -v m="$mota" 'BEGIN{exit !(m < 99.0)}' && fail=1
done
[ "$fail" = 0 ] && echo "parity: MOTA >= 99% on every sequence" || { echo "parity: FAILED"; exit 1; }
