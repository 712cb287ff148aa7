#!/usr/bin/env bash
# Quality on a folder of ground-truth quad meshes (DESIGN §7): for each mesh, sample a
# cloud (its vertices + NOISE × #vertices noise points, seed 1), reconstruct, and
# compare with the ground truth. Prints one markdown row per mesh and the means.
#   scripts/quality_table.sh BIN MESH_DIR [NOISE] [MODEL] [OUTDIR]
# MODEL is a weights file, or a comma list of them (an ensemble: reconstruct --model A,B).
# Extra reconstruct options can be given in RECONSTRUCT_ARGS (e.g. "--threshold 0.7").
# Extra synth options in SYNTH_ARGS (e.g. "--jitter 0.02": vertices moved too); the
# ground truth is then the mesh synth writes (--gt), not the file in MESH_DIR.
# SHUFFLE=S shuffles each cloud's points (seed S) before reconstructing: synth writes the
# mesh's vertices first and noise points last, an order no scanner gives (session 30).
# POSE=S moves each cloud and its ground truth alike by a random rotation, a uniform scale
# 10^U(-3, 3) and an offset of up to 1000 times that scale per axis (seed S and the mesh's
# name; session 40): the same table in another pose, scale and place.
# Example: scripts/quality_table.sh target/release/point2quad ../shared/data/quads/eval 0.1
set -euo pipefail
BIN=$1; DIR=$2; NOISE=${3:-0.1}; MODEL=${4:-}; OUT=${5:-out/quality}
mkdir -p "$OUT"
JSONL="$OUT/metrics_noise${NOISE}.jsonl"; : > "$JSONL"
for f in "$DIR"/*.obj "$DIR"/*.off "$DIR"/*.ply; do
  [ -e "$f" ] || continue
  name=$(basename "${f%.*}")
  ref=$f
  gtarg=()
  if [ -n "${SYNTH_ARGS:-}${POSE:-}" ]; then ref=$OUT/$name.gt.obj; gtarg=(--gt "$ref"); fi
  "$BIN" synth --from "$f" --noise "$NOISE" --seed 1 -o "$OUT/$name.xyz" ${gtarg[@]+"${gtarg[@]}"} ${SYNTH_ARGS:-} 2>/dev/null
  if [ -n "${POSE:-}" ]; then
    python3 - "$OUT/$name.xyz" "$ref" "$POSE" "$name" <<'PY'
import math, random, sys
cloud, gt, seed, name = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
r = random.Random(f"{seed}:{name}")
q = [r.gauss(0, 1) for _ in range(4)]
n = math.sqrt(sum(x * x for x in q))
a, b, c, d = (x / n for x in q)
R = [[a*a + b*b - c*c - d*d, 2*(b*c - a*d), 2*(b*d + a*c)],
     [2*(b*c + a*d), a*a - b*b + c*c - d*d, 2*(c*d - a*b)],
     [2*(b*d - a*c), 2*(c*d + a*b), a*a - b*b - c*c + d*d]]
s = 10 ** r.uniform(-3, 3)
t = [1000 * s * r.uniform(-1, 1) for _ in range(3)]
def move(p):
    return "%.17g %.17g %.17g" % tuple(s * sum(R[i][j] * p[j] for j in range(3)) + t[i] for i in range(3))
def rewrite(path, is_obj):
    out = []
    for line in open(path):
        w = line.split()
        if is_obj and w and w[0] == "v":
            out.append("v " + move([float(x) for x in w[1:4]]) + "\n")
        elif not is_obj and w and not line.startswith("#"):
            out.append(move([float(x) for x in w[:3]]) + "\n")
        else:
            out.append(line)
    open(path, "w").writelines(out)
rewrite(cloud, False)
rewrite(gt, True)
PY
  fi
  if [ -n "${SHUFFLE:-}" ]; then
    python3 - "$OUT/$name.xyz" "$SHUFFLE" <<'PY'
import random, sys
lines = open(sys.argv[1]).readlines()
head = [l for l in lines if l.startswith("#")]
pts = [l for l in lines if not l.startswith("#")]
random.Random(int(sys.argv[2])).shuffle(pts)
open(sys.argv[1], "w").writelines(head + pts)
PY
  fi
  t0=$(date +%s.%N)
  if "$BIN" reconstruct "$OUT/$name.xyz" -o "$OUT/$name.obj" ${MODEL:+--model "$MODEL"} ${RECONSTRUCT_ARGS:-} \
       --svg "$OUT/$name.svg" 2> "$OUT/$name.log"; then
    t1=$(date +%s.%N)
    json=$("$BIN" eval "$OUT/$name.obj" --gt "$ref" --json)
    gt=$("$BIN" eval "$ref" --json)
    echo "{\"name\": \"$name\", \"seconds\": $(python3 -c "print(round($t1 - $t0, 3))"), \"pred\": $json, \"gt\": $gt}" >> "$JSONL"
  else
    echo "{\"name\": \"$name\", \"failed\": true}" >> "$JSONL"
    cat "$OUT/$name.log" >&2
  fi
done
python3 - "$JSONL" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
ok = [r for r in rows if not r.get("failed")]
keys = [("precision", "P"), ("recall", "R"), ("watertightness", "watertight"), ("manifoldness", "manifold"),
        ("nonmanifold_vertices", "nm verts"), ("scaled_jacobian", "SJ"), ("inverted_quads", "SJ ≤ 0"), ("edge_ratio", "edge ratio"),
        ("angle_dev_deg", "angle dev"), ("chamfer", "Chamfer")]
print("| mesh | " + " | ".join(k[1] for k in keys) + " | GT SJ | quad only | s |")
print("|---" * (len(keys) + 4) + "|")
for r in ok:
    p = r["pred"]
    # `null` (Chamfer of an empty prediction) is undefined: n/a, here and in the mean.
    cells = [f"{p[k]:.4f}" if isinstance(p[k], float) else "n/a" if p[k] is None else str(p[k]) for k, _ in keys]
    print(f"| {r['name']} | " + " | ".join(cells) + f" | {r['gt']['scaled_jacobian']:.4f} | {p['quad_only']} | {r['seconds']:.1f} |")
n = len(ok)
if n:
    vals = lambda k: [r["pred"][k] for r in ok]
    # Means, but the count of inverted quads is a total over the meshes.
    cells = ["n/a" if None in vals(k) else str(sum(vals(k))) if k == "inverted_quads" else f"{sum(vals(k)) / n:.4f}" for k, _ in keys]
    gsj = sum(r["gt"]["scaled_jacobian"] for r in ok) / n
    allq = all(r["pred"]["quad_only"] for r in ok)
    print(f"| **mean of {n}** | " + " | ".join(cells) + f" | {gsj:.4f} | {allq} | {sum(r['seconds'] for r in ok)/n:.1f} |")
failed = [r["name"] for r in rows if r.get("failed")]
if failed:
    print("failed:", ", ".join(failed))
PY
