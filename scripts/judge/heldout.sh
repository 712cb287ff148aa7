#!/usr/bin/env bash
# One held-out judge model (docs/EXPERIMENTS.md, "The judge"): `make train`'s recipe at seed
# SEED with the six judge meshes held out, then ROUNDS refinement rounds. Resumable: the
# classifier checkpoints every epoch and is marked done when finished; the rounds are
# written atomically at the end. TRAIN_ARGS and REFINE_ARGS add options (an arm's).
#   scripts/judge/heldout.sh SEED [ROUNDS] [NAME]   -> $JUDGE/cNAME.p2qm, $JUDGE/rNAME.p2qm
# (NAME defaults to SEED; JUDGE to out/judge; BIN to target/release/point2quad; DATA to
# make train's dataset out/train/data_nv3, which `make train` or scripts/train.sh writes.)
set -euo pipefail
SEED=$1; ROUNDS=${2:-5}; NAME=${3:-$1}
BIN=${BIN:-target/release/point2quad}; JUDGE=${JUDGE:-out/judge}; DATA=${DATA:-out/train/data_nv3}
SIX=qm_monkey,qm_elephant,qm_feline,thingi_1036393,thingi_88580,thingi_132442
[ -f "$DATA/index.txt" ] || { echo "heldout.sh: no dataset in $DATA (run make train, or the dataset line of scripts/train.sh)" >&2; exit 1; }
mkdir -p "$JUDGE"
C=$JUDGE/c$NAME.p2qm; R=$JUDGE/r$NAME.p2qm
if [ ! -f "$C.done" ]; then
  START=(--config default --sign-free-normals ${TRAIN_ARGS:-})
  [ -f "$C.ckpt" ] && START=(--resume "$C.ckpt")
  "$BIN" train --data "$DATA" --out "$C" --epochs 40 --seed "$SEED" --draws first --hold-out "$SIX" "${START[@]}"
  touch "$C.done"
fi
if [ ! -f "$R" ]; then
  "$BIN" refine --data "$DATA" --model "$C" --out "$R.tmp" --rounds "$ROUNDS" --seed 0 --hold-out "$SIX" --draws all ${REFINE_ARGS:-}
  mv "$R.tmp" "$R"
fi
echo "heldout.sh: $R"
