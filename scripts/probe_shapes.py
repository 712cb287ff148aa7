#!/usr/bin/env python3
"""Small ground-truth quad meshes that probe generality: tiny grids and cubes, short tubes,
tiny tori, anisotropic and graded quads, two scales in one cloud. Writes one OBJ per shape
into OUTDIR. Used by scripts/probe_table.sh; none of these shapes is in any training set.

    python3 scripts/probe_shapes.py OUTDIR
"""
import math
import os
import sys


def write(outdir, name, verts, faces):
    with open(os.path.join(outdir, name + ".obj"), "w") as f:
        for v in verts:
            f.write("v %.9f %.9f %.9f\n" % tuple(v))
        for q in faces:
            f.write("f %d %d %d %d\n" % tuple(i + 1 for i in q))


def sheet(xs, ys, z=lambda x, y: 0.0):
    verts = [(x, y, z(x, y)) for y in ys for x in xs]
    nx = len(xs)
    faces = [(j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i)
             for j in range(len(ys) - 1) for i in range(nx - 1)]
    return verts, faces


def box(n, sx=1.0, sy=1.0, sz=1.0):
    """Surface of a box, n cells along every edge, outward faces."""
    index, verts, faces = {}, [], []

    def vid(p):
        key = tuple(p)
        if key not in index:
            index[key] = len(verts)
            verts.append((p[0] * sx / n, p[1] * sy / n, p[2] * sz / n))
        return index[key]

    for axis in range(3):
        a, b = [ax for ax in range(3) if ax != axis]
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    def corner(u, v):
                        p = [0, 0, 0]
                        p[axis], p[a], p[b] = side, u, v
                        return vid(p)
                    q = [corner(i, j), corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)]
                    if (side == 0) ^ (axis == 1):
                        q.reverse()
                    faces.append(q)
    return verts, faces


def tube(n, m, height):
    """Open cylinder: n quads around, m rings of quads of the given height."""
    verts = [(math.cos(2 * math.pi * i / n), math.sin(2 * math.pi * i / n), j * height)
             for j in range(m + 1) for i in range(n)]
    faces = [(j * n + i, j * n + (i + 1) % n, (j + 1) * n + (i + 1) % n, (j + 1) * n + i)
             for j in range(m) for i in range(n)]
    return verts, faces


def torus(n, m, big=1.0, small=0.45):
    verts = []
    for j in range(m):
        for i in range(n):
            u, v = 2 * math.pi * i / n, 2 * math.pi * j / m
            r = big + small * math.cos(v)
            verts.append((r * math.cos(u), r * math.sin(u), small * math.sin(v)))
    faces = [(j * n + i, j * n + (i + 1) % n, ((j + 1) % m) * n + (i + 1) % n, ((j + 1) % m) * n + i)
             for j in range(m) for i in range(n)]
    return verts, faces


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    for nx, ny in [(2, 2), (2, 3), (3, 3), (3, 4), (5, 2), (5, 3), (2, 6), (4, 4), (6, 6)]:
        write(out, "grid%dx%d" % (nx, ny), *sheet(range(nx), range(ny)))
    for nx, ny in [(3, 3), (4, 3), (6, 4), (8, 5)]:
        write(out, "bent%dx%d" % (nx, ny),
              *sheet(range(nx), range(ny), lambda x, y, nx=nx: 0.15 * (x - nx / 2) ** 2))
    for n in (1, 2, 3, 6):
        write(out, "cube%d" % n, *box(n))
    write(out, "box_4to1", *box(6, 1, 1, 4))
    small = box(6)
    verts = [(x * 0.05 + 3, y * 0.05, z * 0.05) for x, y, z in small[0]] + list(small[0])
    faces = list(small[1]) + [tuple(i + len(small[0]) for i in q) for q in small[1]]
    write(out, "two_scales", verts, faces)
    xs, h = [0.0], 0.02
    for _ in range(30):
        xs.append(xs[-1] + h)
        h *= 1.12
    write(out, "graded", *sheet(xs, [0.05 * j for j in range(21)], lambda x, y: 0.1 * math.sin(3 * x)))
    write(out, "tube8x2", *tube(8, 2, 2 * math.pi / 8))
    write(out, "tube12x3", *tube(12, 3, 2 * math.pi / 12))
    write(out, "tube24x6_3to1", *tube(24, 6, 3 * 2 * math.pi / 24))
    write(out, "torus8x4", *torus(8, 4))
    write(out, "torus12x6", *torus(12, 6))


if __name__ == "__main__":
    main()
