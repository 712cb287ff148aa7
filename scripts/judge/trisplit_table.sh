#!/usr/bin/env bash
# Triangle-split probe (session 39): synthetic shapes converted as a triangle mesh usually
# is made a quad mesh (`synth --triangle-split`: each quad cut into two triangles, each
# triangle into three quads around its centroid), one per family at seeds 101-109 (streams
# no dataset draws from), each clean and with 10% noise points, reconstructed and scored
# against its ground truth. One markdown row per shape: clean P / R / W, then with noise;
# the last row the mean F1 (of P and R) over all clouds. Extra reconstruct options:
# RECONSTRUCT_ARGS (e.g. "--model M").
#   scripts/judge/trisplit_table.sh BIN [OUTDIR]
set -euo pipefail
BIN=$1; OUT=${2:-out/trisplit}
mkdir -p "$OUT"
echo "| shape | points | clean P / R / watertight | 10% noise P / R / watertight |"
echo "|---|---|---|---|"
seed=101; f1s=()
for shape in grid height_field cube cube_sphere torus tube cylinder cage_smooth cage_sharp; do
  row="| $shape"
  for noise in 0 0.1; do
    "$BIN" synth --shape "$shape" --seed "$seed" --triangle-split --noise "$noise" -o "$OUT/$shape-$noise.xyz" --gt "$OUT/$shape.obj" --quiet
    [ "$noise" = 0 ] && row="$row | $(grep -c '^v ' "$OUT/$shape.obj")"
    "$BIN" reconstruct "$OUT/$shape-$noise.xyz" -o "$OUT/$shape-$noise.obj" --quiet ${RECONSTRUCT_ARGS:-}
    s=$("$BIN" eval "$OUT/$shape-$noise.obj" --gt "$OUT/$shape.obj" --json | python3 -c 'import json,sys; d=json.load(sys.stdin); p,r=d["precision"],d["recall"]; print("%.3f / %.3f / %.3f %.6f" % (p, r, d["watertightness"], 2*p*r/(p+r) if p+r>0 else 0))')
    row="$row | ${s% *}"; f1s+=("${s##* }")
  done
  echo "$row |"; seed=$((seed + 1))
done
python3 -c 'import sys; v=[float(x) for x in sys.argv[1:]]; print("| **mean F1** | %d clouds | %.4f | |" % (len(v), sum(v)/len(v)))' "${f1s[@]}"
