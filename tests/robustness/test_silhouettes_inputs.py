"""Robustness rows for the background plates of `mocap silhouettes` (issue 18): each bad plate
is one error line with exit code 2, the videos and plates untouched, and no silhouettes
written (the step writes into ``silhouettes.partial/`` and renames it only when done).

Inputs are made here, without ../shared/data: the 3-camera, 24-frame, 200x150 blob scene of
tests/tracking/rig/test_video.py (`make_blob_scene`), its video workspace, and a clean plate
per camera (the scene's own background image), built once per session and copied per row.
"""

from __future__ import annotations

import functools
import json
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import cv2
import pytest

from tests.robustness.harness import Case, check_case, rows
from tests.robustness.scenes import cache_folder
from tests.tracking.rig.test_video import background_image, make_blob_scene, write_video

CAMERAS = ("cam00", "cam01", "cam02")


@functools.cache
def _scene() -> Path:
    """``ws/`` (the video workspace), ``plates/cam0k.png`` (clean) and ``clips/cam0k.avi``
    (6 frames of the clean plate) in a cached folder."""
    from tracking.rig.video import init_video

    root = cache_folder() / "plates"
    if not (root / "ws").exists():
        videos, calibration, _ = make_blob_scene(root / "scene")
        init_video(root / "ws", videos, calibration)
        (root / "plates").mkdir()
        (root / "clips").mkdir()
        for k, name in enumerate(CAMERAS):
            cv2.imwrite(str(root / "plates" / f"{name}.png"), background_image(seed=k))
            write_video(root / "clips" / f"{name}.avi", [background_image(seed=k)] * 6)
    return root


def _with(change: Callable[[Path], None] | None = None) -> Callable[[Path], None]:
    """Setup: the cached scene copied into the case's folder, then ``change(folder)``."""

    def setup(folder: Path) -> None:
        for part in ("ws", "plates", "clips"):
            shutil.copytree(_scene() / part, folder / part)
        if change is not None:
            change(folder)

    return setup


def _extra_plate(folder: Path) -> None:
    cv2.imwrite(str(folder / "plates" / "camera9.png"), background_image(seed=9))


def _small_plate(folder: Path) -> None:
    cv2.imwrite(str(folder / "plates" / "cam01.png"), background_image(seed=1, width=100,
                                                                        height=75))


def _small_clip(folder: Path) -> None:
    write_video(folder / "clips" / "cam02.avi", [background_image(seed=2, width=160,
                                                                  height=120)] * 6)


def _turned_plate(folder: Path) -> None:
    """cam00's plate upside down: a view the video does not show (the scene's textures are
    too faint to tell one camera's plate from another's, its left-to-right ramp is not)."""
    path = folder / "plates" / "cam00.png"
    cv2.imwrite(str(path), cv2.imread(str(path))[::-1, ::-1])


def _missing_plate(folder: Path) -> None:
    (folder / "plates" / "cam02.png").unlink()


def _cluttered_plate(folder: Path) -> None:
    """cam00's plate shows a box at the left edge that the video never does."""
    path = folder / "plates" / "cam00.png"
    image = cv2.imread(str(path))
    image[40:110, :30] = (200, 60, 20)
    cv2.imwrite(str(path), image)


def _clutter_hinted(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    summary = json.loads((folder / "ws" / "run.json").read_text())["steps"]["silhouettes"][
        "summary"]
    hint = ("cam00: silhouette touches the image border in every frame (does the plate show "
            "people or objects the video does not? then --plates cluttered)")
    assert hint in summary["warnings"] and hint in result.stdout
    # The blob crossing the views touches the border only as it enters and leaves.
    assert not any("every frame" in w for w in summary["warnings"] if not w.startswith("cam00"))


def _nothing_written(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    assert not (ws / "silhouettes").exists() and not (ws / "silhouettes.partial").exists()
    assert "silhouettes" not in json.loads((ws / "run.json").read_text())["steps"]


def _fell_back(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    summary = json.loads((folder / "ws" / "run.json").read_text())["steps"]["silhouettes"][
        "summary"]
    assert "plate" not in summary["cameras"]["cam02"] and "plate" in summary["cameras"]["cam00"]
    assert any(w.startswith("cam02: no plate in plates: the temporal median")
               for w in summary["warnings"])
    assert "cam02: no plate in plates: the temporal median" in result.stdout


SIL = ("silhouettes", "ws")
IMAGES = (*SIL, "--background-images", "plates")
CLIPS = (*SIL, "--background-video", "clips")
INPUTS = ["ws/videos", "plates", "clips"]
ROWS = [
    Case("plate-names-no-camera", lambda f: IMAGES, _with(_extra_plate),
         message=r"plates/camera9\.png names no camera; name each plate after its camera",
         inputs=INPUTS, then=_nothing_written),
    Case("plate-of-another-size", lambda f: IMAGES, _with(_small_plate),
         message=r"background plate cam01\.png is 100x75, camera cam01's video 200x150",
         inputs=INPUTS, then=_nothing_written),
    Case("clip-of-another-size", lambda f: CLIPS, _with(_small_clip),
         message=r"background plate cam02\.avi is 160x120, camera cam02's video 200x150",
         inputs=INPUTS, then=_nothing_written),
    Case("plate-of-another-view", lambda f: IMAGES, _with(_turned_plate),
         message=r"camera cam00: its plate \(cam00\.png\) differs from its video on \d+% of "
                 r"the image or more in each of 5 frames",
         inputs=INPUTS, then=_nothing_written),
    Case("camera-without-plate", lambda f: IMAGES, _with(_missing_plate),
         message=r"no plate for camera\(s\) cam02 while the others have one; add theirs, or "
                 r"give --median-fallback", inputs=INPUTS, then=_nothing_written),
    Case("camera-without-plate-falls-back", lambda f: (*IMAGES, "--median-fallback"),
         _with(_missing_plate), rc=0, inputs=INPUTS, then=_fell_back),
    Case("plate-shows-what-the-video-does-not", lambda f: (*IMAGES, "--no-multi-view-check"),
         _with(_cluttered_plate), rc=0, inputs=INPUTS, then=_clutter_hinted),
    Case("plates-of-both-kinds", lambda f: (*IMAGES, "--background-video", "clips"), _with(),
         message=r"give --background-images or --background-video, not both",
         inputs=INPUTS, then=_nothing_written),
    Case("cluttered-clips", lambda f: (*CLIPS, "--plates", "cluttered"), _with(),
         message=r"--plates cluttered takes --background-images", inputs=INPUTS,
         then=_nothing_written),
]


@pytest.mark.parametrize("case", rows(ROWS))
def test_silhouettes_input(case: Case, tmp_path: Path) -> None:
    check_case(case, tmp_path)
