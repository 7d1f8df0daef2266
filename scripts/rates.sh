#!/usr/bin/env bash
# Detector/depth rates against accuracy and CPU: group D (bundled models, the shipped
# config) on the held-out four-group sequences of one seed set, at several detector/depth rates and
# with the networks on every frame. Prints a table; JSON per run in OUT/rates-SEED_BASE.
# Usage: scripts/rates.sh [OUT_DIR]  (default target/four-groups; sequences are made by
# scripts/four_groups.sh with the same SEED_BASE, default 7061, and reused). FME overrides the binary.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/four-groups}
FME=${FME:-target/release/fme}
B=${SEED_BASE:-7061}
RATES=${RATES:-"every 30/10 10/5 5/2"}
[ -x "$FME" ] || cargo build --release --locked --bin fme
[ -f "$OUT/swarm60-s$((B + 12))/seqinfo.ini" ] || SEED_BASE=$B FME=$FME bash scripts/four_groups.sh "$OUT" >/dev/null
mkdir -p "$OUT/rates-$B"
for seq in "single-s$B" "single-s$((B + 1))" "swarm20-s$((B + 10))" "swarm40-s$((B + 11))" "swarm60-s$((B + 12))"; do
  for r in $RATES; do
    if [ "$r" = every ]; then args=(--every-frame); else args=(--set "detector.rate_hz=${r%/*}" --set "depth.rate_hz=${r#*/}"); fi
    "$FME" eval --json --sequence "$OUT/$seq" --boxes model --depth model "${args[@]}" 2>/dev/null \
      > "$OUT/rates-$B/$seq-${r/\//-}.json"
  done
done
python3 - "$OUT/rates-$B" "$RATES" <<'PY'
import json, os, sys
d, rates = sys.argv[1], sys.argv[2].split()
print(f"{'sequence':15} {'rates Hz':9} {'RMSE':>7} {'RMSE now':>8} {'DistCorr':>8} {'dRMSE m':>7} {'IDF1':>6} {'MOTA':>6} {'fish':>5} {'CPU ms/frame':>12}")
mean = {r: [] for r in rates}
for seq in sorted({'-'.join(f.split('-')[:2]) for f in os.listdir(d)}):
    for r in rates:
        p = os.path.join(d, f"{seq}-{r.replace('/', '-')}.json")
        if not os.path.exists(p):
            continue
        j = json.load(open(p))
        row = (j['speed_rmse_mps'], j['speed_rmse_now_mps'], j['speed_distcorr'], j.get('depth_rmse_m') or float('nan'),
               j.get('idf1', float('nan')), j.get('mota', float('nan')), j['mean_fish'], j['cpu_ms_per_frame'])
        mean[r].append(row)
        print(f"{seq:15} {r:9} {row[0]:7.4f} {row[1]:8.4f} {row[2]:8.3f} {row[3]:7.3f} {100*row[4]:6.1f} {100*row[5]:6.1f} {row[6]:5.1f} {row[7]:12.2f}")
for r in rates:
    rows = mean[r]
    if rows:
        m = [sum(x[i] for x in rows) / len(rows) for i in range(8)]
        print(f"{'mean':15} {r:9} {m[0]:7.4f} {m[1]:8.4f} {m[2]:8.3f} {m[3]:7.3f} {100*m[4]:6.1f} {100*m[5]:6.1f} {m[6]:5.1f} {m[7]:12.2f}")
PY
