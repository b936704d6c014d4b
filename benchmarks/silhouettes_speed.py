"""Speed of `mocap silhouettes` next to OpenCV's MOG2 on the same frames, in one run.

    .venv/bin/python benchmarks/silhouettes_speed.py [--cameras 4] [--frames 120] [--keep DIR]

The scene: `mocap synth --videos` of the CMU walk (4 cameras, 640x480, MJPG, 120 frames at
every 2nd clip frame), made into a video workspace with `mocap init-video`. The step is run
as users run it (`mocap silhouettes WS --overwrite`, defaults: temporal median background,
the multi-view check), in its own process: decode, background model, classification,
clean-up, PNG writing, the check, the recording. Its wall time, start-up included, gives
camera-frames per second. It runs again with ``--no-multi-view-check`` and with
``--no-refine-cameras`` (the cameras' correction by silhouette coherence, session 18); the
differences are the check's and the correction's own times, on their own lines.

MOG2: ``cv2.createBackgroundSubtractorMOG2()`` with its defaults, fed every frame of every
camera's video in order; the time covers decoding and ``apply()``, with no clean-up and no
writing, so it is the floor of what a per-pixel model costs here.

Target (issue 18): the whole step >= 30 camera-frames/s at 640x480 on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
from _cli import SHARED_DATA, mocap  # benchmarks/ is on sys.path when a script here runs

WALK = SHARED_DATA / "mocap_bvh" / "cmu_02_01_walk.bvh"
TARGET = 30.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", type=int, default=4)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--keep", type=Path, help="keep the workspaces in this folder")
    args = parser.parse_args()
    if not WALK.is_file():
        sys.exit(f"{WALK} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        synth, ws = root / "synth", root / "capture"
        mocap("synth", str(synth), "--bvh", str(WALK), "--cameras", str(args.cameras),
              "--frames", str(args.frames), "--step", "2", "--videos", echo=False)
        if not (ws / "cameras.json").exists():
            mocap("init-video", str(ws), "--videos", str(synth / "render" / "videos"),
                  "--calibration", str(synth / "cameras.json"), echo=False)
        units = args.cameras * args.frames
        whole = mocap("silhouettes", str(ws), "--overwrite")
        alone = mocap("silhouettes", str(ws), "--overwrite", "--no-multi-view-check",
                      echo=False)  # fmt: skip
        fixed = mocap("silhouettes", str(ws), "--overwrite", "--no-refine-cameras", echo=False)
        videos = sorted((ws / "videos").iterdir())
        start = time.perf_counter()
        for video in videos:
            subtractor = cv2.createBackgroundSubtractorMOG2()
            capture = cv2.VideoCapture(str(video))
            while True:
                ok, frame = capture.read()
                if not ok:
                    break
                subtractor.apply(frame)
            capture.release()
        mog2 = time.perf_counter() - start
    print(f"{args.cameras} cameras x {args.frames} frames at 640x480 ({units} camera-frames)")
    print(f"{'method':<40}{'seconds':>9}{'camera-frames/s':>17}")
    for name, seconds in (("mocap silhouettes (defaults)", whole),
                          ("  without the multi-view check", alone),
                          ("  the multi-view check alone", whole - alone),
                          ("  without the camera correction", fixed),
                          ("  the camera correction alone", whole - fixed),
                          ("MOG2 (decode + apply, no clean-up)", mog2)):  # fmt: skip
        rate = units / seconds if seconds > 0 else float("inf")
        print(f"{name:<40}{seconds:>9.2f}{rate:>17.1f}")
    rate = units / whole
    print(f"time ours / MOG2: {whole / mog2:.2f}")
    print(f"target >= {TARGET:.0f} camera-frames/s: {rate:.1f}  "
          f"{'PASS' if rate >= TARGET else 'FAIL'}")


if __name__ == "__main__":
    main()
