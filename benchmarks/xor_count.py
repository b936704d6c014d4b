"""The energy's XOR count (`tracking.track.render.covered_gains`, compiled in
`tracking.track.raster.covered_gains`: the gains summed along the outline of the kept
triangles, row by row) against the count it replaced, each triangle's pixels visited and
marked in a stamps image so that each pixel counts once (session 33's: `REFERENCE`'s
`tracking.track.raster`, read from git), in the same run.

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
import importlib.util
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugins.registry import create
from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS, Pose
from tracking.rig.cameras import ring_cameras
from tracking.track.energy import XorCount
from tracking.track.render import covered_gains, render_views
from tracking.track.tracker import _LIMBS, _MOVES, _ROOT, _TRUNK

REFERENCE = "37441dd"
"""The commit whose `tracking.track.raster` (session 33's stamped count) is the reference."""


def _reference_kernels(commit: str, folder: Path) -> Any:
    """`tracking.track.raster` as of `commit` (from this checkout's git history, written to
    `folder` so that numba can cache it), or None without git or that commit."""
    try:
        source = subprocess.run(["git", "show", f"{commit}:tracking/track/raster.py"],
                                cwd=Path(__file__).resolve().parents[1], check=True,
                                capture_output=True, text=True).stdout  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return None
    path = folder / f"raster_{commit}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(f"raster_{commit}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _compare(renderer, views, faces: np.ndarray, vertices: list[np.ndarray], repeats: int,
             reference: Any) -> tuple[dict[str, float], bool]:  # fmt: skip
    """ms per count of each method (the fastest of `repeats` passes over `vertices`), and
    whether they gave the same integers."""
    stamps = np.zeros(views.stacked.shape, np.int64)
    tokens = iter(range(1, 1 << 62))
    faces64 = faces.astype(np.int64)

    def stamped(v: np.ndarray) -> np.ndarray:
        return reference.covered_gains(v, faces64, views.cams_from_world, views.Ks,
                                       views.dists, renderer.options.near_m,
                                       views.max_radius2s, -1.0, views.stacked, stamps,
                                       next(tokens))  # fmt: skip

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
    parser.add_argument("--reference", default=REFERENCE,
                        help="the commit whose stamped count is compared (session 33's)")
    args = parser.parse_args()
    folder = tempfile.TemporaryDirectory()
    reference = _reference_kernels(args.reference, Path(folder.name))
    if reference is None:
        raise SystemExit(f"xor_count: no git history with commit {args.reference} here (the "
                         "reference count is read from it)")
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
          f"of {args.repeats}; stamped: {args.reference}'s")
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
                                  args.repeats, reference)  # fmt: skip
            print(f"{level:<7}{part:<7}{len(faces):>6}{best['outline']:>12.3f}"
                  f"{best['stamped']:>12.3f}{best['stamped'] / best['outline']:>7.2f}  {same}")


if __name__ == "__main__":
    main()
