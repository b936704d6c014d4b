"""Synthetic videos of a `mocap synth` sequence, and the scores of a capture against its truth.

`mocap synth --videos` renders, beside the silhouettes, what a camera rig would have filmed::

    WS/render/videos/<camera>.avi        MJPG, frame k of the video = frame k of the sequence
    WS/render/backgrounds/<camera>.png   the empty scene as that camera sees it (a photo taken
                                         before the subject walked in)

Each camera looks at a static textured scene of its own (blurred colour noise over a
horizontal ramp, grey levels about 80-160 in every channel); the subject is its exact
silhouette (the renderer's mask, without the silhouette noise of `mocap synth`) painted in a
saturated red cloth, with a fixed, mildly textured pattern. The colours are far enough apart
(the cloth's red channel typically 90 grey levels above the scene's, its blue one 80
below) that the thesis' background subtraction with its default thresholds finds the
subject; it errs at the edges, where MJPG blurs the two together, and in the narrow gaps
between the limbs and the trunk, which its clean-up closes.

These are the inputs of `mocap init-video` and `mocap capture`: ``--videos WS/render/videos
--calibration WS/cameras.json --background-images WS/render/backgrounds``. The truth to score
the capture against stays in the synth workspace: ``gt/joints.csv`` for the joints and, with
``--clean``, ``silhouettes/`` for the masks (`capture_scores`).
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from recon.errors import UserError

RENDER_DIR = "render"
"""``WS/render/``: the synthetic videos and background photos of a synth workspace."""
VIDEO_SUFFIX = ".avi"
_CLOTH_BGR = (40.0, 45.0, 235.0)


def scene_background(width: int, height: int, seed: int) -> np.ndarray:
    """(H, W, 3) uint8 BGR: a static textured scene, blurred colour noise (sigma 2 px) over a
    left-to-right ramp, grey levels about 80-160 in every channel."""
    rng = np.random.default_rng([seed, 1])
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (height, width, 3)).astype(np.float32),
                             (0, 0), 2.0)
    ramp = np.linspace(0, 40, width, dtype=np.float32)[None, :, None]
    return np.clip(100 + 0.6 * (noise - 127.5) + ramp, 0, 255).astype(np.uint8)


def cloth_texture(width: int, height: int, seed: int) -> np.ndarray:
    """(H, W, 3) uint8 BGR: the subject's red cloth, blurred noise of 6 grey levels RMS."""
    rng = np.random.default_rng([seed, 2])
    noise = cv2.GaussianBlur(rng.normal(0, 1, (height, width)).astype(np.float32), (0, 0), 3.0)
    noise *= 6.0 / max(float(noise.std()), 1e-6)
    return np.clip(np.asarray(_CLOTH_BGR, np.float32) + noise[..., None], 0, 255).astype(np.uint8)


def composite(background: np.ndarray, subject: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The frame a camera films: ``subject`` (H, W, 3) where ``mask`` (H, W) bool, else the
    ``background`` (H, W, 3)."""
    return np.where(mask[..., None], subject, background)


class SyntheticVideos:
    """Writes ``folder/videos/<camera>.avi`` and ``folder/backgrounds/<camera>.png`` while a
    sequence is rendered: a context manager whose `add` takes each view's exact mask, frame by
    frame; leaving it closes the videos. ``folder`` is created (it is the partial output of the
    synth step, renamed into place with the rest of the step's outputs)."""

    def __init__(self, folder: Path, cameras: Sequence[Any], frame_rate: float,
                 seed: int) -> None:  # fmt: skip
        self.folder, self.cameras, self.frame_rate = Path(folder), list(cameras), frame_rate
        self.backgrounds = [scene_background(c.width, c.height, seed + 17 * k)
                            for k, c in enumerate(self.cameras)]
        self.cloth = [cloth_texture(c.width, c.height, seed + 17 * k)
                      for k, c in enumerate(self.cameras)]
        self._writers: list[cv2.VideoWriter] = []
        self.frames = 0

    def __enter__(self) -> SyntheticVideos:
        (self.folder / "videos").mkdir(parents=True)
        (self.folder / "backgrounds").mkdir()
        for camera, background in zip(self.cameras, self.backgrounds, strict=True):
            path = self.folder / "backgrounds" / f"{camera.name}.png"
            if not cv2.imwrite(str(path), background):
                raise UserError(f"could not write {path}")
            video = self.folder / "videos" / f"{camera.name}{VIDEO_SUFFIX}"
            writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"),
                                     self.frame_rate, (camera.width, camera.height))
            if not writer.isOpened():
                raise UserError(f"OpenCV cannot write MJPG video {video} here")
            writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
            self._writers.append(writer)
        return self

    def add(self, view: int, mask: np.ndarray) -> None:
        """The next frame of camera ``view`` (index into the cameras), from its exact mask."""
        self._writers[view].write(composite(self.backgrounds[view], self.cloth[view], mask))
        if view == len(self.cameras) - 1:
            self.frames += 1

    def __exit__(self, *exc: object) -> None:
        for writer in self._writers:
            writer.release()

    def summary(self) -> dict[str, Any]:
        return {"videos": f"{RENDER_DIR}/videos", "backgrounds": f"{RENDER_DIR}/backgrounds",
                "format": f"MJPG {VIDEO_SUFFIX}", "frames": self.frames}


# ---------------------------------------------------------------------------------------------
# Scores of a capture against the truth of a synth workspace


@dataclass(frozen=True)
class CaptureScores:
    """A capture of a synthetic sequence against its truth."""

    mpjpe_mm: float
    """Mean distance of the tracked joints to the true ones (world frame), over the frames
    both have, in millimetres."""
    max_joint_error_mm: float
    frames_scored: int
    silhouette_iou: float | None
    """Mean IoU of the capture's silhouettes with the exact renders (None: the synth
    workspace's silhouettes are noisy, not the truth)."""
    min_silhouette_iou: float | None

    def lines(self) -> list[str]:
        text = [f"truth       MPJPE {self.mpjpe_mm:.1f} mm over {self.frames_scored} frames "
                f"(worst joint {self.max_joint_error_mm:.1f} mm)"]
        if self.silhouette_iou is not None:
            text.append(f"            silhouette IoU {self.silhouette_iou:.3f} with the exact "
                        f"renders (mean; min {self.min_silhouette_iou:.3f})")
        return text

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def read_joints_csv(path: Path) -> dict[tuple[int, str], np.ndarray]:
    """(frame, joint) -> (3,) position of a ``frame,joint,x,y,z`` file (gt/ or tracks/)."""
    if not path.is_file():
        raise UserError(f"{path} not found")
    with path.open(newline="") as handle:
        return {(int(r["frame"]), r["joint"]): np.array([float(r[k]) for k in "xyz"])
                for r in csv.DictReader(handle)}  # fmt: skip


def _masks_iou(a: Path, b: Path) -> float:
    x, y = (cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in (a, b))
    if x is None or y is None:
        raise UserError(f"cannot read {a if x is None else b}")
    x, y = x > 127, y > 127
    union = np.count_nonzero(x | y)
    return float(np.count_nonzero(x & y) / union) if union else 1.0


def capture_scores(capture_root: Path | str, truth_root: Path | str) -> CaptureScores:
    """Scores of the capture workspace ``capture_root`` (tracked from the videos of the synth
    workspace ``truth_root``): joint errors of ``tracks/joints.csv`` against ``gt/joints.csv``,
    and, when the synth run was ``--clean`` (its silhouettes are the exact renders), the IoU of
    every silhouette of the capture with the render of the same camera and frame."""
    from recon.workspace import Workspace

    capture_root, truth_root = Path(capture_root), Path(truth_root)
    tracked = read_joints_csv(capture_root / "tracks" / "joints.csv")
    truth = read_joints_csv(truth_root / "gt" / "joints.csv")
    common = sorted(set(tracked) & set(truth))
    if not common:
        raise UserError(f"{capture_root}/tracks/joints.csv has no frame of "
                        f"{truth_root}/gt/joints.csv")
    errors = np.array([np.linalg.norm(tracked[key] - truth[key]) for key in common])
    synth = Workspace(truth_root).step("synth")
    clean = synth is not None and bool(synth.config.get("clean"))
    ious: list[float] = []
    if clean:
        for folder in sorted(p for p in (capture_root / "silhouettes").iterdir() if p.is_dir()):
            for mask in sorted(folder.glob("[0-9]*.png")):
                exact = truth_root / "silhouettes" / folder.name / mask.name
                if exact.is_file():
                    ious.append(_masks_iou(mask, exact))
    return CaptureScores(
        mpjpe_mm=1000 * float(errors.mean()), max_joint_error_mm=1000 * float(errors.max()),
        frames_scored=len({frame for frame, _ in common}),
        silhouette_iou=float(np.mean(ious)) if ious else None,
        min_silhouette_iou=float(np.min(ious)) if ious else None)
