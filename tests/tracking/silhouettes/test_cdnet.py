"""CDnet 2012 baseline/highway through `mocap silhouettes` itself (`make_silhouettes`, its
defaults), as benchmarks/silhouettes_cdnet.py scores it: the shipped path, a clean plate cut
from the frames before the scored range."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.cameras import Camera, write_cameras_json
from recon.workspace import Workspace
from tests.helpers import shared_dataset
from tracking.rig.video import read_frames
from tracking.silhouettes.step import SilhouettesConfig, make_silhouettes
from tracking.silhouettes.subtraction import Counts, confusion_counts

CAMERA = "highway"


def one_camera_workspace(ws: Path, frames: list[np.ndarray]) -> Workspace:
    """A video workspace not made by `init_video` (which wants two cameras or more): a
    lossless video of ``frames`` in order (HuffYUV: it decodes 3x faster than FFV1, and the
    step decodes the video up to its last processed frame more than once) and one nominal
    camera (f = image width, principal point at the centre, identity pose), as the benchmark
    builds it."""
    height, width = frames[0].shape[:2]
    (ws / "videos").mkdir(parents=True)
    writer = cv2.VideoWriter(
        str(ws / "videos" / f"{CAMERA}.mkv"), cv2.VideoWriter_fourcc(*"HFYU"), 30.0, (width, height)
    )
    assert writer.isOpened(), "OpenCV cannot write HuffYUV here"
    for frame in frames:
        writer.write(frame)
    writer.release()
    K = np.array([[width, 0.0, width / 2], [0.0, width, height / 2], [0.0, 0.0, 1.0]])
    write_cameras_json(ws / "cameras.json", [Camera(CAMERA, width, height, K, np.eye(3, 4))])
    return Workspace(ws)


@pytest.mark.shared_data
def test_cdnet_highway_f_measure_of_the_step_with_a_clean_plate(tmp_path: Path) -> None:
    data = shared_dataset("cdnet_highway")
    first = int((data / "temporalROI.txt").read_text().split()[0])  # 470
    count = len(list((data / "input").glob("in*.jpg")))  # 900: this copy ends before the ROI's
    # Video frame k is CDnet's in{k+1}: the step's indexes are 0-based, CDnet's names 1-based.
    frames = [cv2.imread(str(data / "input" / f"in{i:06d}.jpg")) for i in range(1, count + 1)]
    ws = one_camera_workspace(tmp_path / "ws", frames)
    for index, decoded in read_frames(ws, CAMERA, [0, first - 1, count - 1]):
        assert np.array_equal(decoded, frames[index])  # lossless: the step sees the JPGs
    # The plate: the per-pixel median of the frames before the scored range (a car covers a
    # pixel in fewer than half of them; every one of them shows cars).
    plates = tmp_path / "plates"
    plates.mkdir()
    cv2.imwrite(
        str(plates / f"{CAMERA}.png"),
        np.median(np.stack(frames[: first - 1]), axis=0).astype(np.uint8),
    )
    # Every 5th scored frame (the plate model does not depend on the processed frames).
    config = SilhouettesConfig(background_images=plates, first=first - 1, frame_step=5)
    record = make_silhouettes(ws, config)
    assert record.summary["cameras"][CAMERA]["plate"]["frames"] == 1
    assert not record.summary["multi_view_check"]  # one camera
    roi = cv2.imread(str(data / "ROI.bmp"), cv2.IMREAD_GRAYSCALE)
    counts = Counts()
    for index in range(first - 1, count, 5):
        mask = cv2.imread(str(ws.silhouettes_dir / CAMERA / f"{index:06d}.png"),
                          cv2.IMREAD_GRAYSCALE)  # fmt: skip
        gt = cv2.imread(str(data / "groundtruth" / f"gt{index + 1:06d}.png"),
                        cv2.IMREAD_GRAYSCALE)  # fmt: skip
        counts += confusion_counts(mask > 127, gt, roi)
    assert counts.tp > 100_000  # cars were there to find
    assert counts.f_measure >= 0.95, (counts.precision, counts.recall, counts.f_measure)
