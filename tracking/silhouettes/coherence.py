"""Refining a rig's calibration from its silhouettes: silhouette coherence.

A rig is calibrated once (a wand, a board), then cameras move: a camera turned by a third of a
degree moves its image by 10 pixels at 1,700 px focal length, about 2 cm on a subject 3 m
away, more than a forearm's error. The silhouettes of every frame tell: where the views
disagree, the visual hull of all of them (`tracking.silhouettes.hull`) is carved thinner than
each silhouette. The *silhouette coherence* of a rig (Hernandez, Schmitt and Cipolla,
"Silhouette coherence for camera calibration under circular motion", PAMI 2007) is how much
of each silhouette the projection of the hull of all of them fills; we take it as the share
of the views' silhouette pixels (pooled, over the pixels whose label a view can tell) that the
hull's projection covers, which is the IoU of the two in each view (the hull's projection lies
within the silhouette).

The correction is an image shift per camera (dx, dy), in pixels, applied to the principal
point: to first order what a small turn of the camera about its centre does to a subject near
the middle of the image (a 10 px shift at the image's edge is a 0.1 px different turn). It
leaves the cameras' positions, focal lengths and distortion as calibrated. A shift of every
view that a 3D translation of the subject explains changes nothing: a small penalty on the
shifts (`_PENALTY_PER_PX2`) picks the least correction among those, and the part of the
calibration's error that such a move explains stays: the subject as a whole may then sit a
centimetre from where the calibration's world has it (`benchmarks/camera_correction.py`, two
cameras 7-12 px off: the capture moved by 11 mm, its joints right within 9 mm of each other
against 43 mm uncorrected).

The search (`refine_rig`): steepest coordinate ascent, the best move of one camera along one
axis at a time, in steps of 8, 4, 2 and 1 pixels, on some frames spread over the sequence. The
coherence is measured on rays through the silhouettes' pixels (`_Frame`), whose samples are
projected once per frame, so a shift only moves them. The correction is then checked on other
frames, and kept only when it makes them more coherent by ``coherence_min_gain``: a
calibration that is right stays as it is.

On the Pose2Sim demo (portrait 1080x1920, Qualisys calibration), the four views' hull fills
cam01 and cam02 least (IoU 0.81 against 0.88 and 0.90 for cam03 and cam04), and the tracked
body shows the same in every frame: drawn in cam01 it sits 10 px left of the person, in cam03
10 px left and 12 px up. `mocap silhouettes` finds cam01 (+12, -3), cam02 (-1, -8), cam03 (+10,
+8) and cam04 (+1, -8) px from 3 frames (coherence of 3 others 0.878 -> 0.931; the common
vertical part is a move of the subject); the exact hull of 5 frames (1 cm voxels), no body
model involved, then fills the views better: median IoU 0.867 -> 0.903. On an exact rig the
correction is 0 (tests).

Pure numpy and OpenCV; no I/O.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from recon.cameras import Camera
from tracking.silhouettes.hull import Box, _with_unknown, rays_meeting_point

_PENALTY_PER_PX2 = 1e-5
"""Coherence traded for one squared pixel of correction: 10 px cost 0.001, a tenth
of what the Pose2Sim demo's corrections gain."""

_STEPS_PX = (8.0, 4.0, 2.0, 1.0)
"""The steps of the coordinate descent, pixels."""


@dataclass(frozen=True)
class CoherenceConfig:
    """Settings of `refine_rig`. Field help is the CLI's help."""

    refine_cameras: bool = field(
        default=True,
        metadata={"help": "correct each camera's calibration by the image shift that makes the "
                  "views' silhouettes agree best (silhouette coherence), when other frames "
                  "confirm it; silhouettes/cameras.json has the cameras used from then on"},
    )  # fmt: skip
    coherence_frames: int = field(
        default=6,
        metadata={"help": "frames spread over the sequence for the correction: every other one "
                  "fits it, the rest check it"},
    )  # fmt: skip
    coherence_max_shift_px: float = field(
        default=24.0, metadata={"help": "largest correction of a camera, pixels per axis"}
    )
    coherence_min_gain: float = field(
        default=0.005,
        metadata={"help": "keep the correction only when it raises the checking frames' "
                  "coherence (the share of the silhouettes' pixels under the projection of "
                  "the hull of all views) by this much"},
    )  # fmt: skip

    def __post_init__(self) -> None:
        from recon.errors import UserError

        if self.coherence_frames < 2:
            raise UserError(f"--coherence-frames must be >= 2, got {self.coherence_frames}")
        if not self.coherence_max_shift_px > 0:
            raise UserError(f"--coherence-max-shift-px must be > 0, got "
                            f"{self.coherence_max_shift_px}")  # fmt: skip


_CUBE_M = 2.4
"""Side of the coherence hulls' cube, metres, centred where the silhouettes' rays meet: a
standing or reaching person (the hull-based start's)."""


@dataclass(frozen=True)
class CoherenceResult:
    """What `refine_rig` found. cameras: the refined cameras when ``accepted``, else the given
    ones; shifts_px: (C, 2) the correction found (applied or not); fitted / checked: the
    coherence of the fitting and checking frames, before and after."""

    cameras: list[Camera]
    shifts_px: np.ndarray
    fitted: tuple[float, float]
    checked: tuple[float, float]
    accepted: bool

    def summary(self) -> dict[str, object]:
        return {
            "accepted": self.accepted,
            "shifts_px": {c.name: [round(float(v), 1) for v in s]
                          for c, s in zip(self.cameras, self.shifts_px, strict=True)},
            "coherence_fitted": [round(v, 4) for v in self.fitted],
            "coherence_checked": [round(v, 4) for v in self.checked],
        }  # fmt: skip


def shifted(camera: Camera, shift_px: Sequence[float]) -> Camera:
    """`camera` with its principal point moved by (dx, dy) pixels."""
    K = np.array(camera.K, dtype=float)
    K[0, 2] += shift_px[0]
    K[1, 2] += shift_px[1]
    return dataclasses.replace(camera, K=K)


_RAYS_PER_VIEW = 1200
"""Rays sampled per view and frame, on a regular grid of its (dilated) silhouette's pixels."""

_RAY_STEP_M = 0.02
"""Spacing of the samples along a ray, metres (a forearm is 6-8 cm across)."""

_RAY_REACH_M = 1.0
"""The samples span this far on either side of where the silhouettes' rays meet, metres."""


_CACHED = 600
"""Cone tests a frame keeps (one per pair of views and shift tried; ~100 kB each)."""


class _Frame:
    """One frame's silhouettes and, per view, rays through a grid of its silhouette's pixels
    (dilated by ``coherence_max_shift_px``), sampled in depth around the subject and projected
    once into every other view; a correction only moves those projections.

    A pixel of view i is under the projection of the exact visual hull of all the views when
    its ray meets the other views' silhouette cones at one point (it is in view i's cone by
    construction), so a view's coherence is the share of its silhouette's rays that do: the
    IoU of the silhouette and the hull's projection, which lies within the silhouette. Exact up
    to the sampling, with no voxels: at 2 cm voxels the coherence of an exact rig peaked 2 px
    off it."""

    def __init__(self, cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                 unknown: Sequence[np.ndarray | None], boxes: Sequence[Box | None],
                 config: CoherenceConfig) -> None:  # fmt: skip
        self.boxes = [b if b is not None else (0, 0, c.width, c.height)
                      for b, c in zip(boxes, cameras, strict=True)]  # fmt: skip
        self.masks = [np.asarray(m, bool) for m in masks]
        self.carving = _with_unknown(self.masks, unknown)
        self.views = [k for k, m in enumerate(self.masks) if m.any()]
        self.pixels: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.uv: dict[tuple[int, int], np.ndarray] = {}
        self.front: dict[tuple[int, int], np.ndarray] = {}
        self._inside: dict[tuple[int, int, tuple[int, int]], np.ndarray] = {}
        if len(self.views) < 2:  # nothing to agree on (`coverage` is (0, 0))
            return
        centre = rays_meeting_point([cameras[k] for k in self.views],
                                    [self.carving[k] for k in self.views])
        margin = int(np.ceil(config.coherence_max_shift_px)) + 1
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
        for i in self.views:
            cam = cameras[i]
            near = cv2.dilate(self.masks[i].astype(np.uint8), disc).astype(bool)
            stride = max(1, int(np.ceil(np.sqrt(near.sum() / _RAYS_PER_VIEW))))
            grid = np.zeros_like(near)
            grid[::stride, ::stride] = True
            rows, cols = np.nonzero(near & grid)
            known = np.ones(len(rows), bool) if unknown[i] is None else ~unknown[i][rows, cols]
            self.pixels[i] = (rows, cols, known)
            xy = (np.column_stack([cols + 0.5, rows + 0.5]) - cam.K[:2, 2]) / np.diag(cam.K)[:2]
            xy[:, 0] -= cam.K[0, 1] * xy[:, 1] / cam.K[0, 0]
            if cam.has_distortion:
                xy = cam.undistort(xy)
            rays = np.column_stack([xy, np.ones(len(xy))]) @ cam.R  # world directions, z = 1
            depth = float((cam.R @ centre + cam.t)[2])
            z = np.arange(max(depth - _RAY_REACH_M, 0.1), depth + _RAY_REACH_M, _RAY_STEP_M)
            points = cam.center_in_world + rays[:, None, :] * z[None, :, None]
            for j in self.views:
                if j != i:
                    uv, d = cameras[j].project(points.reshape(-1, 3))
                    shape = points.shape[:2]
                    self.uv[i, j] = uv.reshape(*shape, 2).astype(np.float32)
                    self.front[i, j] = (d > 0).reshape(shape)

    def _in_cone(self, i: int, j: int, shift: tuple[int, int]) -> np.ndarray:
        """(rays, samples) bool: the samples of view i's rays inside view j's silhouette cone
        (or unseen by view j, which does not carve them), view j's image moved by shift."""
        cached = self._inside.get((i, j, shift))
        if cached is not None:
            return cached
        if len(self._inside) > _CACHED:
            self._inside.clear()
        x0, y0, x1, y1 = self.boxes[j]
        col = np.floor(self.uv[i, j][..., 0] + shift[0])
        row = np.floor(self.uv[i, j][..., 1] + shift[1])
        with np.errstate(invalid="ignore"):
            seen = self.front[i, j] & (col >= x0) & (col < x1) & (row >= y0) & (row < y1)
        inside = ~seen
        inside[seen] = self.carving[j][row[seen].astype(np.int64), col[seen].astype(np.int64)]
        self._inside[i, j, shift] = inside
        return inside

    def coverage(self, shifts_px: np.ndarray) -> tuple[int, int]:
        """(covered, total): the views' silhouette pixels (sampled, known) under the
        projection of the exact visual hull, and all of them, with each view's image moved by
        its shift; (0, 0) with fewer than two views."""
        if len(self.views) < 2:
            return 0, 0
        shifts = [(int(round(x)), int(round(y))) for x, y in shifts_px]
        covered = total = 0
        for i in self.views:
            rows, cols, known = self.pixels[i]
            r, c = rows + shifts[i][1], cols + shifts[i][0]
            mask = self.masks[i]
            inside = (r >= 0) & (r < mask.shape[0]) & (c >= 0) & (c < mask.shape[1])
            silhouette = np.zeros(len(rows), bool)
            silhouette[inside] = mask[r[inside], c[inside]]
            silhouette &= known
            meets = np.ones(len(rows), bool)[:, None]
            for j in self.views:
                if j != i:
                    meets = meets & self._in_cone(i, j, shifts[j])
            covered += np.count_nonzero(silhouette & meets.any(axis=1))
            total += np.count_nonzero(silhouette)
        return covered, total


def coherence(frames: Sequence[_Frame], shifts_px: np.ndarray) -> float:
    """The share of the frames' silhouette pixels (pooled over views and frames: a view that
    shows a sliver of the subject weighs a sliver) under the projection of their exact visual
    hulls (`_Frame.coverage`); 0 when no view has two others."""
    counts = np.array([f.coverage(shifts_px) for f in frames]).sum(axis=0)
    return float(counts[0] / counts[1]) if counts[1] else 0.0


def _score(frames: Sequence[_Frame], shifts_px: np.ndarray) -> float:
    return coherence(frames, shifts_px) - _PENALTY_PER_PX2 * float(np.sum(shifts_px**2))


def refine_rig(cameras: Sequence[Camera], masks: Sequence[Sequence[np.ndarray]],
               unknown: Sequence[np.ndarray | None] | None = None,
               config: CoherenceConfig | None = None,
               boxes: Sequence[Box | None] | None = None) -> CoherenceResult:  # fmt: skip
    """Per-camera image shifts that make the silhouettes coherent (module docstring).

    masks: per frame, per camera (H, W) bool silhouettes (at least 2 frames: the even ones fit
    the correction, the odd ones check it); unknown: per camera, None or the pixels whose
    label the view cannot tell; boxes: per camera, None or the (x0, y0, x1, y1) pixels that
    hold the image (`tracking.rig.video.content_box`)."""
    config = config or CoherenceConfig()
    cameras = list(cameras)
    unknown = list(unknown) if unknown is not None else [None] * len(cameras)
    boxes = list(boxes) if boxes is not None else [None] * len(cameras)
    frames = [_Frame(cameras, m, unknown, boxes, config) for m in masks]
    fit, check = frames[0::2], frames[1::2] or frames[0::2]
    shifts = np.zeros((len(cameras), 2))
    start = best = _score(fit, shifts)
    for step in _STEPS_PX:
        while True:  # the best of the moves of one camera along one axis, while one gains
            moves = []
            for k in range(len(cameras)):
                for axis in range(2):
                    for sign in (1.0, -1.0):
                        trial = shifts.copy()
                        trial[k, axis] += sign * step
                        if abs(trial[k, axis]) <= config.coherence_max_shift_px:
                            moves.append((_score(fit, trial), trial))
            score, trial = max(moves, key=lambda move: move[0])
            if score <= best + 1e-5:
                break
            shifts, best = trial, score
    fitted = (start, coherence(fit, shifts))
    checked = (coherence(check, np.zeros_like(shifts)), coherence(check, shifts))
    accepted = bool(checked[1] - checked[0] >= config.coherence_min_gain)
    refined = [shifted(c, s) for c, s in zip(cameras, shifts, strict=True)] if accepted \
        else cameras  # fmt: skip
    return CoherenceResult(refined, shifts, fitted, checked, accepted)  # type: ignore[arg-type]
