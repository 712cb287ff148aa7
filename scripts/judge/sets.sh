#!/usr/bin/env bash
# The judge's mesh sets (docs/EXPERIMENTS.md, "The judge"): the six `train/` meshes the
# judge's classifiers hold out (organic: qm_monkey, qm_elephant, qm_feline; thin shells:
# thingi_1036393, thingi_88580, thingi_132442), the six meshes of the validation split
# (val), and all twelve coarsened by chord collapse to about 30% of their faces (coarse,
# reported only). organic, thin and val hold links to the shared meshes.
#   scripts/judge/sets.sh [OUT]          (default out/judge/sets; needs ../shared)
set -euo pipefail
OUT=${1:-out/judge/sets}
TRAIN=${TRAIN_MESHES:-../shared/data/quads/train}
[ -d "$TRAIN" ] || { echo "sets.sh: $TRAIN not found (the judge reads the shared train/ meshes)" >&2; exit 1; }
TRAIN=$(cd "$TRAIN" && pwd)
declare -A SETS=(
  [organic]="qm_monkey.obj qm_elephant.obj qm_feline.off"
  [thin]="thingi_1036393.obj thingi_88580.obj thingi_132442.obj"
  [val]="thingi_113418.obj thingi_129929.obj thingi_1312954.obj thingi_136243.obj thingi_1450321.obj thingi_49382.obj"
)
all=()
for set in organic thin val; do
  mkdir -p "$OUT/$set"
  for f in ${SETS[$set]}; do
    [ -f "$TRAIN/$f" ] || { echo "sets.sh: $TRAIN/$f not found" >&2; exit 1; }
    ln -sfn "$TRAIN/$f" "$OUT/$set/$f"
    all+=("$TRAIN/$f")
  done
done
cargo build --release --quiet --example coarsen_mesh
mkdir -p "$OUT/coarse"
target/release/examples/coarsen_mesh --fraction 0.3 --seed 1 --out "$OUT/coarse" "${all[@]}" >/dev/null
echo "sets.sh: organic, thin, val and coarse in $OUT"
