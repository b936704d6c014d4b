"""`mocap silhouettes` with its defaults on small synthetic recordings of the kinds users record
(benchmarks/silhouettes_kinds.py runs the same kinds at 640x480 with CMU clips): a subject who
keeps still, with a plate; a subject who walks across the images, with no plate; a plate and
an exposure drift. Scored against `mocap synth --clean`'s exact renders (video frame k is synth
frame k), per camera: the median IoU over the frames, the worst frame's, and no empty
silhouette with the subject in view.

`mocap synth` renders our own body model over a synthetic scene in red cloth; the silhouettes
step sees only pixels, so that is a fair subject for it. 2 cameras face each other (cam00 at
+Z, cam01 at -Z), 320x240, 12 frames, MJPG quality 95 as synth writes it.

The issue's target, median IoU >= 0.92, is asserted on a lossless video of the still scene;
the MJPG videos get `MJPG_MEDIAN`: MJPG blurs the cloth's colour into the scene by about a
pixel all round the outline, which the step rightly calls foreground, and at 320x240 that
rim alone costs ~0.08 of IoU (measured: still + plate 0.876-0.891 from MJPG, 0.962-0.974 from
the same frames lossless; walk + median 0.869-0.887; at 640x480 the same still scene gives
0.928-0.932 from MJPG).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.workspace import Workspace
from tests.tracking.test_capture import Synthetic
from tracking.body.bvh import write_bvh
from tracking.body.model import BodyShape
from tracking.body.motion import motion_from_poses
from tracking.body.synthetic import walking_poses
from tracking.rig.synth import SynthConfig, synthesize
from tracking.rig.synth_video import cloth_texture, composite, scene_background
from tracking.rig.video import init_video
from tracking.silhouettes.step import UNKNOWN_NAME, SilhouettesConfig, make_silhouettes

FRAMES = 12
SIZE = "320x240"
TARGET = 0.92
MJPG_MEDIAN, MJPG_WORST = 0.85, 0.75
DRIFT_END_BGR = (0.78, 0.80, 0.82)


def synthetic_scene(folder: Path, *, walk: bool, along: bool = False) -> Synthetic:
    """A 1.70 m subject filmed by cam00 (+Z) and cam01 (-Z): walking along +X at 1.2 m/s, so
    across both images, 12 frames at 6 Hz (2.2 m); ``along``: along +Z instead, towards cam00
    and away from cam01, on the same pixels of both images in most frames; or standing still
    (the walk's first pose, held) for 12 frames at 30 Hz."""
    shape = BodyShape.default(1.70)
    rate = 6.0 if walk else 30.0
    heading, start = (0.0, (0.0, -1.1)) if along else (90.0, (-1.1, 0.0))
    poses = walking_poses(FRAMES, rate, shape, heading_deg=heading, start_in_world=start,
                          **({} if walk else {"speed_m_s": 0.0, "cadence_hz": 0.0}))  # fmt: skip
    bvh = folder / "clip.bvh"
    folder.mkdir(parents=True)
    write_bvh(motion_from_poses(poses, shape, 1 / rate), bvh)
    synthesize(folder / "synth", SynthConfig(bvh=bvh, cameras=2, size=SIZE, step=1, clean=True,
                                             videos=True))  # fmt: skip
    return Synthetic(folder / "synth")


def drifted_videos(videos: Path, out: Path) -> Path:
    """``out/<camera>.avi``, lossless (FFV1): frame k of n of each video multiplied per channel
    by ``1 - (1 - end) * k / (n - 1)`` (the light dims: 22% in blue, 18% in red at the end)."""
    out.mkdir()
    end = np.asarray(DRIFT_END_BGR, np.float32)
    for video in sorted(videos.iterdir()):
        capture = cv2.VideoCapture(str(video))
        frames = []
        while (read := capture.read())[0]:
            frames.append(read[1])
        capture.release()
        height, width = frames[0].shape[:2]
        writer = cv2.VideoWriter(str(out / f"{video.stem}.avi"), cv2.VideoWriter_fourcc(*"FFV1"),
                                 30.0, (width, height))  # fmt: skip
        assert writer.isOpened(), "OpenCV cannot write FFV1 here"
        for k, frame in enumerate(frames):
            gain = 1 - (1 - end) * k / (len(frames) - 1)
            writer.write(np.clip(frame * gain + 0.5, 0, 255).astype(np.uint8))
        writer.release()
    return out


def lossless_videos(scene: Synthetic, out: Path) -> Path:
    """``out/<camera>.avi`` (FFV1): the frames of the scene's videos composited again, as
    `tracking.rig.synth_video.SyntheticVideos` does, from the exact renders."""
    out.mkdir()
    for k, folder in enumerate(sorted(p for p in (scene.root / "silhouettes").iterdir()
                                      if p.is_dir())):  # fmt: skip
        masks = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) > 127
                 for p in sorted(folder.glob("[0-9]*.png"))]  # fmt: skip
        height, width = masks[0].shape
        backdrop = scene_background(width, height, 17 * k)  # synth's seed 0, camera k
        assert np.array_equal(backdrop, cv2.imread(str(scene.backgrounds / f"{folder.name}.png")))
        cloth = cloth_texture(width, height, 17 * k)
        writer = cv2.VideoWriter(str(out / f"{folder.name}.avi"), cv2.VideoWriter_fourcc(*"FFV1"),
                                 30.0, (width, height))  # fmt: skip
        assert writer.isOpened(), "OpenCV cannot write FFV1 here"
        for mask in masks:
            writer.write(composite(backdrop, cloth, mask))
        writer.release()
    return out


@pytest.fixture(scope="module")
def still(tmp_path_factory: pytest.TempPathFactory) -> Synthetic:
    return synthetic_scene(tmp_path_factory.mktemp("kinds") / "still", walk=False)


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Synthetic:
    return synthetic_scene(tmp_path_factory.mktemp("kinds") / "walk", walk=True)


@pytest.fixture(scope="module")
def walk_along(tmp_path_factory: pytest.TempPathFactory) -> Synthetic:
    return synthetic_scene(tmp_path_factory.mktemp("kinds") / "along", walk=True, along=True)


@dataclass(frozen=True)
class Scores:
    median: dict[str, float]
    worst: dict[str, float]
    empty: dict[str, list[int]]
    """Frames whose truth shows the subject but whose silhouette is empty."""


def scores(ws: Workspace, truth: Synthetic) -> Scores:
    """Per camera, the IoU of every silhouette of ``ws`` with the exact render of its frame."""
    median, worst, empty = {}, {}, {}
    for folder in sorted(p for p in (truth.root / "silhouettes").iterdir() if p.is_dir()):
        ious, empty[folder.name] = [], []
        exact_masks = sorted(folder.glob("[0-9]*.png"))
        assert len(exact_masks) == FRAMES
        for path in exact_masks:
            exact = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127
            found = cv2.imread(str(ws.silhouettes_dir / folder.name / path.name),
                               cv2.IMREAD_GRAYSCALE) > 127  # fmt: skip
            assert exact.any()  # the subject is in view in every frame
            ious.append(np.count_nonzero(exact & found) / np.count_nonzero(exact | found))
            if not found.any():
                empty[folder.name].append(int(path.stem))
        median[folder.name], worst[folder.name] = float(np.median(ious)), float(min(ious))
    return Scores(median, worst, empty)


def assert_found(result: Scores, median: float = MJPG_MEDIAN, worst: float = MJPG_WORST
                 ) -> None:  # fmt: skip
    assert all(m >= median for m in result.median.values()), result
    assert all(w >= worst for w in result.worst.values()), result
    assert not any(result.empty.values()), result


def test_a_subject_who_keeps_still_is_found_against_the_plate(still: Synthetic, tmp_path: Path):
    ws = init_video(tmp_path / "ws", still.videos, still.calibration)
    record = make_silhouettes(ws, SilhouettesConfig(background_images=still.backgrounds))
    assert_found(scores(ws, still))
    assert not record.summary["warnings"]


def test_a_subject_who_keeps_still_meets_the_target_without_the_codec(still: Synthetic,
                                                                      tmp_path: Path):  # fmt: skip
    """The same frames, lossless: what is left is the step's own error (the gaps between the
    arms and the trunk and between the legs that its closing fills)."""
    ws = init_video(tmp_path / "ws", lossless_videos(still, tmp_path / "lossless"),
                    still.calibration)  # fmt: skip
    make_silhouettes(ws, SilhouettesConfig(background_images=still.backgrounds))
    assert_found(scores(ws, still), TARGET, TARGET)


def test_a_subject_who_keeps_still_is_lost_by_the_median(still: Synthetic, tmp_path: Path):
    """Why plates exist: held still, the subject is its own temporal median, the background;
    the silhouettes are empty (or nearly) in every frame of every camera."""
    ws = init_video(tmp_path / "ws", still.videos, still.calibration)
    record = make_silhouettes(ws, SilhouettesConfig())
    result = scores(ws, still)
    assert max(result.median.values()) < 0.1, result
    assert all(len(frames) >= FRAMES - 1 for frames in result.empty.values()), result
    # The step says why, and what to give it.
    for name in result.empty:
        assert any(w.startswith(f"{name}: every silhouette is empty") and "plates" in w
                   for w in record.summary["warnings"]), record.summary["warnings"]  # fmt: skip


def test_a_subject_who_walks_across_is_found_by_the_median(walk: Synthetic, tmp_path: Path):
    ws = init_video(tmp_path / "ws", walk.videos, walk.calibration)
    record = make_silhouettes(ws, SilhouettesConfig())
    assert_found(scores(ws, walk))
    assert not record.summary["warnings"]
    assert not list(ws.silhouettes_dir.glob(f"*/{UNKNOWN_NAME}"))


def test_a_median_that_holds_the_walking_subject_is_reported(walk_along: Synthetic,
                                                             tmp_path: Path):  # fmt: skip
    """Walking towards one camera and away from the other, the subject stays on the same
    pixels in most frames: the median shows it there, no method can see the empty scene
    behind it, and the silhouettes miss most of it. The step must not pass that off as a
    result: each camera is warned about, and the pixels it could not tell are unknown."""
    ws = init_video(tmp_path / "ws", walk_along.videos, walk_along.calibration)
    record = make_silhouettes(ws, SilhouettesConfig())
    result = scores(ws, walk_along)
    assert max(result.median.values()) < MJPG_MEDIAN, result  # lost, as expected
    for name in result.median:
        assert record.summary["cameras"][name]["median_holds_subject"] > 0.01
        assert any(w.startswith(f"{name}: the subject stood on the same pixels") and
                   "--background-images" in w for w in record.summary["warnings"])
        unknown = cv2.imread(str(ws.silhouettes_dir / name / UNKNOWN_NAME),
                             cv2.IMREAD_GRAYSCALE) > 127  # fmt: skip
        found_missed = [0, 0]
        for path in sorted((walk_along.root / "silhouettes" / name).glob("[0-9]*.png")):
            exact = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127
            found = cv2.imread(str(ws.silhouettes_dir / name / path.name),
                               cv2.IMREAD_GRAYSCALE) > 127  # fmt: skip
            missed = exact & ~found
            found_missed[0] += np.count_nonzero(missed & unknown)
            found_missed[1] += np.count_nonzero(missed)
        # Most of what the silhouettes miss lies in the unknown pixels.
        assert found_missed[0] >= 0.7 * found_missed[1], (name, found_missed)


def test_an_exposure_drift_is_matched_to_the_plate(still: Synthetic, tmp_path: Path):
    """The light dims by ~20% over the clip (per channel slightly differently); the plate was
    taken at the start's exposure. Each frame's gain to the plate is measured and undone."""
    videos = drifted_videos(still.videos, tmp_path / "drift")
    ws = init_video(tmp_path / "ws", videos, still.calibration)
    record = make_silhouettes(ws, SilhouettesConfig(background_images=still.backgrounds))
    assert_found(scores(ws, still))
    for name, camera in record.summary["cameras"].items():
        gain = camera["exposure_gain"]
        assert gain["min"] == pytest.approx(0.80, abs=0.03), name  # the last frame's
        assert gain["max"] == pytest.approx(1.00, abs=0.03), name  # the first frame's
