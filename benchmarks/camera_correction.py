"""The cameras' correction by silhouette coherence (`mocap silhouettes`), against a known truth.

    .venv/bin/python benchmarks/camera_correction.py [--frames N] [--keep DIR]

`mocap synth --videos --clean` films the CMU walk (MakeHuman's skinned body, `mocap synth`'s
defaults: a mismatched subject with loose clothes) with 4 ring cameras at 640x480. The
calibration handed to `mocap capture` then has two cameras off by a few pixels (`OFFSETS_PX`:
what a camera turned by a fifth to a third of a degree shows), and the same videos are captured
three times, with `mocap capture`'s defaults but for the calibration and ``--no-refine-cameras``:

* exact: the true calibration (the correction must leave it as it is);
* off, corrected: the default, the cameras corrected by the silhouettes;
* off, as given: ``--no-refine-cameras``, the previous behaviour.

Printed per run: MPJPE against the synthetic truth (`tracking.rig.synth_video.capture_scores`),
the same with the mean offset of all joints over all frames removed ("moved": a correction by
silhouettes alone is determined up to a move of the whole scene, which it leaves), the worst
joint error, the silhouettes' IoU with the exact renders, and the correction found;
then the MPJPE ratio of the corrected run to the uncorrected one, in the same run. The
correction is compared with the offsets up to what a move of the subject explains (every
image shift that a 3D translation of the subject makes is no error of the rig): the residual
is the offsets plus the correction, less the shifts of the best such translation (least
squares over the 4 views' projection Jacobians at the subject).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from _cli import SHARED_DATA, mocap  # benchmarks/ is on sys.path when a script here runs

BVH = SHARED_DATA / "mocap_bvh" / "cmu_02_01_walk.bvh"
OFFSETS_PX = {"cam01": (10.0, -6.0), "cam02": (-7.0, 0.0)}
"""Principal-point errors of the calibration given to the capture, pixels (x, y)."""


def _gauge_residual(cameras: list, offsets: dict, corrections: np.ndarray,
                    centre: np.ndarray) -> np.ndarray:  # fmt: skip
    """(C, 2) the calibration's `offsets` (name -> (x, y) px) plus the corrections, less the
    image shifts of the 3D translation of the subject at `centre` that explains most of
    them."""
    error = np.array([offsets.get(c.name, (0.0, 0.0)) for c in cameras]) + corrections
    rows = []
    for cam in cameras:  # d(uv)/d(centre) by central differences, 1 mm
        rows.append(np.stack([(cam.project((centre + d)[None])[0][0]
                               - cam.project((centre - d)[None])[0][0]) / 2e-3
                              for d in np.eye(3) * 1e-3], axis=1))  # fmt: skip
    jacobian = np.concatenate(rows)  # (2C, 3)
    move = np.linalg.lstsq(jacobian, error.ravel(), rcond=None)[0]
    return (error.ravel() - jacobian @ move).reshape(-1, 2)


def main() -> None:
    from recon.cameras import read_cameras_json, write_cameras_json
    from tracking.rig.synth_video import capture_scores, read_joints_csv
    from tracking.silhouettes.coherence import shifted

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=45)
    parser.add_argument("--keep", type=Path, help="keep the workspaces in this folder")
    args = parser.parse_args()
    if not BVH.is_file():
        sys.exit(f"{BVH} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        synth = root / "synth"
        mocap("synth", str(synth), "--bvh", str(BVH), "--cameras", "4", "--size", "640x480",
              "--frames", str(args.frames), "--videos", "--clean", echo=False)  # fmt: skip
        exact = read_cameras_json(synth / "cameras.json")
        off = [shifted(c, OFFSETS_PX.get(c.name, (0.0, 0.0))) for c in exact]
        write_cameras_json(root / "off.json", off)
        gt = json.loads((synth / "gt" / "pose.json").read_text())
        truth = read_joints_csv(synth / "gt" / "joints.csv")
        centre = np.mean([f["params"][:3] for f in gt["frames"]], axis=0)
        centre = np.asarray(gt.get("world_from_upright", np.eye(3))) @ centre
        print(f"CMU walk, {args.frames} frames, 4 cameras 640x480; calibration off by "
              + ", ".join(f"{k} {v}" for k, v in OFFSETS_PX.items()) + " px")
        print(f"{'run':>18} {'MPJPE mm':>9} {'moved':>6} {'max mm':>7} {'sil IoU':>8}  "
              "correction (px)")
        mpjpe = {}
        for name, calibration, flags, offsets in (
                ("exact", synth / "cameras.json", (), {}),
                ("off, corrected", root / "off.json", (), OFFSETS_PX),
                ("off, as given", root / "off.json", ("--no-refine-cameras",), OFFSETS_PX)):
            ws = root / name.replace(", ", "_").replace(" ", "_")
            mocap("capture", str(ws), "--videos", str(synth / "render" / "videos"),
                  "--calibration", str(calibration), "--background-images",
                  str(synth / "render" / "backgrounds"), *flags, echo=False)  # fmt: skip
            scores = capture_scores(ws, synth)
            mpjpe[name] = scores.mpjpe_mm
            # Up to a move of the whole subject: what silhouettes alone cannot tell.
            tracked = read_joints_csv(ws / "tracks" / "joints.csv")
            errors = np.array([tracked[k] - truth[k] for k in tracked if k in truth])
            moved = 1000 * np.linalg.norm(errors - errors.mean(axis=0), axis=1).mean()
            record = json.loads((ws / "run.json").read_text())["steps"]["silhouettes"]
            correction = record["summary"].get("camera_correction")
            text = "off"
            if correction is not None:
                found = np.array([correction["shifts_px"][c.name] for c in exact])
                residual = _gauge_residual(exact, offsets, found if correction["accepted"]
                                           else 0 * found, centre)  # fmt: skip
                text = (("applied " if correction["accepted"] else "not applied ")
                        + ", ".join(f"{c.name} ({x:+.0f}, {y:+.0f})"
                                    for c, (x, y) in zip(exact, found, strict=True))
                        + f"; rig error left {np.abs(residual).max():.1f} px (max, up to a "
                        "move of the subject)")  # fmt: skip
            print(f"{name:>18} {scores.mpjpe_mm:>9.1f} {moved:>6.1f} "
                  f"{scores.max_joint_error_mm:>7.0f} {scores.silhouette_iou:>8.3f}  {text}",
                  flush=True)  # fmt: skip
        print(f"\nMPJPE ratio corrected / as given: "
              f"{mpjpe['off, corrected'] / mpjpe['off, as given']:.2f}; corrected / exact: "
              f"{mpjpe['off, corrected'] / mpjpe['exact']:.2f}")


if __name__ == "__main__":
    main()
