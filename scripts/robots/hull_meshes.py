#!/usr/bin/env python3
"""Write the convex hull of each STL mesh as a small binary STL.

Usage: scripts/robots/hull_meshes.py IN_DIR OUT_DIR   (needs python3 with numpy and scipy)

Every `*.stl` under IN_DIR (binary or ASCII) is read, the convex hull of its vertices computed
(scipy's Qhull) and written to the same relative path under OUT_DIR, triangles facing outwards.
calsim fits one bounding capsule per link around its collision meshes, and that capsule depends on
the mesh's extreme points only (src/robot/capsule_fit.rs), so a hull gives the same capsules at a
fraction of the size: this is how the meshes shipped under robots/ were reduced. Exit 2 on bad
input, with one line naming the file.
"""
import struct
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull


def read_stl(path: Path) -> np.ndarray:
    data = path.read_bytes()
    if len(data) >= 84:
        n = struct.unpack_from("<I", data, 80)[0]
        if 84 + 50 * n == len(data):
            rec = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count=n, offset=84)
            return rec["v"].reshape(-1, 3).astype(np.float64)
    text = data.decode("ascii", errors="strict")
    verts = [[float(x) for x in line.split()[1:4]] for line in text.splitlines() if line.strip().startswith("vertex")]
    if not verts:
        raise ValueError("no vertices")
    return np.array(verts)


def write_stl(path: Path, points: np.ndarray, hull: ConvexHull) -> None:
    centre = points[hull.vertices].mean(axis=0)
    out = bytearray(b"convex hull written by scripts/robots/hull_meshes.py".ljust(80, b" "))
    out += struct.pack("<I", len(hull.simplices))
    for tri in hull.simplices:
        a, b, c = points[tri]
        normal = np.cross(b - a, c - a)
        if np.dot(normal, a - centre) < 0:  # face outwards
            b, c = c, b
            normal = -normal
        norm = np.linalg.norm(normal)
        normal = normal / norm if norm > 0 else normal
        out += struct.pack("<12fH", *normal, *a, *b, *c, 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(out))


def main(src: Path, dst: Path) -> int:
    files = sorted(src.rglob("*.stl"))
    if not files:
        print(f"hull_meshes: {src}: no .stl file", file=sys.stderr)
        return 2
    for f in files:
        try:
            points = np.unique(read_stl(f), axis=0)
            hull = ConvexHull(points)
        except Exception as e:  # one line naming the file
            print(f"hull_meshes: {f}: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
            return 2
        out = dst / f.relative_to(src)
        write_stl(out, points, hull)
        print(f"{f.relative_to(src)}: {len(points)} vertices -> {len(hull.vertices)} on the hull, {out.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        sys.exit(2)
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
