"""The energy's XOR count (`tracking.track.render.covered_gains`, compiled in
`tracking.track.raster.covered_gains`: the gains summed along the outline of the kept
triangles, row by row) against the count it replaced, each triangle's pixels visited and
marked in a stamps image so that each pixel counts once (session 33's, kept below as the
reference), in the same run.

    .venv/bin/python benchmarks/xor_count.py [--poses 64] [--repeats 5]

Scene: the tracker's start model (`mocap track`'s default body, mpfb: MakeHuman's average
subject, 1.75 m, decimated to 2502 vertices and 5000 faces), 4 ring cameras at 640x480
(radius 4 m, f 686 px, the suite's rig) and their pyramid levels 1 and 2, gains of a
silhouette of another pose; counted: the whole body (a root stage), the trunk's faces and
an arm's (what a stage moves: `SilhouetteTracker`'s `_StageEnergy`), each with only its own
vertices, over `--poses` random poses in turn (one pose again and again would let the
branch predictor learn it). Printed: ms per count (4 views) of each, their ratio, and
whether every count is the same integer.
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np

from plugins.registry import create
from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS, Pose
from tracking.rig.cameras import ring_cameras
from tracking.track.energy import XorCount
from tracking.track.raster import project_vertices
from tracking.track.render import covered_gains, render_views
from tracking.track.tracker import _LIMBS, _MOVES, _ROOT, _TRUNK


@numba.njit(cache=True, nogil=True)
def _stamped_count(vertices, faces, cams_from_world, Ks, dists, near_m, max_radius2s,
                   keep_winding, gains, stamps, token):  # fmt: skip
    """Session 33's count: every kept triangle's rows scanned (`fill_triangles`), each pixel
    summed once (``stamps`` set to ``token`` where counted)."""
    totals = np.zeros(gains.shape[0], np.int64)
    uv = np.empty((vertices.shape[0], 2))
    for v in range(gains.shape[0]):
        project_vertices(vertices, cams_from_world[v], Ks[v], dists[v], near_m,
                         max_radius2s[v], uv)  # fmt: skip
        gain, stamp, height, width = gains[v], stamps[v], gains.shape[1], gains.shape[2]
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
            swap = by < ay
            tx, ty = (bx, by) if swap else (ax, ay)
            mx, my = (ax, ay) if swap else (bx, by)
            swap = cy < my
            bx, by = (mx, my) if swap else (cx, cy)
            mx, my = (cx, cy) if swap else (mx, my)
            swap = my < ty
            tx, ty, mx, my = (mx, my, tx, ty) if swap else (tx, ty, mx, my)
            y0, y1 = max(np.ceil(ty - 0.5), 0.0), min(np.floor(by - 0.5), height - 1.0)
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
                    if stamp[row, col] != token:
                        stamp[row, col] = token
                        total += gain[row, col]
        totals[v] = total
    return totals


def _compare(renderer, views, faces: np.ndarray, vertices: list[np.ndarray], repeats: int,
             ) -> tuple[dict[str, float], bool]:  # fmt: skip
    """ms per count of each method (the fastest of `repeats` passes over `vertices`), and
    whether they gave the same integers."""
    stamps = np.zeros(views.stacked.shape, np.int64)
    tokens = iter(range(1, 1 << 62))
    faces64 = faces.astype(np.int64)

    def stamped(v: np.ndarray) -> np.ndarray:
        return _stamped_count(v, faces64, views.cams_from_world, views.Ks, views.dists,
                              renderer.options.near_m, views.max_radius2s, -1.0, views.stacked,
                              stamps, next(tokens))  # fmt: skip

    def outline(v: np.ndarray) -> np.ndarray:
        return covered_gains(renderer, v, faces, views)

    same = all(np.array_equal(outline(v), stamped(v)) for v in vertices)
    best = {}
    for name, fn in (("outline", outline), ("stamped", stamped)):
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            for v in vertices:
                fn(v)
            times.append((time.perf_counter() - start) / len(vertices))
        best[name] = 1000 * min(times)
    return best, same


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=5, help="the fastest of this many")
    args = parser.parse_args()
    ring = ring_cameras(4, 4.0, 1.5, (0.0, 0.9, 0.0), 640, 480, 686.2)
    renderer = create("renderer", "cpu-raster")
    model = create("body", "mpfb").tracking_model(1.75)
    rng = np.random.default_rng(0)

    def random_pose() -> Pose:
        x = np.clip(rng.uniform(-0.5, 0.5, len(LOWER_LIMITS)), LOWER_LIMITS, UPPER_LIMITS)
        x[:6] = [0.0, 0.95, 0.0, 0.0, rng.uniform(-np.pi, np.pi), 0.0]
        return Pose(x)

    posed = [model.posed_vertices(random_pose()) for _ in range(args.poses)]
    silhouette = model.posed_vertices(random_pose())
    parts = {name: model.faces_moved_by(_MOVES[free].any(axis=0)) for name, free in (
        ("body", _ROOT), ("trunk", _TRUNK), ("arm", _LIMBS["l_arm"][0]))}
    print(f"XOR count of the mpfb body (5000 faces), 4 views, {args.poses} poses, the fastest "
          f"of {args.repeats}")
    print(f"{'level':<7}{'part':<7}{'faces':>6}{'outline ms':>12}{'stamped ms':>12}"
          f"{'ratio':>7}  same")
    for level in range(3):
        cameras = [c.scaled(0.5**level) for c in ring]
        masks = render_views(renderer, silhouette, model.faces, cameras)
        count = XorCount(renderer, cameras, masks, [None] * 4)
        for part, faces_kept in parts.items():
            faces = model.faces[faces_kept]
            ids = np.unique(faces)
            vertices = [np.ascontiguousarray(v[ids]) for v in posed]
            best, same = _compare(renderer, count.views, np.searchsorted(ids, faces), vertices,
                                  args.repeats)  # fmt: skip
            print(f"{level:<7}{part:<7}{len(faces):>6}{best['outline']:>12.3f}"
                  f"{best['stamped']:>12.3f}{best['stamped'] / best['outline']:>7.2f}  {same}")


if __name__ == "__main__":
    main()
