"""Silhouette tracking on the synthetic CMU walk (issue 6), one run.

    .venv/bin/python benchmarks/tracking_synthetic.py [--frames N] [--keep DIR]

`mocap synth` renders the CMU walk (cmu_02_01_walk.bvh, 30 fps) into 4 ring cameras at
640x480 with silhouette noise; `mocap track` tracks it with its defaults (automatic
initialisation from the visual hull). Reported: MPJPE over the clip and per joint (against
gt/joints.csv), lost frames, seconds per frame and energy evaluations per second, and, measured
in the same run on the same masks, the energy evaluations per second of each renderer plugin.

Targets: MPJPE <= 25 mm with no frame lost; >= 1 frame per second on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from _cli import mocap  # benchmarks/ is on sys.path when a script here runs

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT.parent / "shared" / "data" / "mocap_bvh" / "cmu_02_01_walk.bvh"


def _joints(path: Path) -> dict[int, dict[str, np.ndarray]]:
    out: dict[int, dict[str, np.ndarray]] = defaultdict(dict)
    with path.open() as handle:
        for row in csv.DictReader(handle):
            out[int(row["frame"])][row["joint"]] = np.array([float(row[k]) for k in "xyz"])
    return out


def _renderer_speeds(ws: Path) -> None:
    from plugins.registry import create
    from tracking.body.model import BodyModel, BodyShape, Pose
    from tracking.rig.cameras import read_cameras
    from tracking.track.energy import SilhouetteEnergy
    from tracking.track.render import filament_unavailable_reason

    pose_file = json.loads((ws / "gt" / "pose.json").read_text())
    shape = BodyShape(**pose_file["shape"])
    pose = Pose(pose_file["frames"][0]["params"])
    cameras = read_cameras(ws / "cameras.json")
    import cv2

    masks = [cv2.imread(str(ws / "silhouettes" / c.name / "000000.png"), 0) > 127
             for c in cameras]  # fmt: skip
    print("\nenergy evaluations per second (4 views, 640x480, same masks):")
    rates = {}
    for name in ("cpu-raster", "open3d-raycast", "open3d-filament"):
        if name == "open3d-filament" and (reason := filament_unavailable_reason(60.0)):
            print(f"  {name:16s} unavailable: {reason}")
            continue
        energy = SilhouetteEnergy(BodyModel(shape), cameras, masks, create("renderer", name))
        for level in (0, 1):
            energy(pose, level)
            start = time.perf_counter()
            n = 0
            while time.perf_counter() - start < 3.0:
                energy(pose, level)
                n += 1
            rates[(name, level)] = n / (time.perf_counter() - start)
    reference = rates[("open3d-raycast", 0)]
    for name in dict.fromkeys(n for n, _ in rates):
        print(f"  {name:16s} level 0: {rates[(name, 0)]:6.1f}/s  level 1: "
              f"{rates[(name, 1)]:6.1f}/s  speed vs open3d-raycast (level 0): "
              f"{rates[(name, 0)] / reference:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, help="track only the first N frames")
    parser.add_argument("--keep", type=Path, help="keep the workspace in this folder")
    args = parser.parse_args()
    if not WALK.exists():
        sys.exit(f"{WALK} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        ws = args.keep or Path(tmp) / "walk"
        mocap("synth", str(ws), "--bvh", str(WALK), "--cameras", "4", "--size", "640x480")
        extra = ["--last", str(args.frames - 1)] if args.frames else []
        seconds = mocap("track", str(ws), "--overwrite", *extra)
        truth, tracked = _joints(ws / "gt" / "joints.csv"), _joints(ws / "tracks" / "joints.csv")
        run = json.loads((ws / "run.json").read_text())["steps"]["track"]["summary"]
        frames = sorted(f for f in truth if not args.frames or f < args.frames)
        per_joint: dict[str, list[float]] = defaultdict(list)
        for f in frames:
            for name, xyz in tracked.get(f, {}).items():
                per_joint[name].append(1000 * float(np.linalg.norm(xyz - truth[f][name])))
        lost = [f for f in frames if f not in tracked]
        mpjpe = float(np.mean([e for v in per_joint.values() for e in v]))
        print(f"\nMPJPE over {len(frames)} frames: {mpjpe:.1f} mm; lost frames: {lost or 'none'}")
        print("per joint (mm): " + ", ".join(f"{n} {np.mean(v):.1f}"
                                             for n, v in per_joint.items()))  # fmt: skip
        fps = len(frames) / seconds
        evals = run["evaluations_per_frame"] * len(frames) / seconds
        print(f"speed: {fps:.2f} frames/s ({seconds:.0f} s wall incl. start-up), "
              f"{evals:.0f} energy evaluations/s, {run['evaluations_per_frame']:.0f} per frame")
        print(f"median XOR {run['median_xor_fraction']:.1%} of the silhouette area")
        print(f"target MPJPE <= 25 mm, none lost: "
              f"{'PASS' if mpjpe <= 25 and not lost else 'FAIL'}; target >= 1 frame/s: "
              f"{'PASS' if fps >= 1 else 'FAIL'}")  # fmt: skip
        _renderer_speeds(ws)


if __name__ == "__main__":
    main()
