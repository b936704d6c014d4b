"""The outline refinement's normal equations (`tracking.track.contour._outline_system`), compiled
(`tracking.track.outline_kernel`) against the numpy they replaced (the oracle of
tests/tracking/track/test_contour.py), in the same run.

    .venv/bin/python benchmarks/outline_system.py [--poses 8] [--repeats 50]

Scene: the tracker's start model (`mocap track`'s default body, mpfb: MakeHuman's average
subject, 1.75 m, decimated to 2502 vertices), 4 ring cameras at 640x480 (radius 4 m, f 686
px, the suite's rig), silhouettes of a pose and the system of the pose moved off them (the
root by 3-5 cm, each joint by up to 8 degrees), as in a frame's first outline iteration.
Printed: ms per system (4 views) of each, their ratio, and the largest difference of the
matrices relative to their largest entry.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the oracle in tests/

from plugins.registry import create  # noqa: E402
from tests.tracking.track.test_contour import _outline_system_in_numpy  # noqa: E402
from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS, Pose  # noqa: E402
from tracking.rig.cameras import ring_cameras  # noqa: E402
from tracking.track.contour import ContourConfig, _FrameOutlines, _outline_system, _Posed  # noqa: E402
from tracking.track.render import render_views  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    cameras = ring_cameras(4, 4.0, 1.5, (0.0, 0.9, 0.0), 640, 480, 686.2)
    renderer = create("renderer", "cpu-raster")
    model = create("body", "mpfb").tracking_model(1.75)
    config = ContourConfig()
    rng = np.random.default_rng(0)
    seconds = {"compiled": 0.0, "numpy": 0.0}
    worst = 0.0
    for _ in range(args.poses):
        truth = np.clip(rng.uniform(-0.4, 0.4, len(LOWER_LIMITS)), LOWER_LIMITS, UPPER_LIMITS)
        truth[:3] = [0.0, 0.95, 0.0]
        truth[3:6] = [0.0, rng.uniform(-np.pi, np.pi), 0.0]
        x = truth.copy()
        x[:3] += rng.uniform(0.03, 0.05, 3) * rng.choice([-1, 1], 3)
        x[6:] += np.deg2rad(rng.uniform(-8, 8, len(x) - 6))
        x = np.clip(x, LOWER_LIMITS, UPPER_LIMITS)
        masks = render_views(renderer, model.posed_vertices(Pose(truth)), model.faces, cameras)
        frame = _FrameOutlines(cameras, masks, config)
        posed = _Posed(model, x, np.arange(len(x)))
        rendered = render_views(renderer, posed.verts, model.faces, cameras)
        results = {}
        for name, system in (("compiled", _outline_system), ("numpy", _outline_system_in_numpy)):
            results[name] = system(posed, cameras, frame.targets, rendered, config)  # warm-up
            start = time.perf_counter()
            for _ in range(args.repeats):
                system(posed, cameras, frame.targets, rendered, config)
            seconds[name] += time.perf_counter() - start
        (a, b), (a_ref, b_ref) = results["compiled"], results["numpy"]
        worst = max(worst, np.abs(a - a_ref).max() / np.abs(a_ref).max(),
                    np.abs(b - b_ref).max() / np.abs(b_ref).max())
    ms = {name: 1000 * s / (args.poses * args.repeats) for name, s in seconds.items()}
    print(f"outline system, 4 views 640x480, {args.poses} poses x {args.repeats}: "
          f"compiled {ms['compiled']:.2f} ms, numpy {ms['numpy']:.2f} ms, "
          f"ratio {ms['numpy'] / ms['compiled']:.1f}x; largest relative difference {worst:.1e}")


if __name__ == "__main__":
    main()
