# Sourced by train.sh and train_real.sh: `gen SPLIT FIRST_SEED COUNT` renders swarm sequences with
# `fme synth` into $DATA/SPLIT (every water type I..7C, layouts A..F, 20-60 fish), skipping those
# already there. Needs FME_BIN, DATA, FRAMES and NICE.
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
