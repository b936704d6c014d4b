"""Silhouettes by per-pixel background subtraction with a shadow test, thesis section 6.2.1.

The thesis (after Carranza et al.): "From a sequence of video frames without a moving subject,
the mean and standard deviation of each background pixel in each color channel are computed.
If a pixel differs in at least one color channel by more than an upper threshold from the
background distribution, it is classified as certainly belonging to the foreground. If its
difference from the background is smaller than a lower threshold in all channels, the pixel is
classified as certainly background. All other pixels are considered potential shadow pixels."
Where no empty-background footage exists, "for each pixel, one could compute the median
intensity value over time and consider this to be the background"; the silhouette is then
cleaned by "morphological dilate and erode operations".

Here:

* `BackgroundModel` holds the per-pixel mean and standard deviation, (H, W, C) float32, either
  from empty-background frames (`from_frames`: mean and standard deviation) or from a sequence
  with moving objects (`from_sequence`: temporal median and median absolute deviation x 1.4826,
  which equals the standard deviation for Gaussian noise and ignores objects that cover a pixel
  in fewer than half of the frames; then again over the frames where a pixel is not
  foreground, for subjects that stay put). Whatever its source, the silhouettes step
  (`tracking.silhouettes.step`), the CDnet benchmark and the tests use these two.
* `classify` labels each pixel `Label.BACKGROUND` (0), `Label.SHADOW` (1) or `Label.FOREGROUND`
  (2), per pixel and without clean-up. Differences are z-scores, (frame - mean) / std, with the
  std floored at `SilhouetteConfig.min_std` so that flat, noiseless regions (a wall, a clipped
  sky) do not turn every JPEG ripple into foreground.
* `foreground_mask` turns labels into the cleaned silhouette, (H, W) bool, shadow counted as
  background: opening, closing, hole filling and removal of small components.
* `silhouette_from_frame` is the two in one, then `refined_outline`: the (H, W) bool silhouette
  the tracker compares with projected model silhouettes. The lower threshold calls a pixel
  foreground as soon as a bright subject covers a sixth of it, and codec blur spreads the
  subject's colour a pixel or two out, so the outline comes out too large all round; in a
  band of ``edge_band_px`` round it each pixel goes to the nearer of the background and the
  subject's local colour, which splits it at half the contrast.
* `f_measure` / `confusion_counts` score a silhouette against a CDnet ground-truth image.

Shadow test (the thesis names shadow candidates but not the test): the brightness distortion
of Horprasert, Harwood and Davis (ICCV FRAME-RATE workshop, 1999), alpha = argmin_a
sum_c ((I_c - a E_c) / s_c)^2, scales the background colour E to best explain the pixel I; a
cast shadow dims the light but keeps the surface colour, so it has alpha in
[shadow_min_brightness, shadow_max_brightness] and a small angle between the colour vectors I
and E. The angle, unlike Horprasert's noise-normalised chromaticity distortion, does not grow
more tolerant where the background is noisy; with the latter, grey cars on CDnet's highway
passed as shadows. Only the thesis' candidates (between the two thresholds) are tested, so
`upper_sigma` also bounds how deep a shadow can be, in standard deviations.

Defaults were set on CDnet 2012 highway (benchmarks/silhouettes_cdnet.py, F 0.95) and kept at
round, generic values rather than that sequence's optimum: `min_std` 6 grey levels (4 lets
JPEG ripples through: F 0.71; 6 and 8 give 0.94-0.96), thresholds 3 and 10 sigma, shadows
50-95% of the background's brightness within 2 degrees of its colour. Highway's own cast
shadows are far darker (median 14% of the road's brightness) and are not caught: the shadow
test costs that sequence about 0.015 of F (dark grey car pixels pass it), a price paid for
soft indoor shadows, which it removes.

Images are (H, W, 3) uint8 BGR, OpenCV's order (any channel order works: the test treats the
channels alike), or (H, W) grey, which is treated as (H, W, 1).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

# MAD x 1.4826 is the standard deviation of a normal distribution (1 / Phi^-1(3/4)).
_MAD_TO_STD = 1.4826


class Label(enum.IntEnum):
    """Values of the label image returned by `classify`."""

    BACKGROUND = 0
    SHADOW = 1
    FOREGROUND = 2


# ---------------------------------------------------------------------------------------------
# Background model
# ---------------------------------------------------------------------------------------------


def _as_hwc(frame: np.ndarray, what: str) -> np.ndarray:
    """(H, W, C) view of an (H, W) or (H, W, C) image; ValueError on anything else or NaN."""
    frame = np.asarray(frame)
    if frame.ndim == 2:
        frame = frame[:, :, None]
    if frame.ndim != 3 or frame.shape[0] == 0 or frame.shape[1] == 0:
        raise ValueError(f"{what} has shape {frame.shape}: expected (H, W) or (H, W, C)")
    if not np.issubdtype(frame.dtype, np.number) or np.issubdtype(frame.dtype, np.complexfloating):
        raise ValueError(f"{what} has dtype {frame.dtype}: expected a real-valued image")
    if np.issubdtype(frame.dtype, np.floating) and not np.isfinite(frame).all():
        raise ValueError(f"{what} contains NaN or infinite values")
    return frame


def _checked_frames(frames: Iterable[np.ndarray]) -> list[np.ndarray]:
    """The frames as (H, W, C) arrays, all of one size; ValueError on none, mixed sizes, NaN."""
    checked: list[np.ndarray] = []
    for i, frame in enumerate(frames):
        frame = _as_hwc(frame, f"frame {i}")
        if checked and frame.shape != checked[0].shape:
            raise ValueError(
                f"frame {i} is {frame.shape}, frame 0 is {checked[0].shape}: "
                "all frames must have the same size"
            )
        checked.append(frame)
    if not checked:
        raise ValueError("no frames given: the background model needs at least one frame")
    return checked


PHOTO_MISALIGNMENT_PX = 0.5
"""`BackgroundModel.from_photo`: how far, in pixels, a video frame's edges may sit from the
photo's (half a pixel: sub-pixel vibration, and the video's resampling and compression)."""

# Immerkaer's noise estimator: the difference of two Laplacians cancels image structure up to
# second order; white Gaussian noise of sigma s gives a response of standard deviation 6 s.
_IMMERKAER = np.float32([[1, -2, 1], [-2, 4, -2], [1, -2, 1]])


def noise_sigma(image: np.ndarray) -> np.ndarray:
    """Per channel, the standard deviation of an image's noise (C,) float: J. Immerkaer, "Fast
    noise variance estimation", CVIU 64(2), 1996 (sigma = sqrt(pi / 2) / 6 x the mean absolute
    response of the kernel), over the flatter half of the image (the pixels whose Sobel
    gradient is at most its median, after Tai and Yang, 2008), so that edges and texture count
    less."""
    image = _as_hwc(image, "image").astype(np.float32)
    out = np.empty(image.shape[2])
    for c in range(image.shape[2]):
        plane = image[..., c]
        response = np.abs(cv2.filter2D(plane, cv2.CV_32F, _IMMERKAER)[1:-1, 1:-1])
        gradient = (np.abs(cv2.Sobel(plane, cv2.CV_32F, 1, 0, ksize=3))
                    + np.abs(cv2.Sobel(plane, cv2.CV_32F, 0, 1, ksize=3)))[1:-1, 1:-1]
        flat = gradient <= np.median(gradient)
        out[c] = float(np.mean(response[flat])) * math.sqrt(math.pi / 2) / 6.0
    return out


@dataclass(frozen=True)
class BackgroundModel:
    """Per-pixel colour distribution of the empty scene.

    mean: (H, W, C) float32, the background colour in the frames' channel order and units.
    std: (H, W, C) float32, its per-pixel standard deviation (not floored; the floor is a
    classification setting, `SilhouetteConfig.min_std`).
    """

    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        mean = _as_hwc(self.mean, "background mean")
        std = _as_hwc(self.std, "background std")
        if mean.shape != std.shape:
            raise ValueError(f"background mean is {mean.shape} but std is {std.shape}")
        if (std < 0).any():
            raise ValueError("background std has negative values")
        object.__setattr__(self, "mean", mean.astype(np.float32, copy=False))
        object.__setattr__(self, "std", std.astype(np.float32, copy=False))

    @property
    def shape(self) -> tuple[int, int, int]:
        """(H, W, C) of the frames this model classifies."""
        h, w, c = self.mean.shape
        return h, w, c

    @classmethod
    def from_frames(cls, frames: Iterable[np.ndarray]) -> BackgroundModel:
        """Mean and standard deviation of frames that show only the background (the thesis).

        frames: N >= 1 images, each (H, W, C) or (H, W). One frame gives std 0 everywhere,
        which the classification's `min_std` floor turns into a fixed grey-level threshold
        (`from_photo` estimates a spread from one photo instead).
        """
        checked = _checked_frames(frames)
        # Sums in float64: a float32 sum of squares over hundreds of 8-bit frames loses the
        # few grey levels of variance we are after.
        total = np.zeros(checked[0].shape, np.float64)
        total_sq = np.zeros(checked[0].shape, np.float64)
        for frame in checked:
            f = frame.astype(np.float64)
            total += f
            total_sq += f * f
        n = len(checked)
        mean = total / n
        var = np.maximum(total_sq / n - mean * mean, 0.0)
        return cls(mean.astype(np.float32), np.sqrt(var).astype(np.float32))

    @classmethod
    def from_photo(cls, photo: np.ndarray, *, misalignment_px: float = PHOTO_MISALIGNMENT_PX
                   ) -> BackgroundModel:  # fmt: skip
        """The background of a single photo of the empty scene: its colours, and a spread
        that one photo cannot measure, from a noise model: per channel, the image noise
        (`noise_sigma`, one value over the image) combined with the change that a shift of
        ``misalignment_px`` pixels makes at each pixel (that many times its gradient), so that
        edges, where a video frame and a photo differ most (demosaicing, compression,
        vibration), are not foreground.
        """
        image = _as_hwc(photo, "photo").astype(np.float32)
        sigma = noise_sigma(image)
        spread = np.empty_like(image)
        for c in range(image.shape[2]):
            gx = cv2.Sobel(image[..., c], cv2.CV_32F, 1, 0, ksize=3) / 8.0
            gy = cv2.Sobel(image[..., c], cv2.CV_32F, 0, 1, ksize=3) / 8.0
            spread[..., c] = np.sqrt(sigma[c] ** 2 + misalignment_px**2 * (gx * gx + gy * gy))
        return cls(image, spread)

    @classmethod
    def from_sequence(cls, frames: Sequence[np.ndarray], thresholds: SilhouetteConfig | None = None,
                      *, passes: int = 2) -> BackgroundModel:  # fmt: skip
        """Background of a sequence in which the subject moves and no frame shows the empty
        scene: per pixel, the temporal median and the spread around it (1.4826 MAD).

        frames: N >= 1 uint8 images, each (H, W, C) or (H, W), all held at once (pick a few
        spread over the sequence: `tracking.silhouettes.step.background_sample`); an odd N
        takes the fast path below. A first pass takes every frame: right wherever the subject
        covers a pixel in fewer than half of them, and a MAD that a passing object does not
        inflate the way it inflates a standard deviation. Where the subject stands in many of
        the frames, that median is partly the subject and its spread is inflated by the
        subject's motion, so the silhouettes miss what stands still. Each further pass
        (`passes` in all) classifies the frames against the model so far (`thresholds`) and
        takes the median and spread over the frames where the pixel is background, the
        silhouettes dilated by a margin of 1% of the image's larger side; a pixel with fewer
        than a quarter of the frames free keeps its previous value. (CDnet highway, 21 frames
        before the scored range: F 0.945 with one pass, 0.952 with two.)
        """
        if passes < 1:
            raise ValueError(f"passes must be >= 1, got {passes}")
        checked = _checked_frames(frames)
        if any(frame.dtype != np.uint8 for frame in checked):
            raise ValueError("the temporal median background needs uint8 frames")
        n, (h, w, _) = len(checked), checked[0].shape
        if n % 2:
            # An odd-even transposition sort across frames with element-wise min/max: exactly
            # np.median in a third of its time, and in 8 bits.
            median = _middle([np.array(f) for f in checked])
            mad = _middle([cv2.absdiff(f, median) for f in checked])
            model = cls(median.astype(np.float32),
                        (_MAD_TO_STD * mad.astype(np.float32)).astype(np.float32))
        else:  # the mean of the two middle values, which 8 bits do not hold
            model = _free_median(checked, np.ones((n, h, w), bool), None)
        thresholds = thresholds or SilhouetteConfig()
        margin = np.ones((max(3, round(0.01 * max(h, w))),) * 2, np.uint8)
        for _ in range(passes - 1):
            free = np.stack([cv2.dilate(silhouette_from_frame(f, model, thresholds)
                                        .astype(np.uint8), margin) == 0
                             for f in checked])  # fmt: skip
            model = _free_median(checked, free, model)
        return model


def _middle(arrays: list[np.ndarray]) -> np.ndarray:
    """Element-wise median of an odd number of equal-shape arrays (sorts them in place)."""
    n = len(arrays)
    for rnd in range(n):
        for j in range(rnd % 2, n - 1, 2):
            low = np.minimum(arrays[j], arrays[j + 1])
            np.maximum(arrays[j], arrays[j + 1], out=arrays[j + 1])
            arrays[j] = low
    return arrays[n // 2]


def _free_median(frames: list[np.ndarray], free: np.ndarray, previous: BackgroundModel | None
                 ) -> BackgroundModel:  # fmt: skip
    """Per pixel and channel, median and 1.4826 MAD over the (H, W, C) uint8 frames where
    `free` (N, H, W); the `previous` model where fewer than a quarter of the frames are free
    (None: `free` must leave enough everywhere). Row blocks bound the memory (a 16-bit copy of
    the frames of a block)."""
    n, h, w = free.shape
    c = frames[0].shape[2]
    count = free.sum(axis=0)
    enough = count >= max(1, n // 4)
    if previous is None:
        if not enough.all():
            raise ValueError("without a previous model every pixel needs enough free frames")
        mean, std = np.zeros((h, w, c), np.float32), np.zeros((h, w, c), np.float32)
    else:
        mean, std = previous.mean.copy(), previous.std.copy()
    invalid = np.uint16(65535)  # sorts after every 8-bit value
    rows = max(1, (1 << 24) // (n * w * c))
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        block = np.stack([f[r0:r1] for f in frames]).astype(np.uint16)  # (N, r, W, C)
        block[~free[:, r0:r1]] = invalid
        block.sort(axis=0)
        k = count[r0:r1]
        lo = np.maximum((k - 1) // 2, 0)[None, :, :, None]
        hi = np.maximum(k // 2, 0)[None, :, :, None]
        lo, hi = (np.broadcast_to(i, (1, *block.shape[1:])) for i in (lo, hi))
        med = 0.5 * (np.take_along_axis(block, lo, 0)[0].astype(np.float32)
                     + np.take_along_axis(block, hi, 0)[0].astype(np.float32))
        dev = np.abs(block.astype(np.float32) - med[None])
        dev[block == invalid] = np.inf
        dev.sort(axis=0)
        mad = 0.5 * (np.take_along_axis(dev, lo, 0)[0] + np.take_along_axis(dev, hi, 0)[0])
        ok = enough[r0:r1]
        mean[r0:r1][ok] = med[ok]
        std[r0:r1][ok] = _MAD_TO_STD * mad[ok]
    return BackgroundModel(mean, std)


# ---------------------------------------------------------------------------------------------
# Classification
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class SilhouetteConfig:
    """Thresholds of the per-pixel classification and the morphological clean-up."""

    lower_sigma: float = field(
        default=3.0,
        metadata={
            "help": "certainly background where every channel is within this many (floored) "
            "standard deviations of the background mean"
        },
    )
    upper_sigma: float = field(
        default=10.0,
        metadata={
            "help": "certainly foreground where a channel differs by more than this many "
            "standard deviations; pixels in between are shadow candidates"
        },
    )
    min_std: float = field(
        default=6.0,
        metadata={
            "help": "floor on the per-pixel standard deviation, in grey levels of 8-bit "
            "images: compression and sensor noise that a short background clip under-samples"
        },
    )
    detect_shadows: bool = field(
        default=True,
        metadata={"help": "label shadow candidates that pass the shadow test as shadow"},
    )
    shadow_min_brightness: float = field(
        default=0.5,
        metadata={
            "help": "darkest shadow, as a fraction of the background's brightness; "
            "darker candidates are foreground"
        },
    )
    shadow_max_brightness: float = field(
        default=0.95,
        metadata={"help": "lightest shadow, as a fraction of the background's brightness"},
    )
    shadow_max_angle_deg: float = field(
        default=2.0,
        metadata={
            "help": "largest angle between the colour vectors of pixel and background in a "
            "shadow: a shadow dims the light but keeps the surface's colour"
        },
    )
    smooth_px: float = field(
        default=0.0,
        metadata={"help": "Gaussian blur (sigma, pixels) of the per-pixel difference before "
                  "the thresholds: noisy regions come out more coherent, but strong edges "
                  "bleed outwards by about the sigma (CDnet highway: F 0.955 at 1.0, 0.952 "
                  "at 0); 0 disables"},
    )  # fmt: skip
    open_px: int = field(
        default=3,
        metadata={"help": "diameter of the opening's disc (removes specks); 0 disables"},
    )
    close_px: int = field(
        default=5,
        metadata={"help": "diameter of the closing's disc (bridges thin gaps); 0 disables"},
    )
    max_hole_area: int = field(
        default=400,
        metadata={
            "help": "fill enclosed background holes up to this many pixels (a real gap, "
            "between an arm and the torso, is larger); 0 disables"
        },
    )
    min_area: int = field(
        default=50,
        metadata={"help": "drop foreground components smaller than this many pixels"},
    )
    edge_band_px: int | None = field(
        default=None,
        metadata={"help": "half-width of the band round the cleaned outline where each pixel "
                  "goes to the nearer of the background and the subject's local colour (a "
                  "pixel the subject half covers is split there, not at the lower threshold, "
                  "which codec blur and a bright subject pass a pixel or two out); pixels at "
                  "any image size; 0 disables; default: 1 against clean plates, 0 against a "
                  "median (the Pose2Sim demo: IoU 0.717 with 1, 0.718 with 0)"},
    )  # fmt: skip
    reference_pixels: int = field(
        default=640 * 480,
        metadata={"help": "image size (pixels) the sizes above are meant for: in a larger "
                  "image the lengths grow with the square root of the size ratio and the "
                  "areas with the ratio (a 1920x1088 video: x2.6 and x6.8); 0 disables"},
    )  # fmt: skip

    def scale(self, shape: tuple[int, ...]) -> float:
        """Length factor of the pixel sizes for an image of this (H, W, ...) shape (>= 1)."""
        if self.reference_pixels <= 0:
            return 1.0
        return max(1.0, math.sqrt(shape[0] * shape[1] / self.reference_pixels))

    def __post_init__(self) -> None:
        if not 0 <= self.lower_sigma <= self.upper_sigma:
            raise ValueError(
                f"need 0 <= lower_sigma <= upper_sigma, got {self.lower_sigma}, "
                f"{self.upper_sigma}"
            )
        if self.edge_band_px is not None and self.edge_band_px < 0:
            raise ValueError(f"edge_band_px must be >= 0, got {self.edge_band_px}")
        if self.min_std <= 0:
            raise ValueError(f"min_std must be > 0, got {self.min_std}")
        if not 0 <= self.shadow_min_brightness <= self.shadow_max_brightness:
            raise ValueError("need 0 <= shadow_min_brightness <= shadow_max_brightness")
        for name in ("open_px", "close_px", "max_hole_area", "min_area"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


def _checked_frame(frame: np.ndarray, model: BackgroundModel) -> np.ndarray:
    frame = _as_hwc(frame, "frame")
    if frame.shape != model.shape:
        raise ValueError(f"frame is {frame.shape} but the background model is {model.shape}")
    return frame


def classify(frame: np.ndarray, model: BackgroundModel, config: SilhouetteConfig | None = None
             ) -> np.ndarray:  # fmt: skip
    """Per-pixel labels of one frame, before any clean-up.

    frame: (H, W, C) or (H, W) image of the model's size. Returns (H, W) uint8 with the values
    of `Label`: 0 background, 1 shadow, 2 foreground.
    """
    config = config or SilhouetteConfig()
    image = _checked_frame(frame, model).astype(np.float32)
    std = np.maximum(model.std, np.float32(config.min_std))
    z = (image - model.mean) / std  # (H, W, C) signed z-scores
    # Element-wise maximum over the channels: the same as np.abs(z).max(axis=2), ~7x faster.
    abs_z = np.abs(z)
    abs_max = abs_z[:, :, 0]
    for channel in range(1, abs_z.shape[2]):
        abs_max = np.maximum(abs_max, abs_z[:, :, channel])
    if config.smooth_px > 0:
        abs_max = cv2.GaussianBlur(abs_max, (0, 0), config.smooth_px * config.scale(image.shape))
    background = abs_max < config.lower_sigma
    certain = abs_max > config.upper_sigma
    labels = np.full(abs_max.shape, Label.FOREGROUND, np.uint8)
    labels[background] = Label.BACKGROUND
    if not config.detect_shadows:
        return labels
    candidate = ~(background | certain)
    # Only the candidates (usually a few percent of the image) go through the shadow test.
    rows, cols = np.nonzero(candidate)
    shadow = _shadow_test(image[rows, cols], model.mean[rows, cols], std[rows, cols], config)
    labels[rows[shadow], cols[shadow]] = Label.SHADOW
    return labels


def _shadow_test(image: np.ndarray, mean: np.ndarray, std: np.ndarray, config: SilhouetteConfig
                 ) -> np.ndarray:  # fmt: skip
    """(N,) bool: brightness ratio in the shadow range and colour angle small (Horprasert).

    image, mean, std: (N, C) float32 of N pixels, std already floored.
    """
    inv_var = 1.0 / (std * std)
    num = (image * mean * inv_var).sum(axis=1)
    den = (mean * mean * inv_var).sum(axis=1)
    # A black background (den 0) cannot be darkened: ratio 0 fails any positive minimum.
    alpha = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    dimmed = (alpha >= config.shadow_min_brightness) & (alpha <= config.shadow_max_brightness)
    if image.shape[1] == 1:
        return dimmed
    # Angle between the colour vectors, scale-free so that a 50% shadow is judged like a 90%
    # one; cos >= cos(max angle) avoids an arccos per pixel.
    dot = (image * mean).sum(axis=1)
    norms = np.sqrt((image * image).sum(axis=1) * (mean * mean).sum(axis=1))
    cos = np.divide(dot, norms, out=np.zeros_like(dot), where=norms > 0)
    return dimmed & (cos >= math.cos(math.radians(config.shadow_max_angle_deg)))


def disc(diameter: int) -> np.ndarray:
    """An elliptic structuring element `diameter` pixels across."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter, diameter))


def foreground_mask(labels: np.ndarray, config: SilhouetteConfig | None = None) -> np.ndarray:
    """The cleaned silhouette of a `classify` label image: (H, W) bool, shadow is background.

    Opening removes isolated false detections, closing bridges thin gaps (a car's windscreen,
    a dark belt), then enclosed holes up to `max_hole_area` are filled and components smaller
    than `min_area` are dropped.
    """
    config = config or SilhouetteConfig()
    labels = np.asarray(labels)
    if labels.ndim != 2:
        raise ValueError(f"labels have shape {labels.shape}: expected (H, W)")
    mask = (labels == Label.FOREGROUND).astype(np.uint8)
    k = config.scale(labels.shape)
    open_px, close_px = round(config.open_px * k), round(config.close_px * k)
    if open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, disc(open_px))
    if close_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, disc(close_px))
    if config.max_hole_area > 0:
        mask = fill_holes(mask, round(config.max_hole_area * k * k))
    if config.min_area > 0:
        mask = _drop_small(mask, round(config.min_area * k * k))
    return mask.astype(bool)


def fill_holes(mask: np.ndarray, max_area: int) -> np.ndarray:
    """Background components not touching the border and at most max_area pixels become 1."""
    # 4-connected background pairs with the 8-connected foreground components of _drop_small.
    n, comp, stats, _ = cv2.connectedComponentsWithStats(1 - mask, connectivity=4)
    h, w = mask.shape
    x, y, cw, ch, area = (stats[:, i] for i in range(5))
    inside = (x > 0) & (y > 0) & (x + cw < w) & (y + ch < h)
    fill = inside & (area <= max_area)
    fill[0] = False  # label 0 is the foreground itself
    return np.where(fill[comp], 1, mask).astype(np.uint8)


def component_hulls(mask: np.ndarray, group_px: int = 0) -> np.ndarray:
    """(H, W) uint8, 1 inside the convex hull of each group of components of ``mask``, the
    components closer than about ``group_px`` pixels grouped (the fragments of one subject's
    silhouette: limbs that the background swallowed between): the region a silhouette
    spans, the gaps between its limbs and the holes of a camouflaged part included."""
    mask = np.asarray(mask, np.uint8)
    grow = disc(group_px) if group_px > 1 else None
    grouped = mask if grow is None else cv2.dilate(mask, grow)
    contours, _ = cv2.findContours(grouped, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    hulls = np.zeros(mask.shape, np.uint8)
    for contour in contours:
        cv2.fillPoly(hulls, [cv2.convexHull(contour)], 1)
    return hulls if grow is None else cv2.erode(hulls, grow)


def _drop_small(mask: np.ndarray, min_area: int) -> np.ndarray:
    n, comp, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    keep[0] = False
    return keep[comp].astype(np.uint8)


def silhouette_from_frame(frame_bgr: np.ndarray, model: BackgroundModel,
                          config: SilhouetteConfig | None = None) -> np.ndarray:  # fmt: skip
    """The silhouette of one frame: (H, W) bool, True on the (cleaned) foreground.

    `foreground_mask(classify(frame_bgr, model, config), config)`; use `classify` to see
    the shadow labels too.
    """
    config = config or SilhouetteConfig()
    mask = foreground_mask(classify(frame_bgr, model, config), config)
    return refined_outline(frame_bgr, model, mask, config) if config.edge_band_px else mask


def refined_outline(frame: np.ndarray, model: BackgroundModel, mask: np.ndarray,
                    config: SilhouetteConfig | None = None) -> np.ndarray:  # fmt: skip
    """``mask`` (H, W) bool with the pixels of a band ``edge_band_px`` wide on either side of
    its outline relabelled: foreground where the pixel is nearer (in the model's floored
    standard deviations) the subject's local colour than the background's. The local colour
    is the Gaussian-weighted mean of the frame over the mask's interior (the mask eroded by
    the band), so a pixel the subject covers half is split at half the contrast; pixels with
    no interior nearby keep their label."""
    config = config or SilhouetteConfig()
    r = config.edge_band_px or 1  # codec blur is a pixel or two at any size: not scaled
    shape = disc(2 * r + 1)
    m = mask.astype(np.uint8)
    inner = cv2.erode(m, shape)
    if not inner.any():
        return mask
    band = (cv2.dilate(m, shape) > 0) & (inner == 0)
    ys, xs = np.nonzero(band)
    y0, y1 = max(0, ys.min() - 4 * r), min(mask.shape[0], ys.max() + 4 * r + 1)
    x0, x1 = max(0, xs.min() - 4 * r), min(mask.shape[1], xs.max() + 4 * r + 1)
    image = _checked_frame(frame, model)[y0:y1, x0:x1].astype(np.float32)
    interior = inner[y0:y1, x0:x1].astype(np.float32)
    sigma = float(2 * r)
    weight = cv2.GaussianBlur(interior, (0, 0), sigma)
    colour = cv2.GaussianBlur(image * interior[..., None], (0, 0), sigma)
    if colour.ndim == 2:
        colour = colour[..., None]
    ok = band[y0:y1, x0:x1] & (weight > 0.05)
    pixels = image[ok]
    local = colour[ok] / weight[ok][:, None]
    mean = model.mean[y0:y1, x0:x1][ok]
    std = np.maximum(model.std[y0:y1, x0:x1][ok], np.float32(config.min_std))
    nearer = (((pixels - local) / std) ** 2).sum(1) < (((pixels - mean) / std) ** 2).sum(1)
    out = mask.copy()
    view = out[y0:y1, x0:x1]
    view[ok] = nearer
    return out


EXPOSURE_GRID_PX = 4
"""`exposure_gain` samples every this many pixels in both directions."""


def exposure_gain(frame: np.ndarray, model: BackgroundModel, config: SilhouetteConfig | None = None
                  ) -> np.ndarray:  # fmt: skip
    """Per channel, the factor (C,) float by which a frame's exposure differs from a
    background plate's (auto exposure, white balance, light that drifted since the plate was
    taken): the median ratio of frame to background over the pixels of a sub-sampled grid,
    then twice again over those that the ratio so far makes certainly background
    (`classify`'s lower threshold), so that the subject, whatever its size, does not sway it.
    Divide the frame by it before classifying (`matched_exposure`)."""
    config = config or SilhouetteConfig()
    g = EXPOSURE_GRID_PX
    image = _checked_frame(frame, model)[::g, ::g].astype(np.float32)
    mean = model.mean[::g, ::g]
    std = np.maximum(model.std[::g, ::g], np.float32(config.min_std))
    lit = (mean > 8.0).all(axis=2) & (image > 8.0).all(axis=2)  # no ratio in the dark
    if not lit.any():
        return np.ones(image.shape[2])
    ratio = image[lit] / mean[lit]  # (M, C)
    gain = np.median(ratio, axis=0)
    for _ in range(2):
        agree = (np.abs(image[lit] / gain - mean[lit]) < config.lower_sigma * std[lit]).all(1)
        if agree.sum() < max(16, agree.size // 20):
            break
        gain = np.median(ratio[agree], axis=0)
    return gain.astype(np.float64)


def matched_exposure(frame: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """The uint8 frame (H, W, C) divided by its `exposure_gain` (rounded, saturated)."""
    return cv2.multiply(frame, tuple(float(1.0 / v) for v in gain) + (0.0,) * (4 - len(gain)),
                        dtype=cv2.CV_8U)


# ---------------------------------------------------------------------------------------------
# Scoring (CDnet convention)
# ---------------------------------------------------------------------------------------------

# CDnet 2012/2014 ground-truth grey levels.
GT_STATIC, GT_SHADOW, GT_OUTSIDE_ROI, GT_UNKNOWN, GT_MOTION = 0, 50, 85, 170, 255


@dataclass(frozen=True)
class Counts:
    """Pixel counts of a foreground mask against ground truth; add them to pool frames."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    tn: int = 0

    def __add__(self, other: Counts) -> Counts:
        return Counts(self.tp + other.tp, self.fp + other.fp, self.fn + other.fn,
                      self.tn + other.tn)  # fmt: skip

    @property
    def precision(self) -> float:
        """tp / (tp + fp); NaN when nothing was predicted."""
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else math.nan

    @property
    def recall(self) -> float:
        """tp / (tp + fn); NaN when the truth has no foreground."""
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else math.nan

    @property
    def f_measure(self) -> float:
        """2 tp / (2 tp + fp + fn), the harmonic mean of the two; NaN when all three are 0."""
        den = 2 * self.tp + self.fp + self.fn
        return 2 * self.tp / den if den else math.nan


def confusion_counts(pred_fg: np.ndarray, gt_labels: np.ndarray, roi: np.ndarray | None = None
                     ) -> Counts:  # fmt: skip
    """Counts of a predicted foreground against a CDnet ground-truth image.

    pred_fg: (H, W) bool. gt_labels: (H, W) uint8 with CDnet's values: 255 moving foreground,
    0 static and 50 shadow both background, 170 unknown (object borders) and 85 outside the
    region of interest are not counted. roi: (H, W), nonzero inside (CDnet's ROI.bmp), or None
    for the whole image; pixels outside it are not counted.
    """
    pred_fg = np.asarray(pred_fg, bool)
    gt_labels = np.asarray(gt_labels)
    if gt_labels.ndim == 3:
        gt_labels = gt_labels[:, :, 0]  # a PNG read as 3 equal channels
    if pred_fg.shape != gt_labels.shape:
        raise ValueError(f"prediction is {pred_fg.shape} but ground truth is {gt_labels.shape}")
    valid = (gt_labels != GT_UNKNOWN) & (gt_labels != GT_OUTSIDE_ROI)
    if roi is not None:
        roi = np.asarray(roi)
        if roi.ndim == 3:
            roi = roi[:, :, 0]
        if roi.shape != gt_labels.shape:
            raise ValueError(f"ROI is {roi.shape} but ground truth is {gt_labels.shape}")
        valid &= roi != 0
    truth = gt_labels == GT_MOTION
    tp = int((pred_fg & truth & valid).sum())
    fp = int((pred_fg & ~truth & valid).sum())
    fn = int((~pred_fg & truth & valid).sum())
    return Counts(tp, fp, fn, int(valid.sum()) - tp - fp - fn)


def f_measure(pred_fg: np.ndarray, gt_labels: np.ndarray, roi: np.ndarray | None = None
              ) -> float:  # fmt: skip
    """F-measure of one predicted foreground (H, W) bool against CDnet ground truth.

    See `confusion_counts` for the label convention; NaN when neither prediction nor truth has
    foreground in the counted pixels. To score a sequence the CDnet way, add the frames'
    `Counts` and take `.f_measure` of the sum.
    """
    return confusion_counts(pred_fg, gt_labels, roi).f_measure
