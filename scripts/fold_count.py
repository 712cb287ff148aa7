#!/usr/bin/env python3
"""Folded edges of quad meshes (session 25): interior edges whose two quads' normals
(each the normalised cross product of its diagonals, p2 - p0 and p3 - p1, so for a
consistently oriented mesh comparable across the edge) have a dot product under T.
A quad folded back over its neighbour has a dot near -1; a flat continuation 1.

    scripts/fold_count.py [-t T] MESH.{obj,off} ...   (T defaults to -0.95)

Prints one line per mesh and, for several, the total. OBJ `v`/`f` lines (v/vt/vn forms,
negative indices) and OFF (line by line, as `N OFF`/`NOFF`/`COFF`); faces that are not quads are skipped."""
import math
import sys


def load(path):
    verts, faces = [], []
    with open(path) as f:
        if path.lower().endswith(".off"):
            # Line by line: a header word (OFF, NOFF, COFF, `N OFF`…) with the counts on
            # it or on the next line, then one vertex per line (the first three values;
            # normals and colours after them), then one face per line (count, indices).
            lines = [l.split("#")[0].split() for l in f]
            lines = [l for l in lines if l]
            head = lines.pop(0)
            while head and not head[0][0].isdigit():
                head.pop(0)
            counts = head if head else lines.pop(0)
            nv, nf = int(counts[0]), int(counts[1])
            verts = [tuple(float(x) for x in l[:3]) for l in lines[:nv]]
            faces = [[int(x) for x in l[1:1 + int(l[0])]] for l in lines[nv:nv + nf]]
            return verts, faces
        for line in f:
            s = line.split()
            if not s:
                continue
            if s[0] == "v":
                verts.append(tuple(float(x) for x in s[1:4]))
            elif s[0] == "f":
                idx = [int(t.split("/")[0]) for t in s[1:]]
                faces.append([i - 1 if i > 0 else len(verts) + i for i in idx])
    return verts, faces


def normal(p):
    a = [p[2][i] - p[0][i] for i in range(3)]
    b = [p[3][i] - p[1][i] for i in range(3)]
    c = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    n = math.sqrt(sum(x * x for x in c))
    return tuple(x / n for x in c) if n > 0 else None


def folded(path, t):
    verts, faces = load(path)
    quads = [f for f in faces if len(f) == 4]
    normals = [normal([verts[v] for v in q]) for q in quads]
    edges = {}
    for fi, q in enumerate(quads):
        for k in range(4):
            a, b = q[k], q[(k + 1) % 4]
            edges.setdefault((min(a, b), max(a, b)), []).append(fi)
    count = 0
    for fs in edges.values():
        if len(fs) == 2 and normals[fs[0]] and normals[fs[1]]:
            if sum(x * y for x, y in zip(normals[fs[0]], normals[fs[1]])) < t:
                count += 1
    return len(quads), count


def main(argv):
    t = -0.95
    if len(argv) >= 2 and argv[0] == "-t":
        t = float(argv[1])
        argv = argv[2:]
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    total = 0
    for path in argv:
        n, c = folded(path, t)
        total += c
        print(f"{path}: {n} quads, {c} edges with normal dot < {t}")
    if len(argv) > 1:
        print(f"total: {total} edges with normal dot < {t}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
