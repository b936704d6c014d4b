"""Silhouette renderers side by side: speed, energy evaluations per second, agreement.

    .venv/bin/python benchmarks/renderers.py [--poses 12] [--seed 0] [--budget 3]
                                             [--renderers cpu-raster,open3d-raycast,...]

Scene: 4 ring cameras at 640x480 (radius 4 m, at pelvis height, f = 500 px) around the body
model (:mod:`tracking.body.model`) in random poses: the 18 joint parameters uniform within
``LOWER_LIMITS``/``UPPER_LIMITS``, the root upright at the origin with a uniform heading.

Per renderer, all measured in this run:

* ms per view: median (and max) over poses x cameras, after one warm-up render per camera;
* energy evaluations per second of :class:`tracking.track.energy.SilhouetteEnergy` (4 views) at
  pyramid levels 0, 1, 2 (640x480, 320x240, 160x120), for about ``--budget`` seconds each;
* agreement with ``open3d-raycast``: XOR pixels / ray-cast silhouette pixels, mean and max
  over poses x cameras;
* speed ratio: open3d-raycast's ms per view over the renderer's;
* for the default renderer, the energy's evaluations per second as it counts the XOR without
  drawing the model (`tracking.track.energy.XorCount`) against drawing the masks and counting
  their XOR (the former way; the same integers, checked), and the ratio.

Filament (``open3d-filament``) on a CPU-only machine runs on Mesa's lavapipe: expect
0.04-0.5 s per frame and, now and then, a stall of 25-50 s on a new camera's first frame (the
max column shows them). A renderer that cannot start is listed with its reason.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from plugins.registry import PluginError, create
from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS, BodyModel, BodyShape, Pose
from tracking.rig.cameras import ring_cameras
from tracking.track.energy import SilhouetteEnergy
from tracking.track.render import DEFAULT_RENDERER

REFERENCE = "open3d-raycast"
ALL = ("cpu-raster", "open3d-raycast", "open3d-filament")
LEVELS = (0, 1, 2)


def random_poses(count: int, seed: int) -> list[Pose]:
    """Joint parameters uniform inside their limits; root at the origin, upright, any heading."""
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(count):
        params = np.zeros(len(LOWER_LIMITS))
        params[6:] = rng.uniform(LOWER_LIMITS[6:], UPPER_LIMITS[6:])
        params[5] = rng.uniform(-np.pi, np.pi)  # root_ry, the heading
        poses.append(Pose(params))
    return poses


def _evals_per_second(energy: Callable[[Pose, int], float], poses: list[Pose], level: int,
                      budget_s: float) -> float:
    energy(poses[0], level)  # warm-up: per-camera caches of this level
    start, count = time.perf_counter(), 0
    while True:
        energy(poses[count % len(poses)], level)
        count += 1
        elapsed = time.perf_counter() - start
        if elapsed >= budget_s or count >= 200:
            return count / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--budget", type=float, default=3.0,
                        help="seconds of energy evaluations per renderer and level")
    parser.add_argument("--renderers", default=",".join(ALL))
    args = parser.parse_args()
    names = [n.strip() for n in args.renderers.split(",") if n.strip()]
    if REFERENCE not in names:
        names.insert(0, REFERENCE)

    model = BodyModel(BodyShape.default())
    cameras = ring_cameras(4, 4.0, 0.0, (0.0, 0.0, 0.0), 640, 480, 500.0)
    poses = random_poses(args.poses, args.seed)
    meshes = [model.posed_vertices(p) for p in poses]
    print(f"{len(cameras)} ring cameras 640x480, body model {len(model.rest_vertices)} vertices "
          f"/ {len(model.faces)} triangles, {len(poses)} random poses (seed {args.seed})")

    renderers, failed = {}, {}
    for name in names:
        options = ["canvas_px=640"] if name == "open3d-filament" else []
        try:
            renderers[name] = create("renderer", name, options)
        except PluginError as exc:
            failed[name] = str(exc)

    reference = renderers[REFERENCE]
    truth = [[reference.render(v, model.faces, c) for c in cameras] for v in meshes]
    masks = truth[0]  # the image silhouettes the energy compares against: pose 0

    rows = {}
    for name, renderer in renderers.items():
        for camera in cameras:  # warm-up: per-camera caches, Filament's first frame
            renderer.render(meshes[0], model.faces, camera)
        times, disagreement = [], []
        for vertices, reference_masks in zip(meshes, truth, strict=True):
            for camera, expected in zip(cameras, reference_masks, strict=True):
                start = time.perf_counter()
                mask = renderer.render(vertices, model.faces, camera)
                times.append(time.perf_counter() - start)
                disagreement.append(np.count_nonzero(mask ^ expected) / expected.sum())
        energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=len(LEVELS))
        rates = [_evals_per_second(energy, poses, level, args.budget) for level in LEVELS]
        rows[name] = (1000 * statistics.median(times), 1000 * max(times), rates,
                      float(np.mean(disagreement)), float(np.max(disagreement)))
        print(f"  measured {name}", file=sys.stderr)

    reference_ms = rows[REFERENCE][0]
    print()
    print(f"{'renderer':<17}{'ms/view':>9}{'max':>9}{'evals/s L0':>12}{'L1':>8}{'L2':>8}"
          f"{'XOR vs raycast':>16}{'max':>8}{'speed vs raycast':>18}")
    for name, (ms, ms_max, rates, xor_mean, xor_max) in rows.items():
        agreement = "reference" if name == REFERENCE else f"{100 * xor_mean:.3f}%"
        worst = "" if name == REFERENCE else f"{100 * xor_max:.2f}%"
        print(f"{name:<17}{ms:>9.2f}{ms_max:>9.1f}{rates[0]:>12.1f}{rates[1]:>8.1f}"
              f"{rates[2]:>8.1f}{agreement:>16}{worst:>8}{reference_ms / ms:>17.2f}x")
    for name, reason in failed.items():
        print(f"{name:<17}unavailable: {reason}")
    if DEFAULT_RENDERER in renderers:
        # The energy counts its XOR without drawing the model (`XorCount`); the former way drew
        # the masks and counted their XOR: the same integers, evaluated here on the same poses.
        energy = SilhouetteEnergy(model, cameras, masks, renderers[DEFAULT_RENDERER],
                                  levels=len(LEVELS))  # fmt: skip

        def drawn(pose: Pose, level: int) -> float:
            return float(sum(np.count_nonzero(x) for x in energy.xor_masks(pose, level)))

        assert all(drawn(p, 1) * energy._pixel_area[1][0] == energy(p, 1) for p in poses)
        counted = [_evals_per_second(energy, poses, level, args.budget) for level in LEVELS]
        former = [_evals_per_second(drawn, poses, level, args.budget) for level in LEVELS]
        print(f"\n{DEFAULT_RENDERER} energy, counted (ours) / drawn (the former way), evals/s: "
              + ", ".join(f"L{level} {c:.0f} / {f:.0f} = {c / f:.2f}x"
                          for level, c, f in zip(LEVELS, counted, former, strict=True)))
    fastest = min(rows, key=lambda n: rows[n][0])
    print()
    print(f"fastest: {fastest}; default renderer (tracking.track.render.DEFAULT_RENDERER): "
          f"{DEFAULT_RENDERER}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
