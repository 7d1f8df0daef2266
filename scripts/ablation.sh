#!/usr/bin/env bash
# Ablations of issue 3, the paper's experiments on our synthetic scenes:
#   group A  (GT boxes + GT depth) on a 20-fish swarm of 30 s and on a single fish (Tables 6-7 row A)
#   post-processing on/off over the 18 postproc-suite scenes (Fig. 8)
#   metric fits with relative-gt depth on the swarm (Table 4 analogue)
#   reference layouts A-F with relative-gt depth (Table 5 analogue)
# Usage: scripts/ablation.sh [OUT_DIR]   (default target/ablation). Needs python3 for the tables.
# FME=path/to/fme overrides the binary (default target/release/fme, built if missing).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/ablation}
FME=${FME:-target/release/fme}
FRAMES=${FRAMES:-900}        # 30 s at 30 fps
LAYOUT_FRAMES=${LAYOUT_FRAMES:-300}
SEED=${SEED:-11}
[ -x "$FME" ] || cargo build --release --locked --bin fme
mkdir -p "$OUT"
synth() { local out=$1; shift; [ -f "$out/seqinfo.ini" ] || "$FME" synth --out "$out" --force "$@" >/dev/null; }
ev() { "$FME" eval --json "$@"; }

echo "== synthesising sequences in $OUT" >&2
synth "$OUT/swarm" --preset swarm --fish 20 --frames "$FRAMES" --seed "$SEED" --layout F
synth "$OUT/single" --preset single --frames "$FRAMES" --seed "$((SEED + 1))" --layout F
synth "$OUT/postproc" --preset postproc-suite --seed "$((SEED + 2))"
for L in A B C D E F; do
  synth "$OUT/layout-$L" --preset swarm --fish 20 --frames "$LAYOUT_FRAMES" --seed "$((SEED + 3))" --layout "$L"
done

echo "== evaluating" >&2
R="$OUT/results"; mkdir -p "$R"
ev --sequence "$OUT/swarm" --plot "$OUT/swarm-groupA.png" --series "$OUT/swarm-groupA.csv" > "$R/groupA-swarm.json"
ev --sequence "$OUT/single" --plot "$OUT/single-groupA.png" --series "$OUT/single-groupA.csv" > "$R/groupA-single.json"
for span in 0.1 0.2; do
  ev --sequence "$OUT/swarm" --speed-span "$span" > "$R/groupA-swarm-span$span.json"
  ev --sequence "$OUT/single" --speed-span "$span" > "$R/groupA-single-span$span.json"
done
for d in "$OUT"/postproc/*/; do
  n=$(basename "$d")
  ev --sequence "$d" > "$R/postproc-$n.json"
done
for fit in linear inverse robust poly2 tree knn; do
  ev --sequence "$OUT/swarm" --depth relative-gt --fit "$fit" > "$R/fit-$fit.json"
  ev --sequence "$OUT/swarm" --depth relative-gt --fit "$fit" --foul-refs 2 > "$R/fit-$fit-fouled2.json"
done
for L in A B C D E F; do
  for fit in linear inverse robust; do
    ev --sequence "$OUT/layout-$L" --depth relative-gt --fit "$fit" > "$R/layout-$L-$fit.json"
  done
done

python3 - "$R" <<'PY' | tee "$OUT/ablation.md"
import json, os, sys, glob
R = sys.argv[1]
def load(n):
    with open(os.path.join(R, n + ".json")) as f:
        return json.load(f)
def row(cells): print("| " + " | ".join(str(c) for c in cells) + " |")
print("## Group A: GT boxes + GT depth\n")
row(["scene", "speed span", "frames", "fish", "RMSE m/s", "DistCorr", "RMSE raw m/s", "DistCorr raw", "error 95% m/s"])
row(["---"] * 9)
for scene in ["swarm", "single"]:
    for span, name in [("0 (frame to frame)", f"groupA-{scene}"), ("0.1 s", f"groupA-{scene}-span0.1"), ("0.2 s", f"groupA-{scene}-span0.2")]:
        j = load(name)
        row([scene, span, j["frames"], f'{j["mean_fish"]:.1f}', f'{j["speed_rmse_mps"]:.4f}', f'{j["speed_distcorr"]:.3f}',
             f'{j["speed_rmse_raw_mps"]:.4f}', f'{j["speed_distcorr_raw"]:.3f}',
             f'[{j["error_ci95_mps"][0]:.3f}, {j["error_ci95_mps"][1]:.3f}]'])
print("\n## Post-processing on/off, postproc-suite (GT boxes + GT depth)\n")
row(["scene", "RMSE on", "RMSE off", "delta", "box fixes", "depth fixes"])
row(["---"] * 6)
tot = {"occ": [0, 0, 0], "free": [0, 0, 0]}
for p in sorted(glob.glob(os.path.join(R, "postproc-*.json"))):
    n = os.path.basename(p)[len("postproc-"):-5]
    j = load("postproc-" + n)
    k = "occ" if ("occ" in n.lower() and "noocc" not in n.lower() and "no-occ" not in n.lower() and "no_occ" not in n.lower()) else "free"
    tot[k][0] += j["speed_rmse_mps"]; tot[k][1] += j["speed_rmse_raw_mps"]; tot[k][2] += 1
    row([n, f'{j["speed_rmse_mps"]:.4f}', f'{j["speed_rmse_raw_mps"]:.4f}', f'{j["speed_rmse_mps"] - j["speed_rmse_raw_mps"]:+.4f}',
         j["boxes_corrected"], j["depths_corrected"]])
for k, (on, off, n) in tot.items():
    if n:
        row([f"mean, {'occluded' if k == 'occ' else 'not occluded'} ({n})", f"{on / n:.4f}", f"{off / n:.4f}", f"{(on - off) / n:+.4f}", "", ""])
print("\n## Metric fits, relative-gt depth, swarm layout F (Table 4 analogue)\n")
row(["fit", "depth RMSE m", "d<1.25", "d<1.25^2", "fit residual m", "speed RMSE m/s", "DistCorr",
     "2 fouled refs: depth RMSE m", "d<1.25"])
row(["---"] * 9)
for fit in ["linear", "inverse", "robust", "poly2", "tree", "knn"]:
    j = load("fit-" + fit); k = load(f"fit-{fit}-fouled2")
    res = j.get("fit_residual_m")
    row([fit, f'{j["depth_rmse_m"]:.3f}', f'{j["depth_delta_1_25"]:.3f}', f'{j["depth_delta_1_25_2"]:.3f}',
         "-" if res is None else f"{res:.3f}", f'{j["speed_rmse_mps"]:.3f}', f'{j["speed_distcorr"]:.3f}',
         f'{k["depth_rmse_m"]:.3f}', f'{k["depth_delta_1_25"]:.3f}'])
print("\n## Reference layouts, relative-gt depth (Table 5 analogue)\n")
row(["layout", "refs visible", "linear RMSE m", "linear d<1.25", "linear d<1.25^2", "inverse RMSE m", "inverse d<1.25", "robust RMSE m", "robust d<1.25"])
row(["---"] * 9)
for L in "ABCDEF":
    a, b, c = load(f"layout-{L}-linear"), load(f"layout-{L}-inverse"), load(f"layout-{L}-robust")
    row([L, a["references_visible"], f'{a["depth_rmse_m"]:.3f}', f'{a["depth_delta_1_25"]:.3f}', f'{a["depth_delta_1_25_2"]:.3f}',
         f'{b["depth_rmse_m"]:.3f}', f'{b["depth_delta_1_25"]:.3f}', f'{c["depth_rmse_m"]:.3f}', f'{c["depth_delta_1_25"]:.3f}'])
PY
echo "tables: $OUT/ablation.md, plots: $OUT/*.png" >&2
