# Sourced by the recipes: `gen SPLIT FIRST_SEED COUNT` renders swarm sequences with `fme synth` into
# $DATA/SPLIT (every water type I..7C, layouts A..F, 20-60 fish), skipping those already there. Needs
# FME_BIN, DATA, FRAMES and NICE. `gen_close SPLIT FIRST_SEED COUNT` renders close-fish sequences into
# $DATA/close-SPLIT: 6-20 fish of 0.7-1.4 m in clear and blue water, no reference cubes, so that the
# fish are large (long side up to about half the frame), overlap and stand against the pen's walls and
# floor: what a tank or cage camera near the fish sees and the swarm renders (about 3 % of boxes of
# 128 px and more) lack. `real_recipe_renders COUNT [CLOSE]` is the real-fish recipes' share: COUNT
# training sequences from seed 1000 and the 14 held-out ones, and CLOSE close-fish training
# sequences from seed 5000 with 8 held-out ones from seed 9500 (none when CLOSE is 0 or absent),
# building fme (ROOT) only when some are missing and FME_BIN is unset.
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

close_waters=(I II 1C 3C)
gen_close() { # split first_seed count
  local split=$1 seed=$2 n=$3 i
  for ((i = 0; i < n; i++)); do
    local s=$((seed + i)) w=${close_waters[$(((seed + i) % 4))]}
    local fish=$((6 + (s * 7919) % 15)) cm=$((70 + (s * 104729) % 71))
    local out="$DATA/close-$split/close-s$s-$w-f$fish-l$cm"
    [ -f "$out/seqinfo.ini" ] && continue
    nice -n "$NICE" "$FME_BIN" synth --preset swarm --fish "$fish" --frames "$FRAMES" --seed "$s" \
      --water "$w" --layout none --fish-length "$(printf '%d.%02d' $((cm / 100)) $((cm % 100)))" \
      --out "$out" --force >/dev/null
  done
}

count_seqs() { find "$1" -maxdepth 2 -name seqinfo.ini 2>/dev/null | wc -l; }

real_recipe_renders() { # count [close]
  local close=${2:-0}
  if [ "$(count_seqs "$DATA/train")" -ge "$1" ] && [ "$(count_seqs "$DATA/val")" -ge 14 ] &&
    { [ "$close" = 0 ] || { [ "$(count_seqs "$DATA/close-train")" -ge "$close" ] &&
      [ "$(count_seqs "$DATA/close-val")" -ge 8 ]; }; }; then
    return 0
  fi
  if [ -z "${FME_BIN:-}" ]; then
    (cd "$ROOT" && cargo build --release --locked --bin fme)
    FME_BIN="$ROOT/target/release/fme"
  fi
  gen train 1000 "$1"
  gen val 9000 14
  if [ "$close" != 0 ]; then
    gen_close train 5000 "$close"
    gen_close val 9500 8
  fi
}
