#!/usr/bin/env bash
# Quality: `default` vs `sort` preset on the mot15 sequences with public ground truth
# (TUD-Campus, TUD-Stadtmitte: gt.txt ships in the motmetrics==1.4.0 wheel; nothing is copied).
# Usage: scripts/mot15_quality.sh [fme binary] [mot15 dir] [python with motmetrics] [extra fme args]
set -euo pipefail
FME=${1:-target/release/fme}
DIR=${2:-$(cd "$(dirname "$0")/../.." && pwd)/shared/benchmarks/mot15}
PY=${3:-/tmp/venv-mm/bin/python}
shift $(( $# < 3 ? $# : 3 ))
MMDATA=$("$PY" -c 'import motmetrics, os; print(os.path.join(os.path.dirname(motmetrics.__file__), "data"))')
printf '%-16s %-8s %s\n' sequence preset "$("$FME" track --hyp /dev/null --gt /dev/null | head -1)"
for seq in TUD-Campus TUD-Stadtmitte; do
  for preset in sort default; do
    line=$("$FME" track --preset "$preset" --fps 25 --det "$DIR/$seq/det.txt" --gt "$MMDATA/$seq/gt.txt" "$@" | tail -1)
    printf '%-16s %-8s %s\n' "$seq" "$preset" "$line"
  done
done
