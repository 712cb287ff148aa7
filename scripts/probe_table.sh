#!/usr/bin/env bash
# Generality probe: the small shapes of scripts/probe_shapes.py, each as a clean cloud (its
# vertices) and with 10% noise points (`synth --from MESH --seed 1`), reconstructed and
# scored against the ground truth. One markdown row per shape: clean P / R / watertight,
# then the same with noise. Extra reconstruct options: RECONSTRUCT_ARGS.
#   scripts/probe_table.sh BIN [OUTDIR]
set -euo pipefail
BIN=$1; OUT=${2:-out/probe}
mkdir -p "$OUT"
python3 "$(dirname "$0")/probe_shapes.py" "$OUT/gt"
score() { # PRED GT -> "P / R / W"
  "$BIN" eval "$1" --gt "$2" --json | python3 -c 'import json,sys; d=json.load(sys.stdin); print("%.3f / %.3f / %.3f" % (d["precision"], d["recall"], d["watertightness"]))'
}
echo "| shape | points | clean P / R / watertight | 10% noise P / R / watertight |"
echo "|---|---|---|---|"
for gt in "$OUT"/gt/*.obj; do
  name=$(basename "${gt%.obj}")
  row="| $name | $(grep -c '^v ' "$gt")"
  for noise in 0 0.1; do
    "$BIN" synth --from "$gt" --noise "$noise" --seed 1 -o "$OUT/$name-$noise.xyz" 2>/dev/null
    "$BIN" reconstruct "$OUT/$name-$noise.xyz" -o "$OUT/$name-$noise.obj" ${RECONSTRUCT_ARGS:-} 2> "$OUT/$name-$noise.log"
    row="$row | $(score "$OUT/$name-$noise.obj" "$gt" 2>/dev/null)"
  done
  echo "$row |"
done
