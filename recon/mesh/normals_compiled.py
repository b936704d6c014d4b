"""The compiled kernel of `recon.mesh.normals.vertex_normals`: each triangle's ``(b - a) x
(c - a)`` summed into its three vertices. Apart so that importing the normals does not import
numba; it is imported on the first call."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def summed_face_cross(vertices: np.ndarray, faces: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) float64: per vertex, the sum of ``(b - a) x (c - a)`` over the triangles
    ``faces`` (F, 3) it is a corner of. The arithmetic of the numpy formula it replaces, in its
    order (the differences and the cross product in the vertices' dtype, the sums in float64
    face by face, corner by corner, as ``np.bincount`` adds), so the same floats; the faces
    must index the vertices (not checked here)."""
    out = np.zeros((n, 3))
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u0 = vertices[b, 0] - vertices[a, 0]
        u1 = vertices[b, 1] - vertices[a, 1]
        u2 = vertices[b, 2] - vertices[a, 2]
        v0 = vertices[c, 0] - vertices[a, 0]
        v1 = vertices[c, 1] - vertices[a, 1]
        v2 = vertices[c, 2] - vertices[a, 2]
        x = u1 * v2 - u2 * v1
        y = u2 * v0 - u0 * v2
        z = u0 * v1 - u1 * v0
        for k in range(3):
            i = faces[f, k]
            out[i, 0] += x
            out[i, 1] += y
            out[i, 2] += z
    return out
