"""The frames `pnet simulate` writes, read by the simulator's own readers (plasticitynet_sim, the C++ of
cpp/pnet/io/ply.hpp): one reader of each format for C++ and Python; and the inside-body test a coupled run is checked with.

A particle frame holds position, velocity, mass and hardening per particle; a mesh frame (FEM, or
frame_NNNNN_mesh.ply of a coupled run) every node with its velocity and the triangles (2D: the elements;
3D: the boundary triangles), each with its element's hardening. A missing file raises FileNotFoundError;
anything else than such a frame raises ValueError naming the file and the problem.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


def _sim():
    import plasticitynet_sim  # the C++ readers; imported on first use (training needs no simulator)

    return plasticitynet_sim


@dataclass
class MeshFrame:
    position: np.ndarray   # (n, dim), m
    velocity: np.ndarray   # (n, dim), m/s
    triangles: np.ndarray  # (m, 3) node indices (3D: the boundary faces)
    hardening: np.ndarray  # (m,)
    dim: int = 2


def read_mesh_ply(path: str | Path) -> MeshFrame:
    d = _sim().read_mesh_frame(str(path))
    return MeshFrame(position=d["position"], velocity=d["velocity"], triangles=d["triangles"],
                     hardening=d["hardening"], dim=d["dim"])


def read_particle_positions(path: str | Path) -> np.ndarray:
    """(n, dim) float64 particle positions of a particle frame, m."""
    return _sim().read_particle_frame(str(path))["position"]


def inside_count(points: np.ndarray, nodes: np.ndarray, facets: np.ndarray) -> int:
    """How many points lie inside (or on) the body a frame's closed boundary bounds (facets: edges in 2D,
    triangles in 3D), by the simulator's own test (plasticitynet_sim.inside_count)."""
    return int(_sim().inside_count(np.ascontiguousarray(points, dtype=np.float64),
                                   np.ascontiguousarray(nodes, dtype=np.float64), np.asarray(facets)))
