#!/usr/bin/env python3
"""A sheet whose right half is sampled 16x more sparsely than its left, and its reference mesh.

    python3 scripts/sparse_sheet.py DIR   ->  DIR/sheet.ply (340,000 points), DIR/ref.ply

z = 0.05 sin 3x cos 2y over [-1, 1]^2: 320,000 points on x in [-1, 0], 20,000 on x in [0, 1],
with 0.0005 of Gaussian noise in z (binary PLY, float xyz); the reference is a 200 x 200 grid
mesh of the same function. Pack with --up 0,0,1 and compare with `scanatlas eval P --reference
DIR/ref.ply` (docs/BENCHMARKS.md, "Sparse surfaces"). Seeded: the same files every run.
"""
import math
import os
import random
import struct
import sys


def height(x, y):
    return 0.05 * math.sin(3 * x) * math.cos(2 * y)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    random.seed(7)
    pts = []
    for _ in range(320000):  # dense half, x in [-1, 0]
        x = -random.random()
        y = random.uniform(-1, 1)
        pts.append((x, y, height(x, y) + random.gauss(0, 0.0005)))
    for _ in range(20000):  # sparse half, x in [0, 1]: 16x fewer points per area
        x = random.random()
        y = random.uniform(-1, 1)
        pts.append((x, y, height(x, y) + random.gauss(0, 0.0005)))
    with open(os.path.join(out, "sheet.ply"), "wb") as f:
        f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
                b"property float x\nproperty float y\nproperty float z\nend_header\n" % len(pts))
        for p in pts:
            f.write(struct.pack("<fff", *p))
    n = 200
    verts = [(-1 + 2 * i / n, -1 + 2 * j / n) for j in range(n + 1) for i in range(n + 1)]
    faces = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c = a + 1, a + n + 1
            faces += [(a, b, c + 1), (a, c + 1, c)]
    with open(os.path.join(out, "ref.ply"), "wb") as f:
        f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                % (len(verts), len(faces)))
        for x, y in verts:
            f.write(struct.pack("<fff", x, y, height(x, y)))
        for t in faces:
            f.write(struct.pack("<Biii", 3, *t))


if __name__ == "__main__":
    main()
