"""The compiled kernels of the ``cpu-raster`` renderer (:mod:`tracking.track.render`): the
projection of the vertices (`project_vertices`, `Camera.project`'s arithmetic) and the scanline
fill (`fill_triangles`), run together by `render_mask`; `covered_gains` counts rather than
draws, every view in one call.

Apart from :mod:`tracking.track.render` so that loading the renderer plugins, as `mocap plugins`
does, does not import numba; it is imported on the first render.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def project_vertices(vertices: np.ndarray, cam_from_world: np.ndarray, K: np.ndarray,
                     dist: np.ndarray, near_m: float, max_radius2: float, uv: np.ndarray,
                     ) -> None:  # fmt: skip
    """uv[v]: the pixel of world vertex v (compiled `recon.cameras.Camera.project`, the same
    operations in the same order), NaN where the renderer drops it: closer to the camera plane
    than ``near_m`` (or behind it), or past the monotonic radius ``max_radius2`` of the
    distortion (inf: none)."""
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    distorted = k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0
    check_radius = np.isfinite(max_radius2)
    r = cam_from_world
    for v in range(vertices.shape[0]):
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        cx = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + r[0, 3]
        cy = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + r[1, 3]
        depth = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + r[2, 3]
        if not depth >= near_m or depth <= 0.0:
            uv[v, 0] = np.nan
            uv[v, 1] = np.nan
            continue
        nx, ny = cx / depth, cy / depth
        if check_radius and not (cx**2 + cy**2) / depth**2 < max_radius2:
            uv[v, 0] = np.nan
            uv[v, 1] = np.nan
            continue
        if distorted:
            r2 = nx * nx + ny * ny
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = nx * radial + 2.0 * p1 * nx * ny + p2 * (r2 + 2.0 * nx * nx)
            yd = ny * radial + p1 * (r2 + 2.0 * ny * ny) + 2.0 * p2 * nx * ny
            nx, ny = xd, yd
        uv[v, 0] = K[0, 0] * nx + K[0, 1] * ny + K[0, 2]
        uv[v, 1] = K[1, 1] * ny + K[1, 2]


@numba.njit(cache=True, nogil=True)
def fill_triangles(uv: np.ndarray, faces: np.ndarray, mask: np.ndarray, keep_winding: float
                   ) -> None:  # fmt: skip
    """Scanline fill (compiled): set every pixel of `mask` whose centre lies in a triangle.
    keep_winding: 0 fills every triangle; +1 or -1 only those whose signed area in the image
    has that sign (back-face culling done in the image, where it costs nothing)."""
    _scan(uv, faces, keep_winding, mask, np.zeros((0, 0), np.int8), np.zeros((0, 0), np.int64), 0)


@numba.njit(cache=True, nogil=True)
def _scan(uv: np.ndarray, faces: np.ndarray, keep_winding: float, mask: np.ndarray,
          gain: np.ndarray, stamp: np.ndarray, token: int) -> int:  # fmt: skip
    """The scanline fill of `fill_triangles` and `covered_gains`: with an empty `gain`, sets
    `mask` at every covered pixel centre; else returns the sum of `gain` over the covered
    pixels, each counted once (`stamp` set to `token` where counted; `mask` unused)."""
    counting = gain.shape[0] > 0
    height, width = (gain.shape[0], gain.shape[1]) if counting else (mask.shape[0],
                                                                       mask.shape[1])
    total = 0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ax, ay, bx, by, cx, cy = uv[a, 0], uv[a, 1], uv[b, 0], uv[b, 1], uv[c, 0], uv[c, 1]
        if not (np.isfinite(ax) and np.isfinite(bx) and np.isfinite(cx)
                and np.isfinite(ay) and np.isfinite(by) and np.isfinite(cy)):
            continue
        if keep_winding != 0.0:
            area = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
            if area * keep_winding < 0.0:
                continue
        # Sort by y: top (t), middle (m), bottom (bo), ties kept in vertex order. Selects
        # rather than swaps: the compiler makes them branch-free, and on a body's thousands of
        # small triangles the swaps' branches were mispredicted about half the time.
        swap = by < ay
        tx, ty = (bx, by) if swap else (ax, ay)
        mx, my = (ax, ay) if swap else (bx, by)
        swap = cy < my
        bx, by = (mx, my) if swap else (cx, cy)
        mx, my = (cx, cy) if swap else (mx, my)
        swap = my < ty
        tx, ty, mx, my = (mx, my, tx, ty) if swap else (tx, ty, mx, my)
        y0 = max(np.ceil(ty - 0.5), 0.0)
        y1 = min(np.floor(by - 0.5), height - 1.0)
        if y1 < y0:
            continue
        k_long = (bx - tx) / (by - ty) if by != ty else 0.0
        k_top = (mx - tx) / (my - ty) if my != ty else 0.0
        k_bottom = (bx - mx) / (by - my) if by != my else 0.0
        for row in range(int(y0), int(y1) + 1):
            yc = row + 0.5
            x_long = tx + (yc - ty) * k_long
            x_short = tx + (yc - ty) * k_top if yc < my else mx + (yc - my) * k_bottom
            i0 = max(np.ceil(min(x_long, x_short) - 0.5), 0.0)
            i1 = min(np.floor(max(x_long, x_short) - 0.5), width - 1.0)
            if counting:
                for col in range(int(i0), int(i1) + 1):
                    if stamp[row, col] != token:
                        stamp[row, col] = token
                        total += gain[row, col]
            else:
                for col in range(int(i0), int(i1) + 1):
                    mask[row, col] = True
    return total


@numba.njit(cache=True, nogil=True)
def render_mask(vertices: np.ndarray, faces: np.ndarray, cam_from_world: np.ndarray,
                K: np.ndarray, dist: np.ndarray, near_m: float, max_radius2: float,
                keep_winding: float, mask: np.ndarray) -> None:  # fmt: skip
    """`project_vertices` then `fill_triangles` into `mask`: one view of the renderer."""
    uv = np.empty((vertices.shape[0], 2))
    project_vertices(vertices, cam_from_world, K, dist, near_m, max_radius2, uv)
    fill_triangles(uv, faces, mask, keep_winding)


@numba.njit(cache=True, nogil=True)
def covered_gains(vertices: np.ndarray, faces: np.ndarray, cams_from_world: np.ndarray,
                  Ks: np.ndarray, dists: np.ndarray, near_m: float, max_radius2s: np.ndarray,
                  keep_winding: float, gains: np.ndarray, stamps: np.ndarray, token: int,
                  ) -> np.ndarray:  # fmt: skip
    """(views,) int64: per view, `render_mask`'s pixels, not drawn but summed: ``gains[v]``
    (an int8 image) over the pixels the triangles cover, each once (``stamps[v]``, an int64
    image, is set to `token` where counted: a token not in it yet starts a new count, so
    nothing is cleared). One thread: the views on numba's threads (``prange``) gave the energy
    1.6-1.85x the evaluations per second on an idle 2-core machine, but two such processes side
    by side (`make test`'s two workers) ran 3.5x slower than one thread each, OpenMP's
    threads spinning between the evaluations (session 27). cams_from_world
    (V, 3, 4), Ks (V, 3, 3), dists (V, 5), max_radius2s (V,): the cameras; gains (V, H, W),
    zero past a view's own size (views of several sizes share the largest), stamps the
    same shape."""
    totals = np.zeros(gains.shape[0], np.int64)
    for v in range(gains.shape[0]):
        uv = np.empty((vertices.shape[0], 2))
        project_vertices(vertices, cams_from_world[v], Ks[v], dists[v], near_m,
                         max_radius2s[v], uv)  # fmt: skip
        totals[v] = _scan(uv, faces, keep_winding, np.zeros((0, 0), np.bool_), gains[v],
                          stamps[v], token)  # fmt: skip
    return totals
