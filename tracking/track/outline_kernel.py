"""The compiled per-view part of the outline refinement (:mod:`tracking.track.contour`): which
model vertices are on the occluding contour, and the rows of both residuals with their
derivatives (`outline_rows`). The normal equations are then two BLAS products in
`contour._outline_system`.

The same arithmetic as the numpy it replaced, vertex by vertex (the nearest contour vertex
of each outline point by a search outwards along u rather than a k-d tree), the same
matrices to 3e-16 of their largest entry: 4.66 -> 1.62 ms a system of 4 views at 640x480
(`benchmarks/outline_system.py`), and 0.25 -> 0.19 s a tracked frame of the 60-frame
pirouette of the motion suite (its frames 20-39, the same poses to 1e-14). Apart from
:mod:`tracking.track.contour` so that importing that does not import numba, as
:mod:`tracking.track.raster` is apart from the renderers.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def contour_vertices(verts: np.ndarray, normals: np.ndarray, centre: np.ndarray,
                     uv: np.ndarray, depth: np.ndarray, model_mask: np.ndarray,
                     known: np.ndarray, grazing: float) -> np.ndarray:  # fmt: skip
    """Indices of the vertices on the model's occluding contour in one view: normal nearly
    perpendicular to the ray from the camera centre (|n . ray| < grazing), in front of the
    camera, a pixel inside the image's 1-pixel border, next to a background pixel of the
    model's own silhouette `model_mask` (else hidden behind other parts), and on a pixel of
    `known` (a (0, 0) array: every pixel counts)."""
    h, w = model_mask.shape
    check_known = known.shape[0] > 0
    out = np.empty(verts.shape[0], np.int64)
    n = 0
    for v in range(verts.shape[0]):
        rx, ry, rz = verts[v, 0] - centre[0], verts[v, 1] - centre[1], verts[v, 2] - centre[2]
        norm = np.sqrt(rx * rx + ry * ry + rz * rz)
        cosine = (rx * normals[v, 0] + ry * normals[v, 1] + rz * normals[v, 2]) / norm
        if not abs(cosine) < grazing or not depth[v] > 0:
            continue
        col, row = np.floor(uv[v, 0]), np.floor(uv[v, 1])
        if not (col >= 1 and col < w - 1 and row >= 1 and row < h - 1):
            continue
        c, r = int(col), int(row)
        near_background = False
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if not model_mask[r + dr, c + dc]:
                    near_background = True
        if not near_background or (check_known and not known[r, c]):
            continue
        out[n] = v
        n += 1
    return out[:n]


@numba.njit(cache=True, nogil=True)
def _bilinear(image: np.ndarray, x0: int, y0: int, fx: float, fy: float) -> float:
    return ((1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x0 + 1])
            + fy * ((1 - fx) * image[y0 + 1, x0] + fx * image[y0 + 1, x0 + 1]))


@numba.njit(cache=True, nogil=True)
def outline_rows(idx: np.ndarray, verts: np.ndarray, uv: np.ndarray, R: np.ndarray,
                 t: np.ndarray, fx: float, fy: float, extra: np.ndarray,
                 node_weights: np.ndarray, moved_nodes: np.ndarray, skew: np.ndarray,
                 constant: np.ndarray, sdf: np.ndarray, grad_u: np.ndarray,
                 grad_v: np.ndarray, outline: np.ndarray,
                 ) -> tuple[np.ndarray, ...]:  # fmt: skip
    """The residual rows of one view over the columns (extra, then pose) for the contour
    vertices `idx`:

    * model to image: (n, columns) derivatives of the signed distance (`sdf`, bilinear at
      the vertex's pixel, its gradient `grad_u`, `grad_v` too) and the distances (n,);
    * image to model: (2m, columns) derivatives of the pixel offset from each of the m
      outline points to its nearest contour vertex (its u row, then its v row), the (2m,)
      offsets, and the (m,) distances to it.

    Returns (jac, sdf, jac2, offsets, distances)."""
    n, e, p = idx.shape[0], extra.shape[2], skew.shape[0]
    columns = e + p
    h, w = sdf.shape
    duv = np.empty((n, 2, columns))
    jac = np.empty((n, columns))
    distance = np.empty(n)
    weights = np.empty(p)
    du, dv, d = np.empty(3), np.empty(3), np.empty(3)
    for i in range(n):
        v = idx[i]
        x, y, z = verts[v, 0], verts[v, 1], verts[v, 2]
        # The pinhole part of the projection's derivative (lens distortion ignored: it
        # changes the derivative by far less than a step).
        cx = x * R[0, 0] + y * R[0, 1] + z * R[0, 2] + t[0]
        cy = x * R[1, 0] + y * R[1, 1] + z * R[1, 2] + t[1]
        cz = x * R[2, 0] + y * R[2, 1] + z * R[2, 2] + t[2]
        for j in range(3):
            du[j] = fx / cz * R[0, j] - fx * cx / cz**2 * R[2, j]
            dv[j] = fy / cz * R[1, j] - fy * cy / cz**2 * R[2, j]
        for k in range(e):
            for j in range(3):
                d[j] = extra[v, j, k]
            duv[i, 0, k] = du[0] * d[0] + du[1] * d[1] + du[2] * d[2]
            duv[i, 1, k] = dv[0] * d[0] + dv[1] * d[1] + dv[2] * d[2]
        weights[:] = 0.0
        for node in range(node_weights.shape[1]):
            if node_weights[v, node] != 0.0:  # a vertex follows a few nodes
                for k in range(p):
                    weights[k] += node_weights[v, node] * moved_nodes[k, node]
        for k in range(p):
            for j in range(3):
                d[j] = (skew[k, j, 0] * x + skew[k, j, 1] * y + skew[k, j, 2] * z
                        + constant[j, k]) * weights[k]
            duv[i, 0, e + k] = du[0] * d[0] + du[1] * d[1] + du[2] * d[2]
            duv[i, 1, e + k] = dv[0] * d[0] + dv[1] * d[1] + dv[2] * d[2]
        # The signed distance and its gradient at the pixel.
        px = min(max(uv[v, 0] - 0.5, 0.0), w - 1.001)
        py = min(max(uv[v, 1] - 0.5, 0.0), h - 1.001)
        x0, y0 = int(np.floor(px)), int(np.floor(py))
        ax, ay = px - x0, py - y0
        distance[i] = _bilinear(sdf, x0, y0, ax, ay)
        gu, gv = _bilinear(grad_u, x0, y0, ax, ay), _bilinear(grad_v, x0, y0, ax, ay)
        for k in range(columns):
            jac[i, k] = gu * duv[i, 0, k] + gv * duv[i, 1, k]
    m = outline.shape[0]
    jac2 = np.empty((2 * m, columns))
    offsets = np.empty(2 * m)
    nearest_distance = np.empty(m)
    # The nearest contour vertex of each outline point (the lowest index of equals): the
    # vertices sorted by u, searched outwards from the point's u while |du| can still beat it.
    us = np.empty(n)
    for i in range(n):
        us[i] = uv[idx[i], 0]
    order = np.argsort(us)
    sorted_u = us[order]
    for o in range(m):
        best, nearest = np.inf, n
        start = np.searchsorted(sorted_u, outline[o, 0])
        for step in (-1, 1):
            j = start if step == 1 else start - 1
            while 0 <= j < n:
                du_ = sorted_u[j] - outline[o, 0]
                if du_ * du_ > best:
                    break
                i = order[j]
                dv_ = uv[idx[i], 1] - outline[o, 1]
                d2 = du_ * du_ + dv_ * dv_
                if d2 < best or (d2 == best and i < nearest):
                    best, nearest = d2, i
                j += step
        v = idx[nearest]
        offsets[2 * o] = uv[v, 0] - outline[o, 0]
        offsets[2 * o + 1] = uv[v, 1] - outline[o, 1]
        nearest_distance[o] = np.sqrt(best)
        for k in range(columns):
            jac2[2 * o, k] = duv[nearest, 0, k]
            jac2[2 * o + 1, k] = duv[nearest, 1, k]
    return jac, distance, jac2, offsets, nearest_distance
