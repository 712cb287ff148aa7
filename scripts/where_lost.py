#!/usr/bin/env python3
"""Where the missing faces and the boundary edges of reconstructions lie (session 41).

    scripts/where_lost.py BIN OUTDIR

OUTDIR is a folder `scripts/quality_table.sh` wrote (NAME.xyz clouds and NAME.obj
reconstructions, default options). For each NAME the ground truth is taken again with
`BIN synth --from MESH --noise N --seed 1 --gt` as quality_table.sh does (MESH_DIR and N
from the environment: MESH_DIR, default ../shared/data/quads/eval; NOISE, default 0.1),
and the cloud it writes must equal OUTDIR/NAME.xyz byte for byte, so that the cloud's
first points are the ground truth's vertices in order and the output's vertex indices
are the ground truth's. The candidates are `BIN candidates` on the same cloud (the first
pass's; the second pass's are not counted).

Prints per mesh, and summed:
- missing: ground-truth faces not in the output;
  - displaced: a candidate, but an edge of it is taken by an output face running it the
    same way or by two output faces (a wrong face took its place);
  - not cand. / displaced: the same, not even a candidate;
  - addable: no such conflict (it could be added as it is), split into candidate or not;
- boundary edges of the output, those that are no ground-truth edge, and those whose one
  face is a wrong face (not a ground-truth face).
"""
import collections
import os
import subprocess
import sys


def faces_of(path):
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("f "):
                out.append(tuple(int(t.split("/")[0]) - 1 for t in line.split()[1:]))
    return out


def edges(f):
    return [(f[i], f[(i + 1) % len(f)]) for i in range(len(f))]


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    binary, outdir = sys.argv[1], sys.argv[2]
    mesh_dir = os.environ.get("MESH_DIR", "../shared/data/quads/eval")
    noise = os.environ.get("NOISE", "0.1")
    work = os.path.join(outdir, "where_lost")
    os.makedirs(work, exist_ok=True)
    keys = ["gt", "out", "missing", "displaced", "not cand. displaced", "addable cand.",
            "addable not cand.", "boundary", "boundary not GT edge", "boundary on wrong face"]
    total = collections.Counter()
    print("| mesh | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for mesh in sorted(os.listdir(mesh_dir)):
        name, ext = os.path.splitext(mesh)
        if ext.lower() not in (".obj", ".off", ".ply"):
            continue
        cloud, pred = os.path.join(outdir, name + ".xyz"), os.path.join(outdir, name + ".obj")
        if not (os.path.exists(cloud) and os.path.exists(pred)):
            continue
        gt_cloud, gt = os.path.join(work, name + ".xyz"), os.path.join(work, name + ".gt.obj")
        cand = os.path.join(work, name + ".cand.txt")
        subprocess.run([binary, "synth", "--from", os.path.join(mesh_dir, mesh), "--noise", noise,
                        "--seed", "1", "-o", gt_cloud, "--gt", gt, "--quiet"], check=True)
        with open(gt_cloud, "rb") as a, open(cloud, "rb") as b:
            same = a.read() == b.read()
        if not same:
            sys.exit(f"{cloud}: not the cloud `synth --from {mesh} --noise {noise} --seed 1` writes")
        subprocess.run([binary, "candidates", cloud, "-o", cand, "--quiet"], check=True)
        G, O = faces_of(gt), faces_of(pred)
        with open(cand) as f:
            C = {frozenset(map(int, l.split())) for l in f if l.strip()}
        gt_keys = {frozenset(f) for f in G}
        out_keys = {frozenset(f) for f in O}
        gt_edges = {frozenset(e) for f in G for e in edges(f)}
        per_edge = collections.defaultdict(list)
        directed = set()
        for f in O:
            for e in edges(f):
                per_edge[frozenset(e)].append(f)
                directed.add(e)
        c = collections.Counter(gt=len(G), out=len(O))
        for f in G:
            if frozenset(f) in out_keys:
                continue
            c["missing"] += 1
            conflict = any(len(per_edge[frozenset(e)]) >= 2 or e in directed for e in edges(f))
            is_cand = frozenset(f) in C
            if conflict:
                c["displaced" if is_cand else "not cand. displaced"] += 1
            else:
                c["addable cand." if is_cand else "addable not cand."] += 1
        for e, fs in per_edge.items():
            if len(fs) == 1:
                c["boundary"] += 1
                c["boundary not GT edge"] += e not in gt_edges
                c["boundary on wrong face"] += frozenset(fs[0]) not in gt_keys
        total += c
        print(f"| {name} | " + " | ".join(str(c[k]) for k in keys) + " |")
    print("| **total** | " + " | ".join(str(total[k]) for k in keys) + " |")


if __name__ == "__main__":
    main()
