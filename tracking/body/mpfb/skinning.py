"""The compiled kernels of the MPFB body: the macro targets' sum of
`tracking.body.mpfb.model.shaped_kept_vertices` (`add_targets`), and the linear blend skinning
of `tracking.body.mpfb.model.posed_vertices` and
`tracking.body.mpfb.subject.MpfbModel.posed_vertices`.

Apart from the model so that the ``mpfb`` plugin's module, which ``mocap plugins`` imports to
list it, does not import numba; it is imported on the first posing.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def add_targets(kept: np.ndarray, weights: np.ndarray, starts: np.ndarray, rows: np.ndarray,
                offsets: np.ndarray) -> None:  # fmt: skip
    """kept[rows[i]] += weights[k] * offsets[i] for the rows i of every stored target k with a
    non-zero weight (rows ``starts[k]:starts[k + 1]``), target after target: numpy's
    ``kept[rows_k] += weights[k] * offsets_k`` (float32 offsets widened to float64, the same
    products and sums in the same order, so the same floats; rows are distinct within a
    target) without its gathers and temporaries, a tenth of the time."""
    for k in range(weights.shape[0]):
        w = weights[k]
        if w == 0.0:
            continue
        for i in range(starts[k], starts[k + 1]):
            r = rows[i]
            for c in range(3):
                kept[r, c] += w * np.float64(offsets[i, c])


@numba.njit(cache=True, nogil=True)
def _blended(skin: np.ndarray, bones: np.ndarray, weights: np.ndarray, v: int,
             m: np.ndarray) -> None:  # fmt: skip
    """m (3, 4) = sum_k weights[v, k] skin[bones[v, k]]: vertex v's blended matrix."""
    for i in range(3):
        for j in range(4):
            m[i, j] = 0.0
    for k in range(bones.shape[1]):
        w = weights[v, k]
        if w != 0.0:
            b = bones[v, k]
            for i in range(3):
                for j in range(4):
                    m[i, j] += w * skin[b, i, j]


@numba.njit(cache=True, nogil=True)
def blend_skin(skin: np.ndarray, bones: np.ndarray, weights: np.ndarray, vertices: np.ndarray,
               normals: np.ndarray, out_vertices: np.ndarray, out_normals: np.ndarray,
               ) -> None:  # fmt: skip
    """out_vertices[v] = sum_k weights[v, k] skin[bones[v, k]] (vertices[v], 1): the skinning
    matrices (B, 3, 4) blended by each vertex's (up to 4) weights, applied to it; with
    ``normals`` of the same length as ``vertices`` the blended rotation turns them into
    ``out_normals``, renormalised (an empty ``normals`` skips them)."""
    with_normals = normals.shape[0] == vertices.shape[0]
    m = np.empty((3, 4))
    for v in range(vertices.shape[0]):
        _blended(skin, bones, weights, v, m)
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        for i in range(3):
            out_vertices[v, i] = m[i, 0] * x + m[i, 1] * y + m[i, 2] * z + m[i, 3]
        if with_normals:
            a, b, c = normals[v, 0], normals[v, 1], normals[v, 2]
            norm = 0.0
            for i in range(3):
                out_normals[v, i] = m[i, 0] * a + m[i, 1] * b + m[i, 2] * c
                norm += out_normals[v, i] ** 2
            norm = max(np.sqrt(norm), 1e-12)
            for i in range(3):
                out_normals[v, i] /= norm


@numba.njit(cache=True, nogil=True)
def blend_skin_at(skin: np.ndarray, bones: np.ndarray, weights: np.ndarray,
                  vertices: np.ndarray, ids: np.ndarray, out_vertices: np.ndarray,
                  ) -> None:  # fmt: skip
    """`blend_skin`'s vertices ``ids`` alone (no normals): out_vertices[n] is what it makes of
    vertex ids[n], the same floats (the same products and sums in the same order)."""
    m = np.empty((3, 4))
    for n in range(ids.shape[0]):
        v = ids[n]
        _blended(skin, bones, weights, v, m)
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        for i in range(3):
            out_vertices[n, i] = m[i, 0] * x + m[i, 1] * y + m[i, 2] * z + m[i, 3]


@numba.njit(cache=True, nogil=True)
def skin_matrices(world: np.ndarray, parents: np.ndarray, order: np.ndarray,
                  rest_heads: np.ndarray, root_translation: np.ndarray, out_skin: np.ndarray,
                  ) -> None:  # fmt: skip
    """out_skin[b]: bone b's (3, 4) skinning matrix world_from_rest, ``x -> W_b (x - h_b) +
    H_b``, for the bones' world rotations W_b (``world``, (B, 3, 3)) about each bone's rest
    head h_b (`rest_heads`, (B, 3)) and the root's translation (3,) from rest: the posed heads
    H_b of `tracking.body.mpfb.model.forward_kinematics` (each child's head rides on its
    parent's rotation), compiled. ``order``: every bone, parents first (its root first);
    ``parents``: (B,) parent per bone, -1 for the root."""
    heads = np.empty((world.shape[0], 3))
    for n in range(order.shape[0]):
        b = order[n]
        p = parents[b]
        if p < 0:
            for i in range(3):
                heads[b, i] = rest_heads[b, i] + root_translation[i]
            continue
        for i in range(3):
            offset = 0.0
            for k in range(3):
                offset += world[p, i, k] * (rest_heads[b, k] - rest_heads[p, k])
            heads[b, i] = heads[p, i] + offset
    for b in range(world.shape[0]):
        for i in range(3):
            moved = 0.0
            for k in range(3):
                out_skin[b, i, k] = world[b, i, k]
                moved += world[b, i, k] * rest_heads[b, k]
            out_skin[b, i, 3] = heads[b, i] - moved
