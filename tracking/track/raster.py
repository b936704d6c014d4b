"""The compiled scanline kernel of the ``cpu-raster`` renderer
(:func:`tracking.track.render.rasterize_triangles`).

Apart from :mod:`tracking.track.render` so that loading the renderer plugins, as `mocap plugins`
does, does not import numba; it is imported on the first render.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def fill_triangles(uv: np.ndarray, faces: np.ndarray, mask: np.ndarray, keep_winding: float
                   ) -> None:  # fmt: skip
    """Scanline fill (compiled): set every pixel of `mask` whose centre lies in a triangle.
    keep_winding: 0 fills every triangle; +1 or -1 only those whose signed area in the image
    has that sign (back-face culling done in the image, where it costs nothing)."""
    height, width = mask.shape
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        xs = (uv[a, 0], uv[b, 0], uv[c, 0])
        ys = (uv[a, 1], uv[b, 1], uv[c, 1])
        if not (np.isfinite(xs[0]) and np.isfinite(xs[1]) and np.isfinite(xs[2])
                and np.isfinite(ys[0]) and np.isfinite(ys[1]) and np.isfinite(ys[2])):
            continue
        if keep_winding != 0.0:
            area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0])
            if area * keep_winding < 0.0:
                continue
        # Sort by y: top (t), middle (m), bottom (b).
        t, m, bo = 0, 1, 2
        if ys[m] < ys[t]:
            t, m = m, t
        if ys[bo] < ys[m]:
            m, bo = bo, m
            if ys[m] < ys[t]:
                t, m = m, t
        tx, ty, mx, my, bx, by = xs[t], ys[t], xs[m], ys[m], xs[bo], ys[bo]
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
            for col in range(int(i0), int(i1) + 1):
                mask[row, col] = True
