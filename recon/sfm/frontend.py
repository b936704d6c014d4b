"""The thesis' two-view front end: Harris corners, NCC matching, RANSAC + LMedS for ``F``.

This is the alternative to COLMAP's SIFT front end that reproduces the feature pipeline of the
thesis (ch. 4, §4.4.2 and Figure 4.1): Harris corners are detected in each image, matched by
normalised cross-correlation (NCC) of grey-level windows, and the fundamental matrix of each
pair is estimated robustly by RANSAC followed by Least Median of Squares (LMedS) on the RANSAC
inliers. Its ``F`` feeds the closed-form Kruppa focal estimator (:mod:`recon.calibration`).

Parameters
----------
The thesis names its methods but gives no numbers for them. The NCC window (15 x 15,
``patch_radius_px = 7``) and the 0.8 correlation threshold are those of Zhang, Deriche,
Faugeras and Luong's robust matcher, which the thesis cites for this step ([35]; our copy of
the thesis has no reference list). The Harris settings were chosen on the synthetic room
(``recon.evaluation.synthetic_room``): a 3 x 3 structure-tensor window, k = 0.04, 3 px suppression
and a
quality level of 0.001 gave 153 and 183 correct inliers on two pairs, against 122 and 133 with
a 5 x 5 window and 4 px, and 93 and 95 with OpenCV's default quality level of 0.01.

What differs from the thesis, and why
-------------------------------------
- Zhang et al. disambiguate correlation matches by *relaxation* (support from neighbouring
  matches). Here a mutual-best check and a ratio test between the best and second-best NCC do
  that job, in one pass over the NCC matrix.
- Corners get sub-pixel positions from a parabola through the Harris response around each
  maximum: on the synthetic room this halves the true epipolar error of correct matches
  (median Sampson distance 0.08-0.10 px instead of 0.19-0.23 px at integer positions).
- LMedS breaks down when more than half of the matches lie on one plane, and plain RANSAC
  stops early on a plane plus two points, so each model is kept only if it has the most
  inliers, next to a USAC_ACCURATE model (OpenCV's DEGENSAC-style plane-and-parallax check).
  The winner is refined by minimising the Sampson distances of its inliers (``refine``,
  :func:`recon.sfm.fundamental.refine_sampson`).
- A pair whose matches a homography explains (a planar scene or a pure rotation) is reported
  as ``"planar-or-panoramic"`` without ``F``: there the matches do not determine ``F``, and a
  Kruppa focal from it would be arbitrary.

Conventions
-----------
- Pixel coordinates are COLMAP's: pixel ``(i, j)`` covers ``[i, i + 1) x [j, j + 1)`` and has
  its centre at ``(i + 0.5, j + 0.5)``, i.e. OpenCV coordinates + 0.5. Corners are always
  returned in the original, full-resolution image, even when detection ran on a downscaled
  copy (``max_image_size``).
- ``F`` maps image-1 points to epipolar lines in image 2: ``x2ᵀ F x1 = 0`` for homogeneous
  pixel coordinates in the convention above (COLMAP's convention; for cameras ``K[I|0]`` and
  ``K[R|t]``, ``F ∝ K⁻ᵀ [t]ₓ R K⁻¹``). It is scaled to unit Frobenius norm with its
  largest-magnitude entry positive, and has rank 2.
- Match arrays are ``(M, 2)`` int64: column 0 indexes the corners of image 1, column 1 those
  of image 2.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from recon.errors import UserError
from recon.sfm.fundamental import normalise_fundamental, refine_sampson, sampson_distance_px

# A window whose grey levels vary less than this (standard deviation, 8-bit units) has no
# usable correlation: its NCC with anything is dominated by noise and quantisation.
_MIN_PATCH_STD = 1.0
# Sub-pixel refinement moves a corner by at most half a pixel; a parabola whose vertex lies
# further out is not a clean maximum, and the integer position is kept.
_MAX_SUBPIXEL_SHIFT = 0.5


@dataclass(frozen=True, kw_only=True)
class HarrisNccConfig:
    """Settings of the Harris + NCC front end. Pixel sizes refer to the detection image."""

    max_corners: int = field(
        default=2000,
        metadata={"help": "corners per image: the strongest Harris maxima after suppression"},
    )
    quality_level: float = field(
        default=0.001,
        metadata={"help": "drop corners whose Harris response is below this times the maximum"},
    )
    min_distance_px: int = field(
        default=3,
        metadata={"help": "non-maximum suppression radius: corners are at least this far apart"},
    )
    block_size: int = field(
        default=3,
        metadata={"help": "side of the window summing the Harris structure tensor (pixels)"},
    )
    harris_k: float = field(
        default=0.04,
        metadata={"help": "Harris k in det(M) - k trace(M)^2"},
    )
    patch_radius_px: int = field(
        default=7,
        metadata={"help": "NCC window radius r: windows are (2r+1)x(2r+1) pixels"},
    )
    min_ncc: float = field(
        default=0.8,
        metadata={"help": "smallest normalised cross-correlation of a match"},
    )
    max_ncc_ratio: float | None = field(
        default=0.9,
        metadata={
            "help": "ratio test: the best match's window distance sqrt(2 - 2 NCC) must be below "
            "this times the second best's (candidates overlapping the best excluded); "
            "None disables"
        },
    )
    max_disparity_frac: float | None = field(
        default=None,
        metadata={
            "help": "search range: a match moves at most this fraction of the image diagonal; "
            "None searches the whole image"
        },
    )
    mutual: bool = field(
        default=True,
        metadata={"help": "keep a match only if each corner is the other's best NCC match"},
    )
    ransac_threshold_px: float = field(
        default=1.0,
        metadata={
            "help": "inlier threshold of RANSAC, of the final Sampson distance and of the "
            "homography check, in detection px (scaled up for downscaled images)"
        },
    )
    ransac_confidence: float = field(
        default=0.999,
        metadata={"help": "RANSAC and LMedS confidence that an outlier-free sample was drawn"},
    )
    ransac_max_iters: int = field(
        default=10000,
        metadata={"help": "most iterations of each robust estimator (RANSAC, LMedS, USAC)"},
    )
    degeneracy_candidate: bool = field(
        default=True,
        metadata={
            "help": "also fit F with OpenCV's USAC_ACCURATE, whose DEGENSAC check survives "
            "matches mostly on one plane, and keep it if it has more inliers than the thesis' "
            "RANSAC + LMedS"
        },
    )
    refine: bool = field(
        default=True,
        metadata={"help": "refine F by minimising the Sampson distances of its inliers"},
    )
    max_homography_inlier_ratio: float | None = field(
        default=0.8,
        metadata={
            "help": "report a pair as planar-or-panoramic (no F) when a homography explains "
            "more than this fraction of F's inliers; None disables the check"
        },
    )
    min_off_plane_inliers: int | None = field(
        default=30,
        metadata={
            "help": "report a pair as planar-or-panoramic (no F) when fewer of F's inliers than "
            "this are off the dominant homography (only they determine F); None disables"
        },
    )
    min_inliers: int = field(
        default=30,
        metadata={"help": "fewest inlier matches for a pair to get an F"},
    )
    max_image_size: int = field(
        default=2000,
        metadata={
            "help": "larger images are downscaled to this longest side for detection and "
            "matching; coordinates stay in full-resolution pixels"
        },
    )

    def __post_init__(self) -> None:
        positive_ints = ("max_corners", "min_distance_px", "patch_radius_px", "ransac_max_iters")
        for name in positive_ints:
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.block_size < 2:
            raise ValueError(f"block_size must be at least 2, got {self.block_size}")
        if not 0.0 < self.quality_level < 1.0:
            raise ValueError(f"quality_level must be in (0, 1), got {self.quality_level}")
        if not 0.0 < self.harris_k < 0.25:
            raise ValueError(f"harris_k must be in (0, 0.25), got {self.harris_k}")
        if not -1.0 <= self.min_ncc < 1.0:
            raise ValueError(f"min_ncc must be in [-1, 1), got {self.min_ncc}")
        if self.max_ncc_ratio is not None and not 0.0 < self.max_ncc_ratio <= 1.0:
            raise ValueError(f"max_ncc_ratio must be in (0, 1] or None, got {self.max_ncc_ratio}")
        if self.max_disparity_frac is not None and not self.max_disparity_frac > 0.0:
            raise ValueError(
                f"max_disparity_frac must be positive or None, got {self.max_disparity_frac}"
            )
        if not (math.isfinite(self.ransac_threshold_px) and self.ransac_threshold_px > 0.0):
            raise ValueError(
                f"ransac_threshold_px must be positive, got {self.ransac_threshold_px}"
            )
        if not 0.0 < self.ransac_confidence < 1.0:
            raise ValueError(f"ransac_confidence must be in (0, 1), got {self.ransac_confidence}")
        if self.min_off_plane_inliers is not None and self.min_off_plane_inliers < 0:
            raise ValueError(
                f"min_off_plane_inliers must be non-negative, got {self.min_off_plane_inliers}"
            )
        ratio = self.max_homography_inlier_ratio
        if ratio is not None and not 0.0 < ratio <= 1.0:
            raise ValueError(f"max_homography_inlier_ratio must be in (0, 1] or None, got {ratio}")
        if self.min_inliers < 8:
            raise ValueError(f"min_inliers must be at least 8, got {self.min_inliers}")
        if self.max_image_size < 16:
            raise ValueError(f"max_image_size must be at least 16, got {self.max_image_size}")


@dataclass(frozen=True)
class PairGeometry:
    """Two-view geometry of one image pair.

    ``status`` is ``"ok"`` (``F`` set, ``inlier_matches`` are its inliers), or why there is no
    ``F``: ``"too-few-corners"``, ``"too-few-matches"``, ``"degenerate"`` (OpenCV found no
    ``F``), ``"too-few-inliers"`` or ``"planar-or-panoramic"`` (a homography explains the
    matches; ``inlier_matches`` are then the homography's inliers).
    """

    F: np.ndarray | None  # (3, 3) x2ᵀ F x1 = 0, pixel centres at +0.5, unit Frobenius norm
    inlier_matches: np.ndarray  # (K, 2) int64 indices into (corners1, corners2)
    num_matches: int  # NCC matches before geometric verification
    status: str
    matches: np.ndarray = field(
        default_factory=lambda: np.zeros((0, 2), np.int64)
    )  # (M, 2) int64 all NCC matches, for COLMAP's matches table


@dataclass(frozen=True)
class FrontEndResult:
    corners: dict[str, np.ndarray]  # image name -> (N, 2) float32 px, pixel centres at +0.5
    pairs: dict[tuple[str, str], PairGeometry]  # (name_i, name_j) with name_i < name_j


@dataclass(frozen=True)
class _Windows:
    """NCC windows of the corners of one image that are far enough from its border."""

    vectors: np.ndarray  # (V, (2r+1)^2) float32, zero mean and unit norm
    index: np.ndarray  # (V,) int64 corner index of each row of ``vectors``
    points_px: np.ndarray  # (V, 2) float64 full-resolution px of those corners
    exclusion_px: float  # full-resolution distance below which two corners' windows overlap
    detection_scale: float  # full-resolution px per detection px (1 unless downscaled)
    diagonal_px: float  # full-resolution image diagonal


def _detection_image(
    image_gray: np.ndarray, config: HarrisNccConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Float32 grey image at detection resolution and the (2,) full-from-detection x, y scales.

    In COLMAP coordinates (pixel edges at integers) resizing maps points exactly:
    ``points_full_px = scale * points_det_px``.
    """
    if image_gray.ndim != 2 or min(image_gray.shape) < 1:
        raise ValueError(f"expected a (H, W) grey image, got shape {image_gray.shape}")
    gray = image_gray.astype(np.float32, copy=False)
    height, width = gray.shape
    longest = max(height, width)
    if longest <= config.max_image_size:
        return gray, np.ones(2)
    shrink = longest / config.max_image_size
    size = (max(1, round(width / shrink)), max(1, round(height / shrink)))
    # Area averaging: the anti-aliased reduction, so corners are not made from aliasing.
    small = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    # One scale per axis: rounding the sides makes them differ slightly, and both are exact.
    return small, np.array([width / size[0], height / size[1]])


def _subpixel_offsets(response: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(N, 2) vertex offsets of parabolas through the response at (x - 1, x, x + 1) and in y."""
    offsets = np.zeros((len(xs), 2))
    for axis, (dx, dy) in enumerate(((1, 0), (0, 1))):
        before = response[ys - dy, xs - dx].astype(np.float64)
        centre = response[ys, xs].astype(np.float64)
        after = response[ys + dy, xs + dx].astype(np.float64)
        curvature = before - 2.0 * centre + after
        with np.errstate(divide="ignore", invalid="ignore"):
            shift = 0.5 * (before - after) / curvature
        usable = (curvature < 0) & (np.abs(shift) <= _MAX_SUBPIXEL_SHIFT)
        offsets[:, axis] = np.where(usable, shift, 0.0)
    return offsets


def detect_corners(image_gray: np.ndarray, config: HarrisNccConfig) -> np.ndarray:
    """Harris corners of a grey image, strongest first.

    ``image_gray`` is ``(H, W)`` in 8-bit grey levels (uint8 or float). Corners closer to the
    border than the NCC window are not detected, since they could not be matched. Returns
    ``(N, 2)`` float32 ``(x, y)`` full-resolution pixel coordinates with pixel centres at +0.5,
    ``N <= config.max_corners``.
    """
    gray, scale = _detection_image(image_gray, config)
    height, width = gray.shape
    response = cv2.cornerHarris(gray, config.block_size, 3, config.harris_k)
    border = max(config.patch_radius_px, config.block_size // 2 + 1)
    if height <= 2 * border or width <= 2 * border:
        return np.zeros((0, 2), np.float32)
    size = 2 * config.min_distance_px + 1
    dilated = cv2.dilate(response, np.ones((size, size), np.uint8))
    threshold = config.quality_level * float(response.max())
    is_peak = (response == dilated) & (response > max(threshold, 0.0))
    is_peak[:border] = False
    is_peak[-border:] = False
    is_peak[:, :border] = False
    is_peak[:, -border:] = False
    ys, xs = np.nonzero(is_peak)
    strength = response[ys, xs]
    # Strongest first; ties broken by raster order so the result is deterministic.
    order = np.lexsort((xs, ys, -strength))
    xs, ys = xs[order], ys[order]
    # Equal responses on a plateau are all "maxima"; keep the first of any two within the
    # suppression window (Chebyshev distance, like the dilation).
    if len(xs) > 1:
        tree = cKDTree(np.column_stack([xs, ys]))
        pairs = tree.query_pairs(r=config.min_distance_px, p=np.inf, output_type="ndarray")
        keep = np.ones(len(xs), bool)
        keep[pairs.max(axis=1)] = False
        xs, ys = xs[keep], ys[keep]
    xs, ys = xs[: config.max_corners], ys[: config.max_corners]
    offsets = _subpixel_offsets(response, xs, ys)
    points_det = np.column_stack([xs, ys]) + offsets + 0.5
    return (points_det * scale).astype(np.float32)


def _ncc_windows(
    image_gray: np.ndarray, corners_px: np.ndarray, config: HarrisNccConfig
) -> _Windows:
    """Zero-mean, unit-norm NCC windows around the corners, at detection resolution."""
    gray, scale = _detection_image(image_gray, config)
    height, width = gray.shape
    corners_px = np.asarray(corners_px, np.float64).reshape(-1, 2)
    r = config.patch_radius_px
    # Nearest detection pixel of each corner (OpenCV coordinates): the window is centred there.
    centres = np.floor(corners_px / scale).astype(np.int64)
    inside = (
        (centres[:, 0] >= r)
        & (centres[:, 0] < width - r)
        & (centres[:, 1] >= r)
        & (centres[:, 1] < height - r)
    )
    index = np.flatnonzero(inside)
    offsets = np.arange(-r, r + 1)
    rows = centres[index, 1][:, None, None] + offsets[None, :, None]
    cols = centres[index, 0][:, None, None] + offsets[None, None, :]
    windows = gray[rows, cols].reshape(len(index), (2 * r + 1) ** 2)
    windows = windows - windows.mean(axis=1, keepdims=True)
    norms = np.linalg.norm(windows, axis=1)
    textured = norms > _MIN_PATCH_STD * math.sqrt(windows.shape[1])
    vectors = (windows[textured] / norms[textured, None]).astype(np.float32)
    full_height, full_width = image_gray.shape
    return _Windows(
        vectors=vectors,
        index=index[textured],
        points_px=corners_px[index[textured]],
        exclusion_px=(2 * r + 1) * float(scale.max()),
        detection_scale=float(scale.max()),
        diagonal_px=math.hypot(full_width, full_height),
    )


def _match_windows(w1: _Windows, w2: _Windows, config: HarrisNccConfig) -> np.ndarray:
    """(M, 2) int64 corner indices of the NCC matches between two images' windows."""
    empty = np.zeros((0, 2), np.int64)
    if len(w1.index) == 0 or len(w2.index) == 0:
        return empty
    # For unit-norm zero-mean windows, the NCC of every pair is one matrix product.
    ncc = w1.vectors @ w2.vectors.T
    if config.max_disparity_frac is not None:
        radius = config.max_disparity_frac * max(w1.diagonal_px, w2.diagonal_px)
        ncc[cdist(w1.points_px, w2.points_px, "sqeuclidean") > radius**2] = -np.inf
    rows = np.arange(len(w1.index))
    best2 = np.argmax(ncc, axis=1)
    best_ncc = ncc[rows, best2]
    good = best_ncc >= config.min_ncc
    if config.mutual:
        best1 = np.argmax(ncc, axis=0)
        good &= best1[best2] == rows
    candidates = np.flatnonzero(good)
    if config.max_ncc_ratio is not None and len(candidates):
        # The runner-up must be a different place: corners whose windows overlap the best
        # one's look alike whether or not the match is right, so they are not competitors.
        chosen = w2.points_px[best2[candidates]]
        overlapping = cdist(chosen, w2.points_px, "sqeuclidean") < w2.exclusion_px**2
        rivals = np.where(overlapping, -np.inf, ncc[candidates])
        second_ncc = rivals.max(axis=1)
        best_distance = np.sqrt(np.maximum(2.0 - 2.0 * best_ncc[candidates], 0.0))
        second_distance = np.sqrt(np.maximum(2.0 - 2.0 * second_ncc, 0.0))
        distinct = best_distance < config.max_ncc_ratio * second_distance
        candidates = candidates[distinct]
    if len(candidates) == 0:
        return empty
    return np.column_stack([w1.index[candidates], w2.index[best2[candidates]]]).astype(np.int64)


def match_ncc(
    gray1: np.ndarray,
    corners1: np.ndarray,
    gray2: np.ndarray,
    corners2: np.ndarray,
    config: HarrisNccConfig,
) -> np.ndarray:
    """Match corners of two grey images by NCC of their ``(2r+1)²`` windows.

    ``corners1``/``corners2`` are ``(N1, 2)``/``(N2, 2)`` full-resolution px (pixel centres at
    +0.5), as from :func:`detect_corners` with the same config. Corners whose window leaves the
    image or is flat are skipped. Returns ``(M, 2)`` int64 indices into (corners1, corners2).
    """
    w1 = _ncc_windows(gray1, corners1, config)
    w2 = _ncc_windows(gray2, corners2, config)
    return _match_windows(w1, w2, config)


def estimate_fundamental(
    points1_px: np.ndarray, points2_px: np.ndarray, config: HarrisNccConfig
) -> tuple[np.ndarray | None, np.ndarray]:
    """Robust ``F`` of matched points: RANSAC, LMedS on its inliers, then Sampson inliers.

    Of the RANSAC, the LMedS and (``degeneracy_candidate``) a USAC_ACCURATE model, the one with
    the most Sampson inliers is kept, then refined (``refine``). ``ransac_threshold_px`` is in
    the points' pixels here.

    ``points1_px``/``points2_px`` are ``(N, 2)`` matched px. Returns ``F`` ((3, 3),
    ``x2ᵀ F x1 = 0`` in the points' convention, unit Frobenius norm, rank 2), or None when
    OpenCV finds none or there are fewer than 8 matches, and the ``(N,)`` bool inlier mask
    (Sampson distance below ``ransac_threshold_px``; all False without ``F``).
    """
    p1 = np.asarray(points1_px, np.float64).reshape(-1, 2)
    p2 = np.asarray(points2_px, np.float64).reshape(-1, 2)
    no_inliers = np.zeros(len(p1), bool)
    if len(p1) < 8:
        return None, no_inliers
    F_ransac, mask = cv2.findFundamentalMat(
        p1,
        p2,
        cv2.FM_RANSAC,
        config.ransac_threshold_px,
        config.ransac_confidence,
        config.ransac_max_iters,
    )
    if F_ransac is None or F_ransac.shape != (3, 3) or mask is None:
        return None, no_inliers
    if not np.isfinite(F_ransac).all() or np.linalg.norm(F_ransac) == 0:
        return None, no_inliers
    F = normalise_fundamental(F_ransac)
    inliers = sampson_distance_px(F, p1, p2) < config.ransac_threshold_px
    # The thesis then optimises the RANSAC consensus with LMedS. LMedS returns a 7-point model
    # of its own and breaks down when over half of the points lie on one plane (a plane plus
    # two other points then has a zero median): measured on the synthetic room, where 115 of
    # 155 inliers were on one plane, its F was 116 px off. So it is kept only when it
    # explains at least as many matches as RANSAC's.
    ransac_inliers = mask.ravel().astype(bool)
    if ransac_inliers.sum() >= 8:
        F_lmeds, _ = cv2.findFundamentalMat(
            p1[ransac_inliers],
            p2[ransac_inliers],
            cv2.FM_LMEDS,
            config.ransac_threshold_px,
            config.ransac_confidence,
            config.ransac_max_iters,
        )
        if F_lmeds is not None and F_lmeds.shape == (3, 3) and np.isfinite(F_lmeds).all():
            F_lmeds = normalise_fundamental(F_lmeds)
            lmeds_inliers = sampson_distance_px(F_lmeds, p1, p2) < config.ransac_threshold_px
            if lmeds_inliers.sum() >= inliers.sum():
                F, inliers = F_lmeds, lmeds_inliers
    if config.degeneracy_candidate:
        # Plain RANSAC stops early on a plane plus two off-plane points, which looks like a
        # large consensus: with 100 of 120 synthetic matches on a floor it missed the true F
        # in 7 of 20 trials; USAC_ACCURATE (with a plane-and-parallax check) in none.
        F_usac, _ = cv2.findFundamentalMat(
            p1,
            p2,
            cv2.USAC_ACCURATE,
            config.ransac_threshold_px,
            config.ransac_confidence,
            config.ransac_max_iters,
        )
        if F_usac is not None and F_usac.shape == (3, 3) and np.isfinite(F_usac).all():
            F_usac = normalise_fundamental(F_usac)
            usac_inliers = sampson_distance_px(F_usac, p1, p2) < config.ransac_threshold_px
            if usac_inliers.sum() > inliers.sum():
                F, inliers = F_usac, usac_inliers
    if config.refine:
        # Two rounds: the refined F may admit matches the 7-point model just missed.
        for _ in range(2):
            if inliers.sum() < 8:
                break
            F_refined = refine_sampson(F, p1[inliers], p2[inliers])
            refined_inliers = sampson_distance_px(F_refined, p1, p2) < config.ransac_threshold_px
            if refined_inliers.sum() < inliers.sum():
                break
            F, inliers = F_refined, refined_inliers
    return F, inliers


def _no_geometry(
    status: str, matches: np.ndarray | None = None, inlier_matches: np.ndarray | None = None
) -> PairGeometry:
    empty = np.zeros((0, 2), np.int64)
    matches = empty if matches is None else matches
    return PairGeometry(
        F=None,
        inlier_matches=empty if inlier_matches is None else inlier_matches,
        num_matches=len(matches),
        status=status,
        matches=matches,
    )


def _pair_geometry(
    matches: np.ndarray,
    corners1: np.ndarray,
    corners2: np.ndarray,
    detection_scale: float,
    config: HarrisNccConfig,
) -> PairGeometry:
    """Geometric verification of NCC matches (M, 2) between corners (N1, 2) and (N2, 2).

    ``detection_scale`` (full-resolution px per detection px) converts the inlier threshold,
    which is in detection px like the corners' accuracy, to the corners' full-resolution px.
    """
    if detection_scale != 1.0:
        threshold_px = config.ransac_threshold_px * detection_scale
        config = dataclasses.replace(config, ransac_threshold_px=threshold_px)
    if len(matches) < config.min_inliers:
        return _no_geometry("too-few-matches", matches)
    points1 = np.asarray(corners1, np.float64)[matches[:, 0]]
    points2 = np.asarray(corners2, np.float64)[matches[:, 1]]
    F, inliers = estimate_fundamental(points1, points2, config)
    if F is None:
        return _no_geometry("degenerate", matches)
    if inliers.sum() < config.min_inliers:
        return _no_geometry("too-few-inliers", matches)
    max_ratio, min_off_plane = config.max_homography_inlier_ratio, config.min_off_plane_inliers
    if max_ratio is not None or min_off_plane is not None:
        # Matches on one plane (or under a pure rotation) fit a homography and every F of a
        # 2-parameter family, so only the matches off that homography pin F down. Measured on
        # the synthetic room: 41 inliers of which 29 on the homography gave an F 27 px off on
        # average. The ratio test is COLMAP's (its max_H_inlier_ratio).
        H, h_mask = cv2.findHomography(
            points1,
            points2,
            cv2.RANSAC,
            config.ransac_threshold_px,
            maxIters=config.ransac_max_iters,
            confidence=config.ransac_confidence,
        )
        if H is not None and h_mask is not None:
            on_plane = h_mask.ravel().astype(bool)
            too_planar = max_ratio is not None and on_plane.sum() > max_ratio * inliers.sum()
            off_plane = int((inliers & ~on_plane).sum())
            if too_planar or (min_off_plane is not None and off_plane < min_off_plane):
                return _no_geometry("planar-or-panoramic", matches, matches[on_plane])
    return PairGeometry(
        F=F,
        inlier_matches=matches[inliers],
        num_matches=len(matches),
        status="ok",
        matches=matches,
    )


def match_pair(
    gray1: np.ndarray,
    corners1: np.ndarray,
    gray2: np.ndarray,
    corners2: np.ndarray,
    config: HarrisNccConfig,
) -> PairGeometry:
    """NCC matches of two grey images' corners and their robust fundamental matrix.

    Arguments are as for :func:`match_ncc`; ``F`` maps image-1 points to image-2 lines.
    """
    if min(len(corners1), len(corners2)) < config.min_inliers:
        return _no_geometry("too-few-corners")
    w1 = _ncc_windows(gray1, corners1, config)
    w2 = _ncc_windows(gray2, corners2, config)
    matches = _match_windows(w1, w2, config)
    scale = max(w1.detection_scale, w2.detection_scale)
    return _pair_geometry(matches, corners1, corners2, scale, config)


def _ordered_pairs(
    names: Sequence[str], pairs: Sequence[tuple[str, str]] | None
) -> list[tuple[str, str]]:
    """Requested pairs as ``(name_i, name_j)`` with ``name_i < name_j``, without repeats."""
    if pairs is None:
        return list(itertools.combinations(sorted(names), 2))
    known = set(names)
    ordered: dict[tuple[str, str], None] = {}
    for a, b in pairs:
        missing = [name for name in (a, b) if name not in known]
        if missing:
            raise ValueError(f"pair ({a}, {b}) names an image not in `images`: {missing[0]}")
        if a == b:
            raise ValueError(f"pair ({a}, {b}) pairs an image with itself")
        ordered[(min(a, b), max(a, b))] = None
    return list(ordered)


def run_front_end(
    images: Mapping[str, Path],
    config: HarrisNccConfig,
    pairs: Sequence[tuple[str, str]] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FrontEndResult:
    """Corners of the images and the two-view geometry of each pair.

    ``images`` maps image names (COLMAP's) to files, read in grey levels. ``pairs`` defaults to
    all pairs; each is matched and stored as ``(name_i, name_j)`` with ``name_i < name_j``
    (``F`` maps ``name_i``'s points to ``name_j``'s epipolar lines). Only images in some pair
    are read when ``pairs`` is given. ``progress(done, total)`` is called after each image
    read and each pair matched (``total`` counts both). Raises :class:`UserError` for an
    unreadable image.
    """
    wanted = _ordered_pairs(list(images), pairs)
    used = sorted(images) if pairs is None else sorted({name for pair in wanted for name in pair})
    total = len(used) + len(wanted)
    done = 0
    corners: dict[str, np.ndarray] = {}
    windows: dict[str, _Windows] = {}
    # Keep each image's NCC windows rather than the image: ~2 MB per image at any image size,
    # and every window is cut once instead of once per pair.
    for name in used:
        gray = cv2.imread(str(images[name]), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise UserError(f"cannot read image {images[name]} (missing, or not an image)")
        corners[name] = detect_corners(gray, config)
        windows[name] = _ncc_windows(gray, corners[name], config)
        done += 1
        if progress is not None:
            progress(done, total)
    geometries: dict[tuple[str, str], PairGeometry] = {}
    for a, b in wanted:
        if min(len(corners[a]), len(corners[b])) < config.min_inliers:
            geometries[(a, b)] = _no_geometry("too-few-corners")
        else:
            matches = _match_windows(windows[a], windows[b], config)
            scale = max(windows[a].detection_scale, windows[b].detection_scale)
            geometries[(a, b)] = _pair_geometry(matches, corners[a], corners[b], scale, config)
        done += 1
        if progress is not None:
            progress(done, total)
    return FrontEndResult(corners=corners, pairs=geometries)
