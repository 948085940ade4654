"""Reader for the FEM mesh frames `pnet simulate` writes (cpp/pnet/io/ply.hpp, PlyMesh).

    ply / format binary_little_endian 1.0 / comment plasticitynet mesh / comment dim D
    element vertex n    property double x y z vx vy vz
    element face m      property list uchar int vertex_indices, property double hardening
    end_header

2D frames hold every node and the triangles (z = 0); 3D frames every node and the
boundary triangles, each with the hardening of the tetrahedron it bounds.

Anything else is refused with ValueError naming the file and the problem.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

_VERTEX = np.dtype([(name, "<f8") for name in ("x", "y", "z", "vx", "vy", "vz")])
_FACE = np.dtype([("count", "u1"), ("nodes", "<i4", (3,)), ("hardening", "<f8")])


@dataclass
class MeshFrame:
    position: np.ndarray   # (n, dim), m
    velocity: np.ndarray   # (n, dim), m/s
    triangles: np.ndarray  # (m, 3) node indices (3D: the boundary faces)
    hardening: np.ndarray  # (m,)
    dim: int = 2


def read_mesh_ply(path: str | Path) -> MeshFrame:
    path = Path(path)
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ValueError(f"{path}: not a PLY file with an end_header line")
    header = [line.strip() for line in data[:end].decode("ascii", "replace").splitlines()]
    words = [line.split() for line in header if line and not line.startswith(("comment", "obj_info"))]
    expected = [["ply"], ["format", "binary_little_endian", "1.0"], ["element", "vertex", "#"]]
    expected += [["property", "double", p] for p in _VERTEX.names]
    expected += [["element", "face", "#"], ["property", "list", "uchar", "int", "vertex_indices"],
                 ["property", "double", "hardening"]]
    if len(words) != len(expected):
        raise ValueError(f"{path}: not a plasticitynet mesh frame (header has {len(words)} lines, expected {len(expected)})")
    counts = []
    for got, want in zip(words, expected):
        if want[-1] == "#":
            if got[:-1] != want[:-1] or len(got) != 3 or not got[2].isdigit():
                raise ValueError(f"{path}: header line {' '.join(got)!r}: expected {' '.join(want[:-1])} <count>")
            counts.append(int(got[2]))
        elif got != want:
            raise ValueError(f"{path}: header line {' '.join(got)!r}: expected {' '.join(want)!r}")
    n, m = counts
    body = data[end + len(b"end_header\n"):]
    if len(body) != n * _VERTEX.itemsize + m * _FACE.itemsize:
        raise ValueError(f"{path}: {len(body)} bytes of data for {n} vertices and {m} faces")
    vertices = np.frombuffer(body, _VERTEX, n)
    faces = np.frombuffer(body, _FACE, m, offset=n * _VERTEX.itemsize)
    if m and (np.any(faces["count"] != 3) or faces["nodes"].min() < 0 or faces["nodes"].max() >= n):
        raise ValueError(f"{path}: a face is not a triangle of existing vertices")
    dims = [line.split()[2] for line in header if line.startswith("comment dim ") and len(line.split()) == 3]
    dim = int(dims[0]) if dims and dims[0] in ("2", "3") else 2
    axes = ("x", "y", "z")[:dim]
    return MeshFrame(position=np.stack([vertices[a] for a in axes], axis=1),
                     velocity=np.stack([vertices["v" + a] for a in axes], axis=1),
                     triangles=faces["nodes"].astype(np.int64), hardening=faces["hardening"].copy(), dim=dim)
