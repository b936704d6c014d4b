"""Lost and recovered frames, and video frame rates (issue 20, items 2 and 3).

    .venv/bin/python benchmarks/tracking_recovery.py [--clip NAME] [--fps 30 60] [--frames N]
        [--corrupt A-B] [--true-start] [--keep DIR] [--reuse]

`mocap synth` renders a CMU clip of ``../shared/data/mocap_bvh`` (default: the walk) with its
defaults (4 ring cameras, 640x480, noisy silhouettes, MakeHuman's skinned body with
`tracking.rig.synth.SUBJECT_SHAPE` in loose clothing: not the tracker's own model) at each
``--fps``, keeping ``--frames`` frames; `mocap track` tracks them with its defaults (the
automatic start, the shape pass). ``--corrupt A-B`` first replaces the silhouettes of frames A
to B by those of frame ``A - 8`` in every camera (a track forced wrong: what a tracker sees
when its silhouettes freeze or jump), so that those frames' truth is not what they show.

Printed per run: MPJPE over the clip against the subject's own joints (gt/joints.csv), outside
the corrupted stretch when there is one; the worst joint; the frames pose.json marks lost and
recovered (its ``status`` per frame, `tracking.track.step`); the first frame after the stretch
that is tracked within 80 mm MPJPE again; frames per second and the XOR fraction per frame.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
from _cli import SHARED_DATA, mocap  # benchmarks/ is on sys.path when a script here runs
from tracking_synthetic import _joints

CLIPS = SHARED_DATA / "mocap_bvh"


def corrupt(ws: Path, first: int, last: int, source: int) -> None:
    """Silhouettes of frames first..last replaced by those of frame `source`, every camera."""
    for folder in sorted(p for p in (ws / "silhouettes").iterdir() if p.is_dir()):
        for frame in range(first, last + 1):
            shutil.copyfile(folder / f"{source:06d}.png", folder / f"{frame:06d}.png")


def per_frame_mpjpe(ws: Path) -> dict[int, float]:
    """MPJPE (mm) of each tracked frame against gt/joints.csv."""
    truth, tracked = _joints(ws / "gt" / "joints.csv"), _joints(ws / "tracks" / "joints.csv")
    return {f: 1000 * float(np.mean([np.linalg.norm(xyz - truth[f][n])
                                     for n, xyz in joints.items()]))
            for f, joints in tracked.items()}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", default="cmu_02_01_walk.bvh", help="a clip of mocap_bvh/")
    parser.add_argument("--fps", type=float, nargs="+", default=[30.0])
    parser.add_argument("--frames", type=int, default=24, help="frames synthesised and tracked")
    parser.add_argument("--first-frame", type=int, help="first clip frame (synth's default)")
    parser.add_argument("--corrupt", help="frames A-B whose silhouettes are replaced")
    parser.add_argument("--keep", type=Path, help="keep the workspaces in this folder")
    parser.add_argument("--reuse", action="store_true",
                        help="reuse a kept workspace's synthesis (--keep)")
    parser.add_argument("--true-start", action="store_true",
                        help="start from the subject's own pose and body (--init-pose "
                        "gt/pose.json) instead of the automatic start")
    parser.add_argument("--track", nargs=argparse.REMAINDER, default=[],
                        help="further mocap track flags (last)")
    args = parser.parse_args()
    clip = CLIPS / args.clip
    if not clip.exists():
        sys.exit(f"{clip} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for fps in args.fps:
            ws = root / f"{clip.stem}_{fps:g}fps"
            if not (args.reuse and (ws / "gt" / "joints.csv").exists()):
                first = ["--first-frame", str(args.first_frame)] if args.first_frame else []
                mocap("synth", str(ws), "--bvh", str(clip), "--fps", str(fps), "--frames",
                      str(args.frames), "--overwrite", *first, echo=False)  # fmt: skip
            stretch: range = range(0)
            if args.corrupt:
                a, b = (int(v) for v in args.corrupt.split("-"))
                corrupt(ws, a, b, max(a - 8, 0))
                stretch = range(a, b + 1)
            start = ["--init-pose", str(ws / "gt" / "pose.json")] if args.true_start else []
            seconds = mocap("track", str(ws), "--overwrite", *start, *args.track, echo=False)
            pose = json.loads((ws / "tracks" / "pose.json").read_text())
            errors = per_frame_mpjpe(ws)
            truth, tracked = (_joints(ws / "gt" / "joints.csv"),
                              _joints(ws / "tracks" / "joints.csv"))  # fmt: skip
            per_joint: dict[str, list[float]] = defaultdict(list)
            for f, joints in tracked.items():
                if f not in stretch:
                    for n, xyz in joints.items():
                        per_joint[n].append(1000 * float(np.linalg.norm(xyz - truth[f][n])))
            scored = [e for f, e in errors.items() if f not in stretch]
            worst = max(per_joint, key=lambda n: np.mean(per_joint[n]))
            status = {e["frame"]: e.get("status", "?") for e in pose["frames"]}
            back = next((f for f in sorted(errors) if stretch and f > stretch[-1]
                         and errors[f] < 80), None)  # fmt: skip
            print(f"{clip.stem} at {fps:g} fps, {args.frames} frames"
                  + (", from the true start" if args.true_start else "")
                  + (f", silhouettes of {args.corrupt} replaced" if stretch else "")
                  + f": MPJPE {np.mean(scored):.1f} mm (outside the stretch), worst joint "
                  f"{worst} {np.mean(per_joint[worst]):.1f} mm; {len(errors)}/{len(status)} "
                  f"frames with a pose; {len(status) / seconds:.2f} frames/s")
            print(f"  lost {pose.get('lost', [f for f, s in status.items() if s == 'lost'])}"
                  f" recovered {pose.get('recovered', '?')}"
                  + (f"; tracked within 80 mm again from frame {back}" if stretch else ""))
            print("  frame: status XOR MPJPE: " + ", ".join(
                f"{e['frame']}:{status[e['frame']][:4]} "
                f"{(e['xor_fraction'] or float('nan')):.2f} "
                f"{errors.get(e['frame'], float('nan')):.0f}" for e in pose["frames"]))
            for e in pose["frames"]:
                if e["event"]:
                    print(f"  frame {e['frame']}: {e['event']}")


if __name__ == "__main__":
    main()
