#!/usr/bin/env bash
# make demo: reconstruct the shipped noisy example cloud with the shipped weights, write
# the mesh, an SVG preview, and the metrics against the example's ground truth.
set -euo pipefail
BIN=$1; OUT=$2
mkdir -p "$OUT"
CLOUD=fixtures/demo/example.xyz; GT=fixtures/demo/example_gt.obj
echo "== point2quad reconstruct $CLOUD (shipped weights)"
"$BIN" reconstruct "$CLOUD" -o "$OUT/example.obj" --svg "$OUT/example.svg"
echo "== point2quad eval $OUT/example.obj --gt $GT"
"$BIN" eval "$OUT/example.obj" --gt "$GT"
"$BIN" eval "$OUT/example.obj" --gt "$GT" --json > "$OUT/metrics.json"
echo
echo "demo: mesh $OUT/example.obj, preview $OUT/example.svg, metrics $OUT/metrics.json"
