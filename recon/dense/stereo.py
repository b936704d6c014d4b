"""Rectified two-view stereo on the CPU: pair selection, depth maps, coloured back-projection.

Thesis ch. 5 matches densely along epipolar lines; here the means is modern rectified stereo:
both images of a pair are rotated to a common orientation whose x axis is the baseline (their
epipolar lines become image rows), OpenCV's semi-global matcher (``cv2.StereoSGBM``) finds the
disparity of every pixel in both directions, a left-right consistency check drops occluded and
ambiguous pixels, and each surviving disparity is turned into a depth on the *unrectified*
pixel grid of its view, so that depth maps of one view computed with different partners are
directly comparable (and fusable).

Rectification. ``cv2.stereoRectify`` (``CALIB_ZERO_DISPARITY``) gives the rotation that aligns
the baseline with the x or the y axis; a further rotation about the optical axis (a multiple
of 90 degrees) then puts the source camera on the +x side, so that vertical baselines and
sources on the left need no special case: the reference is always the left image and
disparities are positive. The rectified images are not cropped by ``alpha`` but laid on a
canvas of our own (:class:`_Rectification`): the rectified focal length is the reference's
(no resolution is lost), the rows are those both images cover, and the columns leave exactly
the margin ``StereoSGBM`` needs: it never computes the first ``minDisparity + numDisparities``
columns of its left image, so the images are shifted against each other by the smallest
expected disparity (the search starts at 0) and placed so that every pixel of the overlap is
computed in both directions. Undistorted pinhole images make rectification a homography, done
with one ``cv2.warpPerspective`` per image (what ``initUndistortRectifyMap`` + ``remap`` would
compute, without the maps).

Depth range. With sparse points the disparity search covers the ``depth_percentiles`` of the
reference's points (2nd-98th by default) widened by ``depth_margin``: the cost of SGBM is
width x height x disparities, and the range typically halves the disparities searched. Measured
on 2 cores (``3way`` mode, both depth maps of a pair): 0.27 s per pair at 640x480 (synthetic
room), 0.42 s median (0.34-1.0 s) at 1024x683 on fountain-P11 with COLMAP's sparse points.

Pixel conventions: ``K`` is COLMAP's (pixel (i, j) covers [i, i + 1) x [j, j + 1), centres at
+0.5); OpenCV works with integer centres, so ``K`` is shifted by -0.5 before any OpenCV call.
Depth is z along the view's optical axis in world units, NaN where unknown.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

__all__ = [
    "DepthMap",
    "SgbmMode",
    "StereoConfig",
    "View",
    "backproject_pixels",
    "depths_from_pair",
    "select_pairs",
]


class SgbmMode(enum.StrEnum):
    """``cv2.StereoSGBM`` cost aggregation modes."""

    # 5 paths, single-threaded.
    SGBM = "sgbm"
    # 3 paths, parallel over image strips: the fastest, with a small loss of accuracy.
    THREE_WAY = "3way"
    # 4 paths, parallel.
    HH4 = "hh4"
    # Full 8 paths: slow and memory-hungry (width x height x disparities x 2 bytes).
    HH = "hh"


_CV_MODES = {
    SgbmMode.SGBM: cv2.StereoSGBM_MODE_SGBM,
    SgbmMode.THREE_WAY: cv2.StereoSGBM_MODE_SGBM_3WAY,
    SgbmMode.HH4: cv2.StereoSGBM_MODE_HH4,
    SgbmMode.HH: cv2.StereoSGBM_MODE_HH,
}


@dataclass(frozen=True)
class View:
    """One undistorted image with its pinhole camera.

    ``K`` (3, 3) in pixels with COLMAP's pixel centres at +0.5; ``cam_from_world`` (3, 4)
    ``[R | t]`` with ``x_cam = R x_world + t``; ``image_bgr`` (H, W, 3) uint8 (OpenCV's channel
    order); ``points_in_world`` (N, 3) the sparse points this image observes, if known (the
    same point must have the same coordinates in every view that observes it: pair selection
    counts shared rows).
    """

    name: str
    K: np.ndarray
    cam_from_world: np.ndarray
    image_bgr: np.ndarray
    points_in_world: np.ndarray | None = None

    def __post_init__(self) -> None:
        if np.shape(self.K) != (3, 3):
            raise ValueError(f"{self.name}: K must be (3, 3), got {np.shape(self.K)}")
        if np.shape(self.cam_from_world) != (3, 4):
            raise ValueError(
                f"{self.name}: cam_from_world must be (3, 4), got {np.shape(self.cam_from_world)}"
            )
        image = self.image_bgr
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(
                f"{self.name}: image_bgr must be (H, W, 3) uint8, got {image.shape} {image.dtype}"
            )
        if self.points_in_world is not None and (
            self.points_in_world.ndim != 2 or self.points_in_world.shape[1] != 3
        ):
            raise ValueError(
                f"{self.name}: points_in_world must be (N, 3), got {self.points_in_world.shape}"
            )

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.image_bgr.shape[1], self.image_bgr.shape[0]

    @property
    def center_in_world(self) -> np.ndarray:
        """(3,) camera centre ``-R^T t``."""
        R, t = self.cam_from_world[:, :3], self.cam_from_world[:, 3]
        return -R.T @ t

    @property
    def axis_in_world(self) -> np.ndarray:
        """(3,) unit optical axis (the camera's +z) in world coordinates."""
        axis = self.cam_from_world[2, :3]
        return axis / np.linalg.norm(axis)


@dataclass(frozen=True, kw_only=True)
class StereoConfig:
    """Pair selection and two-view matching of the cpu-stereo backend."""

    max_pairs_per_view: int = field(
        default=2, metadata={"help": "stereo partners each view picks (best covisibility first)"}
    )
    min_triangulation_angle_deg: float = field(
        default=3.0,
        metadata={
            "help": "pairs whose rays meet at a smaller angle (too short a baseline) are "
            "not used: depth precision falls with the angle"
        },
    )
    max_triangulation_angle_deg: float = field(
        default=40.0,
        metadata={
            "help": "pairs whose rays meet at a larger angle are not used: the two "
            "images look too different for block matching"
        },
    )
    max_viewing_angle_deg: float = field(
        default=50.0,
        metadata={
            "help": "largest angle between the optical axes of a pair; also bounds the "
            "rectifying rotation and so the distortion of the rectified images"
        },
    )
    min_shared_points: int = field(
        default=15,
        metadata={
            "help": "with sparse points: partners must observe at least this many of the "
            "same points"
        },
    )
    mode: SgbmMode = field(
        default=SgbmMode.THREE_WAY,
        metadata={
            "help": "StereoSGBM mode: 3way (fastest, parallel), hh4 (4 paths, parallel), "
            "sgbm (5 paths, one thread), hh (8 paths, slow)"
        },
    )
    block_size: int = field(
        default=5, metadata={"help": "SGBM matching block side in pixels (odd, 1-11)"}
    )
    p1: int | None = field(
        default=None,
        metadata={
            "help": "SGBM penalty for disparity changes of 1 between neighbours "
            "(default: 8 * channels * block_size^2)"
        },
    )
    p2: int | None = field(
        default=None,
        metadata={"help": "SGBM penalty for larger disparity jumps (default: 4 * P1)"},
    )
    uniqueness_ratio: int = field(
        default=10,
        metadata={"help": "SGBM: the best cost must beat the second best by this many percent"},
    )
    use_color: bool = field(
        default=False,
        metadata={"help": "match colour images instead of grey (slower, rarely better)"},
    )
    lr_max_diff_px: float | None = field(
        default=1.0,
        metadata={
            "help": "left-right check: largest difference in pixels between a disparity "
            "and the one found back from the other image (None: no check)"
        },
    )
    speckle_window_size: int = field(
        default=100,
        metadata={
            "help": "disparity blobs smaller than this many pixels are removed as speckles (0: off)"
        },
    )
    speckle_range_px: int = field(
        default=2,
        metadata={"help": "largest disparity step in pixels between neighbours of one blob"},
    )
    min_depth: float | None = field(
        default=None,
        metadata={
            "help": "nearest depth to search, world units (default: from the sparse "
            "points, else num_disparities from infinity)"
        },
    )
    max_depth: float | None = field(
        default=None,
        metadata={
            "help": "farthest depth to search, world units (default: from the sparse "
            "points, else infinity)"
        },
    )
    depth_percentiles: tuple[float, ...] = field(
        default=(2.0, 98.0),
        metadata={
            "help": "low and high percentile of the sparse points' depths that bound the "
            "search (give the flag twice)"
        },
    )
    depth_margin: float = field(
        default=0.25,
        metadata={
            "help": "the depth range from the sparse points is widened by this fraction "
            "on both sides"
        },
    )
    num_disparities: int = field(
        default=256,
        metadata={"help": "disparity search range in pixels when no depth range is known"},
    )
    max_num_disparities: int = field(
        default=512,
        metadata={"help": "cap on the disparity search range (cost grows linearly with it)"},
    )

    def __post_init__(self) -> None:
        if self.max_pairs_per_view < 1:
            raise ValueError(f"max_pairs_per_view must be >= 1, got {self.max_pairs_per_view}")
        if not 0 <= self.min_triangulation_angle_deg < self.max_triangulation_angle_deg < 180:
            raise ValueError(
                "need 0 <= min_triangulation_angle_deg < max_triangulation_angle_deg < 180, got "
                f"{self.min_triangulation_angle_deg}, {self.max_triangulation_angle_deg}"
            )
        if not 0 < self.max_viewing_angle_deg < 90:
            raise ValueError(
                f"max_viewing_angle_deg must be in (0, 90), got {self.max_viewing_angle_deg}"
            )
        if self.block_size < 1 or self.block_size % 2 == 0 or self.block_size > 11:
            raise ValueError(f"block_size must be odd and in 1..11, got {self.block_size}")
        if self.lr_max_diff_px is not None and self.lr_max_diff_px < 0:
            raise ValueError(f"lr_max_diff_px must be >= 0, got {self.lr_max_diff_px}")
        for name in ("min_depth", "max_depth"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite, got {value}")
        if (
            self.min_depth is not None
            and self.max_depth is not None
            and self.min_depth >= self.max_depth
        ):
            raise ValueError(f"min_depth {self.min_depth} must be < max_depth {self.max_depth}")
        low_high = self.depth_percentiles
        if len(low_high) != 2 or not 0 <= low_high[0] < low_high[1] <= 100:
            raise ValueError(f"depth_percentiles must be (low, high) in 0..100, got {low_high}")
        if self.depth_margin < 0:
            raise ValueError(f"depth_margin must be >= 0, got {self.depth_margin}")
        for name in ("num_disparities", "max_num_disparities"):
            if getattr(self, name) < 16:
                raise ValueError(f"{name} must be >= 16, got {getattr(self, name)}")


@dataclass(frozen=True)
class DepthMap:
    """Depth of every pixel of view ``view`` (an index into the views), from stereo with ``source``.

    ``depth`` (H, W) float32: z along the view's optical axis in world units at each pixel
    centre of the unrectified image, NaN where unknown.
    """

    view: int
    source: int
    depth: np.ndarray


# ---------------------------------------------------------------------------------------------
# Pair selection


def _point_ids(views: Sequence[View]) -> list[np.ndarray] | None:
    """Per view, (N,) an id for each sparse point row (equal rows, equal id); None if any lacks.

    COLMAP reports a 3D point with the same coordinates to every image that observes it, so
    equal rows identify the same point without the integrator passing point ids.
    """
    if any(v.points_in_world is None or len(v.points_in_world) == 0 for v in views):
        return None
    rows = [np.asarray(v.points_in_world, dtype=np.float64) for v in views]
    _, ids = np.unique(np.concatenate(rows), axis=0, return_inverse=True)
    bounds = np.cumsum([0] + [len(r) for r in rows])
    return [ids.ravel()[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles in degrees between vectors (..., 3) ``a`` and ``b``."""
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _axes_meeting_point(a: View, b: View) -> np.ndarray | None:
    """(3,) midpoint of the closest approach of two optical axes, if in front of both."""
    ca, cb = a.center_in_world, b.center_in_world
    da, db = a.axis_in_world, b.axis_in_world
    w = ca - cb
    dot = float(da @ db)
    denom = 1.0 - dot * dot
    if denom < 1e-9:  # parallel axes never meet
        return None
    sa = (dot * float(db @ w) - float(da @ w)) / denom
    sb = (float(db @ w) - dot * float(da @ w)) / denom
    if sa <= 0 or sb <= 0:
        return None
    return 0.5 * (ca + sa * da + cb + sb * db)


def select_pairs(views: Sequence[View], config: StereoConfig) -> list[tuple[int, int]]:
    """Stereo pairs (i, j), i < j, sorted: each view's best partners within the angle limits.

    With sparse points in every view, partners are ranked by the number of points both
    observe and the triangulation angle is the median over those points of the angle between
    the rays to the two camera centres. Without, partners are ranked by the angle between the
    optical axes and the triangulation angle is taken where the axes pass closest (the angle
    between the axes when they do not meet in front of both cameras). A partner must have a
    triangulation angle in [min, max] and a viewing angle at most ``max_viewing_angle_deg``.
    Each view picks up to ``max_pairs_per_view`` partners (ties broken by viewing angle, then
    index, so the result is deterministic); a pair picked by both of its views is listed once,
    and a view can be in more pairs than it picked. Every pair gives depth maps for both of its
    views (:func:`depths_from_pair`).
    """
    n = len(views)
    ids = _point_ids(views)
    centers = np.array([v.center_in_world for v in views]).reshape(n, 3)
    axes = np.array([v.axis_in_world for v in views]).reshape(n, 3)
    pairs: set[tuple[int, int]] = set()
    for i in range(n):
        # (score, viewing angle, index): ties broken by geometry, then by index.
        candidates: list[tuple[float, float, int]] = []
        for j in range(n):
            if j == i:
                continue
            viewing = float(_angle_deg(axes[i], axes[j]))
            if viewing > config.max_viewing_angle_deg:
                continue
            if ids is not None:
                shared = np.isin(ids[i], ids[j])
                if np.count_nonzero(shared) < config.min_shared_points:
                    continue
                points = np.asarray(views[i].points_in_world, dtype=np.float64)[shared]
                triangulation = float(
                    np.median(_angle_deg(centers[i] - points, centers[j] - points))
                )
                # Most shared points first (sort is ascending).
                score = -float(np.count_nonzero(shared))
            else:
                meet = _axes_meeting_point(views[i], views[j])
                triangulation = (
                    viewing
                    if meet is None
                    else float(_angle_deg(centers[i] - meet, centers[j] - meet))
                )
                score = viewing
            if (
                config.min_triangulation_angle_deg
                <= triangulation
                <= config.max_triangulation_angle_deg
            ):
                candidates.append((score, viewing, j))
        candidates.sort()
        for _, _, j in candidates[: config.max_pairs_per_view]:
            pairs.add((min(i, j), max(i, j)))
    return sorted(pairs)


# ---------------------------------------------------------------------------------------------
# Rectification


def _opencv_K(K: np.ndarray) -> np.ndarray:
    """(3, 3) ``K`` for OpenCV's integer pixel centres (COLMAP's are at +0.5)."""
    shifted = np.asarray(K, dtype=np.float64).copy()
    shifted[0, 2] -= 0.5
    shifted[1, 2] -= 0.5
    return shifted


def _image_corners(size: tuple[int, int]) -> np.ndarray:
    """(3, 4) homogeneous OpenCV coordinates of the outer corners of an image of (w, h)."""
    w, h = size
    return np.array([[-0.5, w - 0.5, w - 0.5, -0.5], [-0.5, -0.5, h - 0.5, h - 0.5], [1, 1, 1, 1]])


def _pixel_grid(size: tuple[int, int]) -> np.ndarray:
    """(3, H, W) homogeneous OpenCV coordinates (x, y, 1) of every pixel centre."""
    w, h = size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([xs, ys, np.ones_like(xs)])


@dataclass(frozen=True)
class _Rectification:
    """Both images of a pair on one rectified canvas: rows are epipolar lines, ref on the left.

    A scene point at rectified depth ``Z`` (along the common rectified optical axis) has canvas
    disparity ``x_ref - x_src = focal * baseline / Z - offset``, searched over
    ``[0, num_disparities)``.
    """

    ref_to_canvas: np.ndarray  # (3, 3) ref OpenCV pixel -> its canvas pixel
    src_to_canvas: np.ndarray  # (3, 3) src OpenCV pixel -> its canvas pixel
    canvas_size: tuple[int, int]  # (width, height) of both canvases
    focal: float  # rectified focal length in pixels
    baseline: float  # distance between the camera centres, world units
    offset: int  # smallest disparity searched
    num_disparities: int  # multiple of 16


def _rect_from_ref(ref: View, src: View) -> tuple[np.ndarray, float]:
    """(3, 3) rotation ref camera -> rectified frame whose +x points to src; the baseline."""
    R_ref, t_ref = ref.cam_from_world[:, :3], ref.cam_from_world[:, 3]
    R_src, t_src = src.cam_from_world[:, :3], src.cam_from_world[:, 3]
    R = R_src @ R_ref.T  # x_src = R x_ref + T
    T = t_src - R @ t_ref
    if not np.linalg.norm(T) > 0:  # one centre: no stereo (the caller gives up)
        return np.eye(3), 0.0
    # Only R1 is used (the canvas is ours), so alpha does not matter.
    R1, *_ = cv2.stereoRectify(
        _opencv_K(ref.K),
        np.zeros(5),
        _opencv_K(src.K),
        np.zeros(5),
        ref.size,
        R,
        T.reshape(3, 1),
        flags=cv2.CALIB_ZERO_DISPARITY,
        alpha=-1,
    )
    # stereoRectify aligns the baseline with +-x or +-y (whichever is closer); a rotation about
    # the optical axis turns it to +x, making src the right camera in every case.
    baseline_in_rect = R1 @ (-R.T @ T)
    angle = math.atan2(baseline_in_rect[1], baseline_in_rect[0])
    c, s = math.cos(angle), math.sin(angle)
    Rz = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ R1, float(np.linalg.norm(baseline_in_rect))


def _disparity_bounds(
    ref: View,
    src: View,
    rect_from_ref: np.ndarray,
    focal: float,
    baseline: float,
    config: StereoConfig,
) -> tuple[float, float]:
    """(smallest, largest) rectified disparity ``focal * baseline / Z`` worth searching."""
    K_inv = np.linalg.inv(_opencv_K(ref.K))
    # Rectified depth of a ref pixel at depth z is z * (rect_from_ref K^-1 p)_z; the factor is
    # affine in p, so its extremes over the image are at the corners.
    factors = (rect_from_ref @ K_inv @ _image_corners(ref.size))[2]
    z_near = z_far = None
    points = ref.points_in_world if ref.points_in_world is not None else src.points_in_world
    if points is not None and len(points) >= 10:
        R_ref, t_ref = ref.cam_from_world[:, :3], ref.cam_from_world[:, 3]
        z_rect = (np.asarray(points, dtype=np.float64) @ R_ref.T + t_ref) @ rect_from_ref[2]
        z_rect = z_rect[z_rect > 0]
        if len(z_rect) >= 10:
            low, high = np.percentile(z_rect, config.depth_percentiles)
            z_near = low / (1.0 + config.depth_margin)
            z_far = high * (1.0 + config.depth_margin)
    if config.min_depth is not None:
        z_near = config.min_depth * float(factors.min())
    if config.max_depth is not None:
        z_far = config.max_depth * float(factors.max())
    scale = focal * baseline
    d_min = 0.0 if z_far is None or z_far <= 0 else scale / z_far
    d_max = d_min + config.num_disparities if z_near is None or z_near <= 0 else scale / z_near
    return d_min, d_max


def _rectify(ref: View, src: View, config: StereoConfig) -> _Rectification | None:
    """The pair's canvas, or None when the images do not overlap on it."""
    rect_from_ref, baseline = _rect_from_ref(ref, src)
    if not (baseline > 0 and np.isfinite(rect_from_ref).all()):
        return None
    rect_from_world = rect_from_ref @ ref.cam_from_world[:, :3]
    rect_from_src = rect_from_world @ src.cam_from_world[:, :3].T
    K_ref, K_src = _opencv_K(ref.K), _opencv_K(src.K)
    focal = 0.5 * (K_ref[0, 0] + K_ref[1, 1])
    K0 = np.diag([focal, focal, 1.0])
    # Pixel -> rectified image coordinates without principal point (origin on the axis).
    G_ref = K0 @ rect_from_ref @ np.linalg.inv(K_ref)
    G_src = K0 @ rect_from_src @ np.linalg.inv(K_src)
    corners_ref = G_ref @ _image_corners(ref.size)
    corners_src = G_src @ _image_corners(src.size)
    # A corner ray more than ~80 degrees off the rectified axis: the pair is too oblique.
    if min(corners_ref[2].min(), corners_src[2].min()) < 0.2:
        return None
    xy_ref = corners_ref[:2] / corners_ref[2]
    xy_src = corners_src[:2] / corners_src[2]
    # Never let a strongly rotated pair blow up the canvas: at most twice the image around
    # the ref's centre.
    limit = 2.0 * max(ref.size)
    y0 = max(xy_ref[1].min(), xy_src[1].min(), -limit)
    y1 = min(xy_ref[1].max(), xy_src[1].max(), limit)
    a_ref, b_ref = max(xy_ref[0].min(), -limit), min(xy_ref[0].max(), limit)
    a_src, b_src = max(xy_src[0].min(), -limit), min(xy_src[0].max(), limit)

    d_min, d_max = _disparity_bounds(ref, src, rect_from_ref, focal, baseline, config)
    offset = math.floor(d_min)
    num = min(16 * math.ceil((d_max - offset + 1) / 16), config.max_num_disparities)
    num = max(num, 16)
    # Canvas columns x' = x + cx. Disparity on the canvas is d - offset when the src canvas has
    # cx_src = cx_ref + offset. SGBM leaves the first `num` columns of its left image unknown,
    # so the ref's first pixel that can have a match (max(a_ref, a_src + offset)) goes to
    # column num + 1; in the reverse pass (both canvases mirrored) the src's last pixel that
    # can have a match must stay `num` + 1 columns inside the right edge.
    first_ref = max(a_ref, a_src + offset)
    last_ref = min(b_ref, b_src + offset + num)
    last_src = min(b_src, b_ref - offset)
    if last_ref - first_ref < 8 or y1 - y0 < 8:
        return None
    cx_ref = num + 1 - first_ref
    cx_src = cx_ref + offset
    width = math.ceil(max(last_ref + cx_ref, last_src + cx_src + num + 1)) + 1
    height = math.ceil(y1 - y0)
    A_ref = np.array([[1.0, 0.0, cx_ref], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    A_src = np.array([[1.0, 0.0, cx_src], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    return _Rectification(
        ref_to_canvas=A_ref @ G_ref,
        src_to_canvas=A_src @ G_src,
        canvas_size=(width, height),
        focal=focal,
        baseline=baseline,
        offset=offset,
        num_disparities=num,
    )


# ---------------------------------------------------------------------------------------------
# Matching


def _matcher(config: StereoConfig, num_disparities: int, channels: int) -> cv2.StereoSGBM:
    area = config.block_size * config.block_size
    p1 = config.p1 if config.p1 is not None else 8 * channels * area
    p2 = config.p2 if config.p2 is not None else 4 * p1
    return cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=num_disparities,
        blockSize=config.block_size,
        P1=p1,
        P2=p2,
        # Our own left-right check uses a full second pass, which is stricter.
        disp12MaxDiff=-1,
        preFilterCap=63,
        uniquenessRatio=config.uniqueness_ratio,
        speckleWindowSize=config.speckle_window_size,
        speckleRange=config.speckle_range_px,
        mode=_CV_MODES[config.mode],
    )


def _disparity(matcher: cv2.StereoSGBM, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(H, W) float32 disparity of ``left`` in pixels, NaN where SGBM found none."""
    raw = matcher.compute(left, right)
    disparity = raw.astype(np.float32) * np.float32(1.0 / cv2.StereoMatcher_DISP_SCALE)
    disparity[raw < 0] = np.nan  # minDisparity is 0: SGBM marks unknown pixels with -16
    return disparity


def _cross_check(
    disparity: np.ndarray, other: np.ndarray, direction: int, max_diff: float
) -> np.ndarray:
    """``disparity`` (H, W) with NaN where the other image's disparity at the match differs.

    The match of column x is x - d in the right image (``direction`` -1, for the left
    image's disparities) or x + d in the left one (+1, for the right image's).
    """
    h, w = disparity.shape
    columns = np.arange(w, dtype=np.float32)[None, :] + direction * disparity
    match = np.rint(np.nan_to_num(columns, nan=-1.0)).astype(np.int64)
    inside = np.isfinite(disparity) & (match >= 0) & (match < w)
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    back = np.full_like(disparity, np.nan)
    back[inside] = other[rows[inside], match[inside]]
    keep = np.abs(disparity - back) <= max_diff  # False where either is NaN
    return np.where(keep, disparity, np.float32(np.nan))


def _to_view_grid(
    canvas_disparity: np.ndarray,
    view_to_canvas: np.ndarray,
    size: tuple[int, int],
    rect: _Rectification,
) -> np.ndarray:
    """(H, W) float32 depth of each pixel of a view from its canvas disparity (NaN: unknown)."""
    grid = _pixel_grid(size)
    q = np.einsum("ij,jhw->ihw", view_to_canvas, grid)
    map_x = (q[0] / q[2]).astype(np.float32)
    map_y = (q[1] / q[2]).astype(np.float32)
    # Bilinear interpolation keeps sub-pixel precision but would average across depth edges
    # (points floating between foreground and background): keep it only where it agrees with
    # the nearest canvas pixel. NaN neighbours propagate, so holes stay holes.
    linear = cv2.remap(
        canvas_disparity,
        map_x,
        map_y,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=float("nan"),
    )
    nearest = cv2.remap(
        canvas_disparity,
        map_x,
        map_y,
        cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=float("nan"),
    )
    disparity = linear.astype(np.float64) + rect.offset
    disparity[~(np.abs(linear - nearest) <= _MAX_INTERPOLATION_STEP_PX)] = np.nan
    disparity[disparity <= 0] = np.nan
    # Depth along the rectified axis, then along the view's own axis: a point at view depth z
    # on the ray of pixel p has rectified depth z * q_z (q = rect K^-1 p, and the canvas maps
    # only add a principal point, leaving the third coordinate alone).
    with np.errstate(invalid="ignore", divide="ignore"):
        depth = rect.focal * rect.baseline / disparity / q[2]
    return depth.astype(np.float32)


# Largest difference in disparity between bilinear and nearest-pixel sampling accepted when
# mapping disparities back to a view: larger means the 2x2 neighbourhood straddles a depth edge.
_MAX_INTERPOLATION_STEP_PX = 0.5
# Canvas disparities this close to the ends of the search range are rejected: the true value
# is likely outside the range and SGBM settled on its border.
_RANGE_BORDER_PX = 1.0


def _grey_or_colour(image_bgr: np.ndarray, use_color: bool) -> np.ndarray:
    return image_bgr if use_color else cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)


def depths_from_pair(
    ref: View, src: View, config: StereoConfig, *, ref_index: int, src_index: int
) -> tuple[DepthMap, DepthMap]:
    """Depth maps of both views of a pair: (ref's, src's), each on its own unrectified grid.

    One rectification and two SGBM passes (ref -> src and src -> ref) give both; each map
    keeps only disparities confirmed by the other pass within ``lr_max_diff_px``. Pixels
    outside the overlap, occluded in the other image or outside the searched depth range are
    NaN. A pair too oblique to rectify gives all-NaN maps.
    """
    nan_ref = np.full(ref.size[::-1], np.nan, dtype=np.float32)
    nan_src = np.full(src.size[::-1], np.nan, dtype=np.float32)
    rect = _rectify(ref, src, config)
    if rect is None:
        return DepthMap(ref_index, src_index, nan_ref), DepthMap(src_index, ref_index, nan_src)
    left = cv2.warpPerspective(
        _grey_or_colour(ref.image_bgr, config.use_color),
        rect.ref_to_canvas,
        rect.canvas_size,
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
    )
    right = cv2.warpPerspective(
        _grey_or_colour(src.image_bgr, config.use_color),
        rect.src_to_canvas,
        rect.canvas_size,
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
    )
    # Footprints: where each canvas shows its image (matches into the black border are void).
    inside_left = (
        cv2.warpPerspective(
            np.full(ref.size[::-1], 255, np.uint8),
            rect.ref_to_canvas,
            rect.canvas_size,
            flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
        )
        > 0
    )
    inside_right = (
        cv2.warpPerspective(
            np.full(src.size[::-1], 255, np.uint8),
            rect.src_to_canvas,
            rect.canvas_size,
            flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
        )
        > 0
    )
    matcher = _matcher(config, rect.num_disparities, 3 if config.use_color else 1)
    d_left = _disparity(matcher, left, right)
    # The right image's disparities: SGBM on both canvases mirrored, right one as the left.
    d_right = _disparity(matcher, right[:, ::-1].copy(), left[:, ::-1].copy())[:, ::-1]
    low, high = _RANGE_BORDER_PX, rect.num_disparities - 1 - _RANGE_BORDER_PX
    for d, inside in ((d_left, inside_left), (d_right, inside_right)):
        d[~inside | ~((d >= low) & (d <= high))] = np.nan
    if config.lr_max_diff_px is None:
        checked_left, checked_right = d_left, d_right
    else:
        checked_left = _cross_check(d_left, d_right, -1, config.lr_max_diff_px)
        checked_right = _cross_check(d_right, d_left, +1, config.lr_max_diff_px)
    depth_ref = _to_view_grid(checked_left, rect.ref_to_canvas, ref.size, rect)
    depth_src = _to_view_grid(checked_right, rect.src_to_canvas, src.size, rect)
    return DepthMap(ref_index, src_index, depth_ref), DepthMap(src_index, ref_index, depth_src)


# ---------------------------------------------------------------------------------------------
# Back-projection


def backproject_pixels(
    view: View, rows: np.ndarray, cols: np.ndarray, z: np.ndarray
) -> np.ndarray:
    """(N, 3) points_in_world at depths (N,) ``z`` (along the view's axis) through the centres
    of pixels (rows, cols) of ``view``."""
    pixels = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))])  # COLMAP centres
    rays_in_world = (view.cam_from_world[:, :3].T @ np.linalg.inv(view.K) @ pixels).T
    return rays_in_world * z[:, None].astype(np.float64) + view.center_in_world
