"""Normals of triangle meshes: pure numpy, no I/O.

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
    cross = _face_cross(vertices, faces)
    corners = np.asarray(faces).ravel()  # each face's three vertices, face by face
    per_corner = np.repeat(cross, 3, axis=0)
    n = len(vertices)
    # bincount sums repeated indices like np.add.at, an order of magnitude faster.
    summed = np.stack([np.bincount(corners, weights=per_corner[:, d], minlength=n)
                       for d in range(3)], axis=1)  # fmt: skip
    return summed / np.maximum(np.linalg.norm(summed, axis=1), 1e-300)[:, None]
