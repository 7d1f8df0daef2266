# Sourced by the recipes: `gen SPLIT FIRST_SEED COUNT` renders swarm sequences with `fme synth` into
# $DATA/SPLIT (every water type I..7C, layouts A..F, 20-60 fish), skipping those already there. Needs
# FME_BIN, DATA, FRAMES and NICE. `real_recipe_renders COUNT` is the real-fish recipes' share: COUNT
# training sequences from seed 1000 and the 14 held-out ones, building fme (ROOT) only when some are
# missing and FME_BIN is unset.
waters=(I II III 1C 3C 5C 7C)
layouts=(A B C D E F)
gen() { # split first_seed count
  local split=$1 seed=$2 n=$3 i
  for ((i = 0; i < n; i++)); do
    local s=$((seed + i)) w=${waters[$(((seed + i) % 7))]} l=${layouts[$(((seed + i) % 6))]}
    local fish=$((20 + (s * 7919) % 41))
    local out="$DATA/$split/swarm-s$s-$w-$l-f$fish"
    [ -f "$out/seqinfo.ini" ] && continue
    nice -n "$NICE" "$FME_BIN" synth --preset swarm --fish "$fish" --frames "$FRAMES" --seed "$s" \
      --water "$w" --layout "$l" --out "$out" --force >/dev/null
  done
}

real_recipe_renders() { # count
  if [ "$(find "$DATA/train" -maxdepth 2 -name seqinfo.ini 2>/dev/null | wc -l)" -ge "$1" ] &&
    [ "$(find "$DATA/val" -maxdepth 2 -name seqinfo.ini 2>/dev/null | wc -l)" -ge 14 ]; then
    return 0
  fi
  if [ -z "${FME_BIN:-}" ]; then
    (cd "$ROOT" && cargo build --release --locked --bin fme)
    FME_BIN="$ROOT/target/release/fme"
  fi
  gen train 1000 "$1"
  gen val 9000 14
}
