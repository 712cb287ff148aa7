#!/usr/bin/env bash
# The clouds session 35 fitted the learned noise test on (examples/noise_test_fit.rs), none
# of them from the judge's twelve meshes: 40 random synthetic shapes (synth seeds
# 1000-1039), the other `train/` meshes (synth seed 3), their chord-collapsed copies at 60%
# (coarsen_mesh --fraction 0.6 --seed 2, synth seed 4) and jittered copies (synth --jitter
# 0.03, seed 5), 10% noise points each. Writes OUT/list.txt: one "CLOUD V" per line, V the
# number of mesh vertices the cloud starts with.
#   scripts/judge/noise_test_data.sh OUT       (BIN: target/release/point2quad; needs ../shared)
set -euo pipefail
OUT=$1; BIN=${BIN:-target/release/point2quad}; TRAIN=${TRAIN_MESHES:-../shared/data/quads/train}
JUDGE_MESHES=" qm_monkey qm_elephant qm_feline thingi_1036393 thingi_88580 thingi_132442 thingi_113418 thingi_129929 thingi_1312954 thingi_136243 thingi_1450321 thingi_49382 "
mkdir -p "$OUT/coarse"
: > "$OUT/list.txt.tmp"
add() { # CLOUD GT
  echo "$1 $(grep -c '^v ' "$2")" >> "$OUT/list.txt.tmp"
}
for s in $(seq 1000 1039); do
  "$BIN" --quiet synth --shape random --seed "$s" -o "$OUT/syn_$s.xyz" --gt "$OUT/syn_$s.gt.obj"
  add "$OUT/syn_$s.xyz" "$OUT/syn_$s.gt.obj"
done
meshes=()
for f in "$TRAIN"/*; do
  n=$(basename "${f%.*}")
  case "$JUDGE_MESHES" in *" $n "*) continue ;; esac
  meshes+=("$f")
  "$BIN" --quiet synth --from "$f" --seed 3 -o "$OUT/tr_$n.xyz" --gt "$OUT/tr_$n.gt.obj"
  add "$OUT/tr_$n.xyz" "$OUT/tr_$n.gt.obj"
done
cargo build --release --quiet --example coarsen_mesh
target/release/examples/coarsen_mesh --fraction 0.6 --seed 2 --out "$OUT/coarse" "${meshes[@]}" >/dev/null
for f in "$OUT"/coarse/*.obj; do
  n=$(basename "${f%.*}")
  "$BIN" --quiet synth --from "$f" --seed 4 -o "$OUT/co_$n.xyz" --gt "$OUT/co_$n.gt.obj"
  add "$OUT/co_$n.xyz" "$OUT/co_$n.gt.obj"
done
for f in "${meshes[@]}"; do
  n=$(basename "${f%.*}")
  "$BIN" --quiet synth --from "$f" --seed 5 --jitter 0.03 -o "$OUT/ji_$n.xyz" --gt "$OUT/ji_$n.gt.obj"
  add "$OUT/ji_$n.xyz" "$OUT/ji_$n.gt.obj"
done
mv "$OUT/list.txt.tmp" "$OUT/list.txt"
echo "noise_test_data.sh: $(wc -l < "$OUT/list.txt") clouds in $OUT/list.txt"
