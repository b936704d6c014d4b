"""Normals of triangle meshes: numpy, the per-vertex sums compiled (numba), no I/O.

The one implementation for meshes of any origin: the reconstructed mesh (its GLB export),
the body model's superquadric surface (:mod:`tracking.body.model`, :mod:`tracking.fit`) and
clouds sampled from it. Triangles are ``(F, 3)`` vertex indices into ``(V, 3)`` vertices;
a triangle's normal follows the right-hand rule (counter-clockwise seen from its front).
"""

from __future__ import annotations

import numpy as np

__all__ = ["face_normals", "vertex_normals"]


def _face_cross(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) ``(b - a) x (c - a)`` per triangle: its normal times twice its area."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return np.cross(b - a, c - a)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) unit normals and (F,) areas of the triangles (zero normals for degenerate ones)."""
    cross = _face_cross(vertices, faces)
    norm = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(norm, 1e-300)[:, None], norm / 2


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals: the area-weighted mean of the normals of the vertex's
    triangles (what Open3D's ``compute_vertex_normals`` computes). Zero for a vertex on no
    triangle of non-zero area."""
    from recon.mesh.normals_compiled import summed_face_cross

    # Compiled: numpy's cross products, repeated per corner and summed by np.bincount, were
    # 6.2 ms for MakeHuman's 13,380-vertex body (reshaped hundreds of times by the tracker's
    # shape refinement), 1.5 ms so, the same floats (session 28).
    vertices, faces = np.asarray(vertices), np.asarray(faces)
    if vertices.dtype not in (np.float32, np.float64):
        vertices = vertices.astype(np.float64)
    n = len(vertices)
    if faces.size and (faces.min() < 0 or faces.max() >= n):
        raise IndexError(f"faces index vertices 0..{n - 1}: got {faces.min()}..{faces.max()}")
    summed = summed_face_cross(np.ascontiguousarray(vertices),
                               np.ascontiguousarray(faces.reshape(-1, 3)), n)
    return summed / np.maximum(np.linalg.norm(summed, axis=1), 1e-300)[:, None]
