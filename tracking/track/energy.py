"""The silhouette energy of thesis section 6.2.3: XOR pixels between model and image, per view.

"The error metric ... computes a pixel-wise exclusive-or operation between the image
silhouette and the rendered model silhouette in each input camera view. ... The energy
function value is the sum of the non-zero pixels for every camera view after this pixel-wise
boolean operation." Section 6.2.5 adds that the fit "can be applied to lower resolution
versions of the video frames by means of an image pyramid", hence the levels here:

* level 0 is the full resolution; level l halves the size l times (``Camera.scaled``, exact
  pixel-edge scaling of K, so model and image stay aligned at every level);
* the image masks of level l are area-averaged from the full-resolution masks
  (``cv2.INTER_AREA``) and kept where the average is >= 0.5, so a coarse pixel is foreground
  when at least half of it was, and a limb half a coarse pixel wide does not vanish;
* the model is rendered directly at each level's camera (pixel-centre rule of
  :mod:`tracking.track.render`); the energy counts its XOR without drawing it (`XorCount`:
  the image's own count plus +1 or -1 for each pixel the model covers), the same integers;
* the XOR count of level l is multiplied by the area ratio of the level (4**l when the image
  size divides by 2**l), i.e. expressed in full-resolution pixels, so levels are comparable;
* pixels of a view whose label is unknown (``known`` False: the background behind them could
  not be estimated, `tracking.silhouettes.step`) count in no XOR, at any level (a coarse pixel
  is known when at least half of it is).

At level 0 the energy of the pose that produced the masks (with the same renderer) is exactly
0; at coarser levels a residual of a fraction of a coarse pixel per unit of outline remains,
because averaging then thresholding is not the same sampling as rendering at the coarse pixel
centre.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from recon.cameras import Camera
from tracking.body.model import BodyModel, Pose


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks of the same shape (1.0 when both empty)."""
    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"masks differ in shape: {a.shape} and {b.shape}")
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def downsample_mask(mask: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the area average of ``mask`` over each coarse pixel, >= 0.5."""
    coverage = cv2.resize(np.asarray(mask, dtype=np.float32), (width, height),
                          interpolation=cv2.INTER_AREA)
    return coverage >= 0.5


def counted(xor: np.ndarray, known: np.ndarray | None) -> np.ndarray:
    """`xor` where the pixels count: all of it when `known` is None."""
    return xor if known is None else xor & known


def known_iou(a: np.ndarray, b: np.ndarray, known: np.ndarray | None) -> float:
    """`iou` of two masks over the pixels where `known` (all when None)."""
    return iou(a, b) if known is None else iou(a & known, b & known)


class XorCount:
    """XOR pixels, in full-resolution pixels, between image silhouettes and ``static`` (masks
    drawn once: the parts of a body a stage does not move, or None for nothing) with a mesh
    drawn over it, counted without drawing the mesh: the XOR of ``static`` alone plus, over
    the pixels the mesh covers that ``static`` does not, +1 outside the image silhouette and
    -1 inside (`tracking.track.render.covered_gains`); unknown pixels count 0. The same
    integers as counting ``(static | mesh) ^ image`` over the known pixels, plus ``missed``
    (per view, pixels counted as XOR whatever is drawn)."""

    def __init__(self, renderer: Any, cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                 known: Sequence[np.ndarray | None],
                 static: Sequence[np.ndarray] | None = None,
                 missed: Sequence[int] | None = None) -> None:  # fmt: skip
        from tracking.track.render import ViewGains

        self.renderer, self.cameras = renderer, cameras
        statics = static or [None] * len(masks)
        base = []
        # Made in the int8 image they are counted from: a stage makes one of these for every
        # few dozen evaluations, and np.where's int64 temporaries made it 3.49 ms at
        # 640x480, against 0.34 now (session 33).
        self.views = ViewGains(cameras)
        for gain, s, m, k in zip(self.views.gains, statics, masks, known, strict=True):
            m = np.asarray(m, bool)
            base.append(np.count_nonzero(counted(m if s is None else s ^ m, k)))
            gain[...] = 1
            gain[m] = -1
            if s is not None:
                gain[s] = 0
            if k is not None:
                gain[~k] = 0
        # Pixels counted whatever the mesh covers (`SilhouetteEnergy`'s missed), per view.
        self.base = np.array(base) + (0 if missed is None else np.asarray(missed))

    def counts(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(views,) XOR pixel counts (each view's own pixels) with the mesh drawn."""
        from tracking.track.render import covered_gains

        return self.base + covered_gains(self.renderer, vertices, faces, self.views)


class SilhouetteEnergy:
    """XOR energy of a body pose against foreground masks seen by calibrated cameras.

    masks[i] is the (H, W) bool foreground of cameras[i] (same size); known[i], when given and
    not None, the (H, W) bool pixels of that view that count (module docstring). missed[i], when
    given and not None: (H, W) bool pixels of that view counted as XOR whatever the pose (the
    fit does not chase them, and the energy keeps the scale of counting them: the tracker's
    floor band). ``renderer`` is a :class:`plugins.protocols.SilhouetteRenderer` instance or
    the name of one (``"cpu-raster"``, ...). ``evaluations`` counts calls of the energy itself.
    """

    def __init__(self, model: BodyModel, cameras: Sequence[Camera],
                 masks: Sequence[np.ndarray], renderer: Any, levels: int = 3,
                 known: Sequence[np.ndarray | None] | None = None,
                 missed: Sequence[np.ndarray | None] | None = None) -> None:  # fmt: skip
        if len(cameras) != len(masks) or not cameras:
            raise ValueError(f"need one mask per camera, got {len(cameras)} cameras and "
                             f"{len(masks)} masks")
        if levels < 1:
            raise ValueError(f"levels must be >= 1, got {levels}")
        if isinstance(renderer, str):
            from plugins.registry import create

            renderer = create("renderer", renderer)
        self.model = model
        self.renderer = renderer
        self.levels = levels
        self.evaluations = 0
        self.cameras: list[list[Camera]] = []
        """cameras[level][view]."""
        self.masks: list[list[np.ndarray]] = []
        """masks[level][view]: (h, w) bool image silhouettes of that level."""
        self.known: list[list[np.ndarray | None]] = []
        """known[level][view]: (h, w) bool pixels that count, or None for all of them."""
        known = list(known) if known is not None else [None] * len(cameras)
        missed = list(missed) if missed is not None else [None] * len(cameras)
        if len(known) != len(cameras) or len(missed) != len(cameras):
            raise ValueError("need one known and one missed mask (or None) per camera")
        # The missed pixels count apart (`missed`), in none of the views' XOR.
        known = [k if m is None else (~np.asarray(m, bool) if k is None
                                      else np.asarray(k, bool) & ~np.asarray(m, bool))
                 for k, m in zip(known, missed, strict=True)]  # fmt: skip
        self.missed: list[np.ndarray] = []
        """missed[level]: (views,) the missed pixels' count per view, in that level's pixels."""
        self._pixel_area: list[np.ndarray] = []  # full-resolution pixels per pixel, per view
        full = []
        for camera, mask in zip(cameras, masks, strict=True):
            mask = np.asarray(mask, dtype=bool)
            if mask.shape != (camera.height, camera.width):
                raise ValueError(f"mask of camera {camera.name} is {mask.shape}, expected "
                                 f"{(camera.height, camera.width)}")
            full.append(mask)
        for level in range(levels):
            level_cameras = [c.scaled(0.5**level) for c in cameras]
            if min(min(c.width, c.height) for c in level_cameras) < 8:
                raise ValueError(f"level {level} would shrink an image below 8 px; use fewer "
                                 f"levels")
            self.cameras.append(level_cameras)
            self.masks.append([m if level == 0 else downsample_mask(m, c.width, c.height)
                               for m, c in zip(full, level_cameras, strict=True)])
            self.known.append([None if k is None else np.asarray(k, bool) if level == 0
                               else downsample_mask(k, c.width, c.height)
                               for k, c in zip(known, level_cameras, strict=True)])
            self.missed.append(np.array([
                0 if m is None else np.count_nonzero(
                    m if level == 0 else downsample_mask(m, c.width, c.height))
                for m, c in zip(missed, level_cameras, strict=True)], dtype=np.int64))
            self._pixel_area.append(np.array([
                (c0.width * c0.height) / (c.width * c.height)
                for c0, c in zip(cameras, level_cameras, strict=True)]))
        # Per level, the XOR counter of `per_view`, made on its first use (shared by
        # `with_model`'s copies: the masks are the same).
        self._counts: list[XorCount | None] = [None] * levels

    def with_model(self, model: BodyModel) -> SilhouetteEnergy:
        """The same cameras and mask pyramid (shared, not rebuilt) for another body model."""
        other = copy.copy(self)
        other.model, other.evaluations = model, 0
        return other

    def _check_level(self, level: int) -> None:
        if not 0 <= level < self.levels:
            raise ValueError(f"level must be in 0..{self.levels - 1}, got {level}")

    def model_masks(self, pose: Pose, level: int = 0) -> list[np.ndarray]:
        """The model's (h, w) bool silhouette in every view at ``level``."""
        self._check_level(level)
        from tracking.track.render import render_views

        vertices = self.model.posed_vertices(pose)
        return render_views(self.renderer, vertices, self.model.faces, self.cameras[level])

    def xor_masks(self, pose: Pose, level: int = 0) -> list[np.ndarray]:
        """Per view, the (h, w) bool XOR of model and image silhouettes over the known pixels."""
        return [counted(m ^ image, known) for m, image, known in
                zip(self.model_masks(pose, level), self.masks[level], self.known[level],
                    strict=True)]  # fmt: skip

    def per_view(self, pose: Pose, level: int = 0) -> np.ndarray:
        """(views,) XOR pixel counts at ``level``, in full-resolution pixels (`xor_masks`'
        pixels, counted by `XorCount` without drawing the model)."""
        self._check_level(level)
        if self._counts[level] is None:
            self._counts[level] = XorCount(self.renderer, self.cameras[level], self.masks[level],
                                           self.known[level],
                                           missed=self.missed[level])  # fmt: skip
        counts = self._counts[level].counts(self.model.posed_vertices(pose), self.model.faces)
        return counts.astype(float) * self._pixel_area[level]

    def __call__(self, pose: Pose, level: int = 0) -> float:
        """Sum over views of the XOR pixel count at ``level``, in full-resolution pixels."""
        self.evaluations += 1
        return float(self.per_view(pose, level).sum())
