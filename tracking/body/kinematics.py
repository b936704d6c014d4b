"""The compiled kernel of `tracking.body.model.parent_from_node_transforms` and
`tracking.body.model.forward_kinematics`: the tracker poses the body thousands of times a
frame, and the numpy version of these 16 nodes and 21 rotations spent ~0.25 ms a pose in
Python overhead (profile of `mocap track` on a synthetic walk, session 16).

Apart from the model so that modules which only describe a body (``mocap plugins``) do not
import numba; it is imported on the first posing.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def node_transforms(params: np.ndarray, rot_params: np.ndarray, rot_axes: np.ndarray,
                    rot_node: np.ndarray, trans_params: np.ndarray, trans_axes: np.ndarray,
                    offsets: np.ndarray, parents: np.ndarray, out_local: np.ndarray,
                    out_world: np.ndarray) -> None:  # fmt: skip
    """out_local[n]: node n's (4, 4) parent_from_node (the root's world_from_pelvis), the
    product of its rotations ``rot_node == n`` in their order (each about ``rot_axes[r]`` by
    ``params[rot_params[r]]`` rad, Rodrigues) with its rest offset ``offsets[n]``, the root's
    moved by ``params[trans_params] @ trans_axes``; out_world[n]: world_from_node. Nodes come
    parents first (``parents[n] < n``)."""
    n_nodes = offsets.shape[0]
    for n in range(n_nodes):
        for i in range(4):
            for j in range(4):
                out_local[n, i, j] = 1.0 if i == j else 0.0
        for i in range(3):
            out_local[n, i, 3] = offsets[n, i]
    r_mat = np.empty((3, 3))
    product = np.empty((3, 3))
    for r in range(rot_params.shape[0]):
        n = rot_node[r]
        angle = params[rot_params[r]]
        x, y, z = rot_axes[r, 0], rot_axes[r, 1], rot_axes[r, 2]
        s, c = np.sin(angle), np.cos(angle)
        t = 1.0 - c
        r_mat[0, 0], r_mat[0, 1], r_mat[0, 2] = c + t * x * x, t * x * y - s * z, t * x * z + s * y
        r_mat[1, 0], r_mat[1, 1], r_mat[1, 2] = t * x * y + s * z, c + t * y * y, t * y * z - s * x
        r_mat[2, 0], r_mat[2, 1], r_mat[2, 2] = t * x * z - s * y, t * y * z + s * x, c + t * z * z
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += out_local[n, i, k] * r_mat[k, j]
                product[i, j] = acc
        for i in range(3):
            for j in range(3):
                out_local[n, i, j] = product[i, j]
    for k in range(trans_params.shape[0]):
        for i in range(3):
            out_local[0, i, 3] += params[trans_params[k]] * trans_axes[k, i]
    for n in range(n_nodes):
        p = parents[n]
        if p < 0:
            for i in range(4):
                for j in range(4):
                    out_world[n, i, j] = out_local[n, i, j]
            continue
        for i in range(4):
            for j in range(4):
                acc = 0.0
                for k in range(4):
                    acc += out_world[p, i, k] * out_local[n, k, j]
                out_world[n, i, j] = acc
