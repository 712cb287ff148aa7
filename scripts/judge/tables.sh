#!/usr/bin/env bash
# The judge's tables for one model (docs/EXPERIMENTS.md, "The judge"): the quality table
# (scripts/quality_table.sh, 10% noise points, synth seed 1) on each set, and the
# generality probe (scripts/probe_table.sh). A table already complete is kept, so an
# interrupted run resumes. EXTRA is given to every `reconstruct` (e.g. "--rounds 5");
# SYNTH_ARGS moves the clouds' vertices too (e.g. "--jitter 0.05"; then no probe).
#   scripts/judge/tables.sh SEED TAG MODEL [EXTRA]   -> $JUDGE/t_TAGSEED_SET.md, probe_TAGSEED.md
set -euo pipefail
S=$1; TAG=$2; MODEL=$3; EXTRA=${4:-}
BIN=${BIN:-target/release/point2quad}; JUDGE=${JUDGE:-out/judge}; SETS=${SETS:-$JUDGE/sets}
[ -d "$SETS/organic" ] || { echo "tables.sh: no sets in $SETS (run scripts/judge/sets.sh)" >&2; exit 1; }
mkdir -p "$JUDGE"
for set in organic thin val coarse; do
  f=$JUDGE/t_${TAG}${S}_$set.md
  if [ -s "$f" ] && grep -q "mean of" "$f"; then continue; fi
  RECONSTRUCT_ARGS="$EXTRA" scripts/quality_table.sh "$BIN" "$SETS/$set" 0.1 "$MODEL" "$JUDGE/o_${TAG}${S}_$set" > "$f.tmp"
  mv "$f.tmp" "$f"
done
f=$JUDGE/probe_${TAG}${S}.md
if [ -z "${SYNTH_ARGS:-}" ] && ! [ -s "$f" ]; then
  RECONSTRUCT_ARGS="--model $MODEL $EXTRA" scripts/probe_table.sh "$BIN" "$JUDGE/po_${TAG}${S}" > "$f.tmp"
  mv "$f.tmp" "$f"
fi
echo "tables.sh: seed $S, tag $TAG done"
