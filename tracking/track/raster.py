"""The compiled kernels of the ``cpu-raster`` renderer (:mod:`tracking.track.render`): the
projection of the vertices (`project_vertices`, `Camera.project`'s arithmetic) and the scanline
fill (`fill_triangles`), run together by `render_mask`; `covered_gains` counts rather than
draws, every view in one call, from the outline of the triangles (`mesh_edges`).

Apart from :mod:`tracking.track.render` so that loading the renderer plugins, as `mocap plugins`
does, does not import numba; it is imported on the first render.
"""

from __future__ import annotations

from typing import NamedTuple

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
    height, width = mask.shape[0], mask.shape[1]
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
        # An edge's x on a row is always its upper end's x plus the row's height below it
        # times the edge's slope: the arithmetic `covered_gains` repeats for the outline.
        k_long = (bx - tx) / (by - ty) if by != ty else 0.0
        k_top = (mx - tx) / (my - ty) if my != ty else 0.0
        k_bottom = (bx - mx) / (by - my) if by != my else 0.0
        for row in range(int(y0), int(y1) + 1):
            yc = row + 0.5
            x_long = tx + (yc - ty) * k_long
            x_short = tx + (yc - ty) * k_top if yc < my else mx + (yc - my) * k_bottom
            i0 = max(np.ceil(min(x_long, x_short) - 0.5), 0.0)
            i1 = min(np.floor(max(x_long, x_short) - 0.5), width - 1.0)
            for col in range(int(i0), int(i1) + 1):
                mask[row, col] = True


@numba.njit(cache=True, nogil=True)
def render_mask(vertices: np.ndarray, faces: np.ndarray, cam_from_world: np.ndarray,
                K: np.ndarray, dist: np.ndarray, near_m: float, max_radius2: float,
                keep_winding: float, mask: np.ndarray) -> None:  # fmt: skip
    """`project_vertices` then `fill_triangles` into `mask`: one view of the renderer."""
    uv = np.empty((vertices.shape[0], 2))
    project_vertices(vertices, cam_from_world, K, dist, near_m, max_radius2, uv)
    fill_triangles(uv, faces, mask, keep_winding)



class MeshEdges(NamedTuple):
    """A triangle mesh's edges, each with the faces on it (`mesh_edges`): what `covered_gains`
    needs to find the outline of the triangles it keeps."""

    vertices: np.ndarray
    """(E, 2) int32: the edge's two vertices, the lower index first."""
    faces: np.ndarray
    """(E, 2) int32: the faces on it; the mesh's face count where there is none (a border)."""
    signs: np.ndarray
    """(E, 2) int8: +1 where that face runs from the first vertex to the second, -1 the other
    way, 0 for none."""


def mesh_edges(faces: np.ndarray) -> MeshEdges:
    """The `MeshEdges` of (F, 3) `faces`. An edge with more than two faces (not a manifold)
    is split into records of two, which count the same: each face adds its own share."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    half = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    face = np.repeat(np.arange(len(faces)), 3)
    sign = np.where(half[:, 0] < half[:, 1], 1, -1)
    ends = np.sort(half, axis=1)
    order = np.lexsort((ends[:, 1], ends[:, 0]))
    ends, face, sign = ends[order], face[order], sign[order]
    first = np.ones(len(ends), bool)
    first[1:] = (ends[1:] != ends[:-1]).any(axis=1)
    rank = np.arange(len(ends)) - np.flatnonzero(first)[np.cumsum(first) - 1]
    record = np.cumsum(rank % 2 == 0) - 1  # a record every two faces of an edge
    count = int(record[-1]) + 1 if len(record) else 0
    edges = MeshEdges(np.zeros((count, 2), np.int32), np.full((count, 2), len(faces), np.int32),
                      np.zeros((count, 2), np.int8))  # fmt: skip
    edges.vertices[record] = ends
    edges.faces[record, rank % 2] = face
    edges.signs[record, rank % 2] = sign
    return edges


@numba.njit(cache=True, nogil=True)
def _outline_count(uv: np.ndarray, faces: np.ndarray, edges: np.ndarray, edge_faces: np.ndarray,
                   edge_signs: np.ndarray, keep_winding: float, gain: np.ndarray,
                   kind: np.ndarray, active: np.ndarray, turns: np.ndarray,
                   ends: np.ndarray) -> int:  # fmt: skip
    """`covered_gains` of one view, its vertices projected (`uv`); kind, active, turns and ends
    scratch arrays of the face and edge counts."""
    height, width = gain.shape[0], gain.shape[1]
    n_faces = faces.shape[0]
    # A face's kind: 0 of a non-positive signed area in the image, 1 of a positive one, -1
    # dropped (a vertex not projected, or culled by `keep_winding`).
    n_active = 0
    if keep_winding < 0.0:
        # Culling the faces of positive area (the renderer's default) keeps kind 0 alone:
        # loops of their own, 1.10-1.15x the whole count's speed (`benchmarks/xor_count.py`'s
        # scene, the same integers; session 44).
        for f in range(n_faces):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            ax, ay = uv[a, 0], uv[a, 1]
            area = (uv[b, 0] - ax) * (uv[c, 1] - ay) - (uv[c, 0] - ax) * (uv[b, 1] - ay)
            # area - area is 0 exactly when area is finite (NaN for NaN and the infinities).
            kind[f] = 0 if area - area == 0.0 and area <= 0.0 else -1
        kind[n_faces] = -1  # the face of none
        # About 9 in 10 edges are inside: the branch that records an outline edge is well
        # predicted, and faster here than recording every edge branch-free.
        for e in range(edges.shape[0]):
            t0 = ((kind[edge_faces[e, 0]] == 0) * edge_signs[e, 0]
                  + (kind[edge_faces[e, 1]] == 0) * edge_signs[e, 1])
            if t0 != 0:
                active[n_active] = e
                turns[n_active, 0] = t0
                turns[n_active, 1] = 0
                n_active += 1
    else:
        for f in range(n_faces):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            ax, ay = uv[a, 0], uv[a, 1]
            area = (uv[b, 0] - ax) * (uv[c, 1] - ay) - (uv[c, 0] - ax) * (uv[b, 1] - ay)
            # Not finite when a vertex is not (NaN, or an infinity in any of its terms).
            first = np.isfinite(area) and area <= 0.0 and (keep_winding <= 0.0 or area == 0.0)
            second = np.isfinite(area) and area > 0.0 and keep_winding >= 0.0
            kind[f] = 0 if first else (1 if second else -1)
        kind[n_faces] = -1  # the face of none
        # The outline: the edges whose kept faces of one kind do not cancel (the faces on
        # both sides kept, each runs it the other way). Branch-free: about 9 in 10 edges are
        # inside (and both kinds' tests mispredict a branch here: 0.86-0.92x with one).
        for e in range(edges.shape[0]):
            ka, kb = kind[edge_faces[e, 0]], kind[edge_faces[e, 1]]
            sa, sb = edge_signs[e, 0], edge_signs[e, 1]
            t0 = (ka == 0) * sa + (kb == 0) * sb
            t1 = (ka == 1) * sa + (kb == 1) * sb
            active[n_active] = e
            turns[n_active, 0] = t0
            turns[n_active, 1] = t1
            n_active += (t0 != 0) | (t1 != 0)
    # The rows each outline edge crosses: pixel centres y with top <= y < bottom.
    row_start = np.zeros(height + 1, np.int64)
    crossing = 0
    for i in range(n_active):
        e = active[i]
        v0, v1 = edges[e, 0], edges[e, 1]
        down = uv[v0, 1] < uv[v1, 1]
        top, bottom = (v0, v1) if down else (v1, v0)
        r0 = max(np.ceil(uv[top, 1] - 0.5), 0.0)
        r1 = min(np.ceil(uv[bottom, 1] - 0.5) - 1.0, height - 1.0)
        if r1 < r0:  # horizontal, or off the image
            continue
        # Sweeping a row left to right, a kind-0 face's downward edge is its left side (the
        # winding goes up), a kind-1 face's its right side.
        turns[crossing, 0] = turns[i, 0] if down else -turns[i, 0]
        turns[crossing, 1] = -turns[i, 1] if down else turns[i, 1]
        ends[crossing, 0], ends[crossing, 1] = top, bottom
        ends[crossing, 2], ends[crossing, 3] = int(r0), int(r1)
        crossing += 1
        for row in range(int(r0), int(r1) + 1):
            row_start[row + 1] += 1
    for row in range(height):
        row_start[row + 1] += row_start[row]
    xs = np.empty(row_start[height])
    w0s = np.empty(row_start[height], np.int64)
    w1s = np.empty(row_start[height], np.int64)
    filled = row_start[:height].copy()
    for i in range(crossing):
        top, bottom = ends[i, 0], ends[i, 1]
        tx, ty, bx, by = uv[top, 0], uv[top, 1], uv[bottom, 0], uv[bottom, 1]
        slope = (bx - tx) / (by - ty)
        for row in range(ends[i, 2], ends[i, 3] + 1):
            j = filled[row]
            filled[row] = j + 1
            xs[j] = tx + (row + 0.5 - ty) * slope  # `fill_triangles`' arithmetic: the same x
            w0s[j], w1s[j] = turns[i, 0], turns[i, 1]
    # Per row, the crossings sorted by x (a few: insertion sort); a pixel is covered where
    # either kind's winding is 1 or more, both ends of a run included (`fill_triangles`' rule).
    total = 0
    for row in range(height):
        lo, hi = row_start[row], row_start[row + 1]
        for i in range(lo + 1, hi):
            x, t0, t1 = xs[i], w0s[i], w1s[i]
            j = i - 1
            while j >= lo and xs[j] > x:
                xs[j + 1], w0s[j + 1], w1s[j + 1] = xs[j], w0s[j], w1s[j]
                j -= 1
            xs[j + 1], w0s[j + 1], w1s[j + 1] = x, t0, t1
        w0, w1, begin = 0, 0, 0.0
        i = lo
        while i < hi:
            x = xs[i]
            was = w0 >= 1 or w1 >= 1
            while i < hi and xs[i] == x:  # crossings at one x together: runs that touch merge
                w0 += w0s[i]
                w1 += w1s[i]
                i += 1
            now = w0 >= 1 or w1 >= 1
            if now and not was:
                begin = x
            elif was and not now:
                i0 = max(np.ceil(begin - 0.5), 0.0)
                i1 = min(np.floor(x - 0.5), width - 1.0)
                run = 0
                for col in range(int(i0), int(i1) + 1):
                    run += gain[row, col]
                total += run
    return total


@numba.njit(cache=True, nogil=True)
def covered_gains(vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray,
                  edge_faces: np.ndarray, edge_signs: np.ndarray, cams_from_world: np.ndarray,
                  Ks: np.ndarray, dists: np.ndarray, near_m: float, max_radius2s: np.ndarray,
                  keep_winding: float, gains: np.ndarray) -> np.ndarray:  # fmt: skip
    """(views,) int64: per view, the sum of ``gains[v]`` (an int8 image) over the pixels
    `render_mask` would set, each once, without drawing them: from the outline of the kept
    triangles (`mesh_edges`: edges, edge_faces, edge_signs) rather than from every triangle.

    Per row, the kept triangles of one orientation in the image cover a pixel centre as many
    times as the winding number there of their outline, the edges between a kept triangle
    and one that is not (or none): inside edges cancel, so only the outline is walked, its
    crossings of the row sorted, and the gains summed over each run of a winding of 1 or
    more. An edge's x on a row is `fill_triangles`' arithmetic, so a pixel centre is inside
    exactly when it is inside one of the triangles drawn; they could differ only for a
    centre on the very row of a triangle's lowest vertex (the runs here are half-open in y).
    The same integers as summing over the drawn masks (tests/tracking/track/test_render.py:
    bodies, open meshes, triangle soups, culling on and off) and as session 33's count of
    each triangle's pixels, which this is 1.1-1.8x faster than on the MPFB body (5000 faces,
    about 860 of its 7500 edges on the outline in a view; `benchmarks/xor_count.py`).

    One thread: the views on numba's threads (``prange``) gave the energy 1.6-1.85x the
    evaluations per second on an idle 2-core machine, but two such processes side by side
    (`make test`'s two workers) ran 3.5x slower than one thread each, OpenMP's threads spinning
    between the evaluations (session 27). Each run's gains summed from per-row prefix sums (the
    same integers) counted 0.75-1.21x as fast on `benchmarks/xor_count.py`'s scene, but the
    sums cost 3-5 ms to make at levels 0-1, once per stage (`_StageEnergy`), which counts a few
    dozen to a few hundred times: not built (session 39).

    cams_from_world (V, 3, 4), Ks (V, 3, 3), dists (V, 5), max_radius2s (V,): the cameras;
    gains (V, H, W), zero past a view's own size (views of several sizes share the largest)."""
    totals = np.zeros(gains.shape[0], np.int64)
    uv = np.empty((vertices.shape[0], 2))
    kind = np.empty(faces.shape[0] + 1, np.int8)
    active = np.empty(edges.shape[0], np.int64)
    turns = np.empty((edges.shape[0], 2), np.int64)
    ends = np.empty((edges.shape[0], 4), np.int64)
    for v in range(gains.shape[0]):
        project_vertices(vertices, cams_from_world[v], Ks[v], dists[v], near_m,
                         max_radius2s[v], uv)  # fmt: skip
        totals[v] = _outline_count(uv, faces, edges, edge_faces, edge_signs, keep_winding,
                                   gains[v], kind, active, turns, ends)  # fmt: skip
    return totals
