#!/usr/bin/env python3
"""Tiles a binary STL NX x NY times in its x-y plane (a gap of 5 % of its size
between copies): a large real mesh from a real one, with the original's mix of
slivers and tiny facets, for the large-mesh benchmarks (bench/study_gpu.sh).
Usage: tile_stl.py IN.stl OUT.stl NX NY"""
import struct
import sys


def main():
    src, dst, nx, ny = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    data = open(src, "rb").read()
    (n,) = struct.unpack_from("<I", data, 80)
    if len(data) != 84 + 50 * n:
        sys.exit(f"{src}: not a binary STL")
    tris = [struct.unpack_from("<12fH", data, 84 + 50 * k) for k in range(n)]
    xs = [t[c] for t in tris for c in (3, 6, 9)]
    ys = [t[c] for t in tris for c in (4, 7, 10)]
    dx, dy = 1.05 * (max(xs) - min(xs)), 1.05 * (max(ys) - min(ys))
    with open(dst, "wb") as f:
        f.write(b"tiled by bench/tile_stl.py".ljust(80, b" "))
        f.write(struct.pack("<I", n * nx * ny))
        for i in range(nx):
            for j in range(ny):
                ox, oy = i * dx, j * dy
                for t in tris:
                    v = list(t)
                    for c in (3, 6, 9):
                        v[c] += ox
                        v[c + 1] += oy
                    f.write(struct.pack("<12fH", *v))


if __name__ == "__main__":
    main()
