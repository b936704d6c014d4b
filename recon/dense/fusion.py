"""Depth-map fusion: multi-view consistency, then one coloured point cloud with oriented normals.

A two-view depth is a single measurement: wrong matches on repetitive or textureless patches
pass the left-right check when both directions make the same mistake. :func:`filter_consistent`
keeps a pixel's depth only when the depth maps of at least ``min_consistent_views`` other
views agree with it: its 3D point is projected into each other view and compared with that
view's depth there, within a relative tolerance. The check is visibility-aware in the sense
that matters: a point lying *behind* the surface another view sees is occluded there, so that
view neither supports nor refutes it (only agreement is counted). The other depth map of the
same stereo pair is not independent evidence (the left-right check made the two agree) and is
never counted.

:func:`fuse` back-projects the kept pixels with their colours (thesis §5.3.5), merges them on a
voxel grid (which also merges the duplicates that overlapping views produce), estimates normals
from the neighbourhood and turns each towards the cameras that saw its points: screened Poisson
needs consistently oriented normals, and the mean viewing direction of a voxel's points is a
reliable outside.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from recon.dense.stereo import DepthMap, View, backproject_pixels

if TYPE_CHECKING:
    import open3d

__all__ = ["FusionConfig", "filter_consistent", "fuse"]


@dataclass(frozen=True, kw_only=True)
class FusionConfig:
    """Consistency filtering and point-cloud building of the cpu-stereo backend."""

    min_consistent_views: int = field(
        default=2,
        metadata={
            "help": "a depth is kept when the depth maps of at least this many other "
            "views agree with it (its own stereo partner's map from the same pair does "
            "not count)"
        },
    )
    rel_depth_tol: float = field(
        default=0.01,
        metadata={"help": "depths agree when they differ by at most this fraction"},
    )
    voxel_size: float | None = field(
        default=None,
        metadata={
            "help": "merge points on a grid of this size, world units (default: "
            "auto_voxel_fraction of the scene's extent)"
        },
    )
    auto_voxel_fraction: float = field(
        default=0.002,
        metadata={
            "help": "automatic voxel size as a fraction of the extent of the points "
            "(the diagonal of their 2nd-98th percentile box)"
        },
    )
    normal_radius: float | None = field(
        default=None,
        metadata={
            "help": "neighbourhood radius for normal estimation, world units (default: 3 voxels)"
        },
    )
    normal_max_nn: int = field(
        default=30, metadata={"help": "at most this many neighbours for a normal"}
    )

    def __post_init__(self) -> None:
        if self.min_consistent_views < 0:
            raise ValueError(f"min_consistent_views must be >= 0, got {self.min_consistent_views}")
        if not 0 < self.rel_depth_tol < 1:
            raise ValueError(f"rel_depth_tol must be in (0, 1), got {self.rel_depth_tol}")
        for name in ("voxel_size", "normal_radius"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite, got {value}")
        if not 0 < self.auto_voxel_fraction < 1:
            raise ValueError(
                f"auto_voxel_fraction must be in (0, 1), got {self.auto_voxel_fraction}"
            )
        if self.normal_max_nn < 3:
            raise ValueError(f"normal_max_nn must be >= 3, got {self.normal_max_nn}")


def _same_pair(a: DepthMap, b: DepthMap) -> bool:
    return {a.view, a.source} == {b.view, b.source}


def _depth_in(
    points_in_world: np.ndarray, view: View, depth: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """((N,) depth of each point in ``view``, (N,) ``depth`` (H, W) at its pixel, NaN outside)."""
    R, t = view.cam_from_world[:, :3], view.cam_from_world[:, 3]
    points_in_cam = points_in_world @ R.T + t
    z = points_in_cam[:, 2]
    h, w = depth.shape
    with np.errstate(invalid="ignore", divide="ignore"):
        projected = points_in_cam @ view.K.T
        # COLMAP coordinates: the pixel whose square [i, i + 1) contains the projection.
        col = np.floor(projected[:, 0] / projected[:, 2])
        row = np.floor(projected[:, 1] / projected[:, 2])
    inside = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    sampled = np.full(len(z), np.nan, dtype=np.float64)
    sampled[inside] = depth[row[inside].astype(np.intp), col[inside].astype(np.intp)]
    return z, sampled


def _consistent(
    own: DepthMap,
    rows: np.ndarray,
    cols: np.ndarray,
    by_view: dict[int, list[DepthMap]],
    views: Sequence[View],
    config: FusionConfig,
) -> np.ndarray:
    """(N,) whether pixels (rows, cols) of ``own`` have enough support from other views."""
    needed = config.min_consistent_views
    if needed == 0 or len(rows) == 0:
        return np.ones(len(rows), dtype=bool)
    view = views[own.view]
    points = backproject_pixels(view, rows, cols, own.depth[rows, cols])
    support = np.zeros(len(points), dtype=np.int32)
    pending = np.arange(len(points))
    axis = view.axis_in_world
    others = sorted(
        (w for w in by_view if w != own.view),
        key=lambda w: (-float(views[w].axis_in_world @ axis), w),
    )
    for position, w in enumerate(others):
        if len(pending) == 0:
            break
        agrees = np.zeros(len(pending), dtype=bool)
        for other in by_view[w]:
            if _same_pair(own, other):
                continue
            z, sampled = _depth_in(points[pending], views[w], other.depth)
            agrees |= np.abs(z - sampled) <= config.rel_depth_tol * sampled  # NaN: False
        support[pending] += agrees
        # Stop testing a pixel once it has enough support, or cannot get it any more.
        left = len(others) - position - 1
        count = support[pending]
        pending = pending[(count < needed) & (count + left >= needed)]
    return support >= needed


def _views_of(depths: Sequence[DepthMap]) -> dict[int, list[DepthMap]]:
    by_view: dict[int, list[DepthMap]] = {}
    for d in depths:
        by_view.setdefault(d.view, []).append(d)
    return by_view


def filter_consistent(
    depths: Sequence[DepthMap], views: Sequence[View], config: FusionConfig
) -> list[DepthMap]:
    """The depth maps with NaN where fewer than ``min_consistent_views`` other views agree.

    A view supports a pixel's depth when one of its depth maps (not from the same stereo pair)
    has, at the pixel the 3D point projects to, a depth within ``rel_depth_tol`` of the
    point's depth in that view. Other views are visited closest viewing direction first and a
    pixel stops being tested once it has enough support, so the cost falls quickly.
    """
    by_view = _views_of(depths)
    kept: list[DepthMap] = []
    for own in depths:
        depth = own.depth.copy()
        rows, cols = np.nonzero(np.isfinite(depth))
        reject = ~_consistent(own, rows, cols, by_view, views, config)
        depth[rows[reject], cols[reject]] = np.nan
        kept.append(DepthMap(own.view, own.source, depth))
    return kept


# Points sampled per depth map to measure the scene's extent for the automatic voxel size.
_EXTENT_SAMPLES = 20000


def _auto_voxel_size(
    depths: Sequence[DepthMap], views: Sequence[View], config: FusionConfig
) -> float | None:
    """``auto_voxel_fraction`` of the diagonal of the 2nd-98th percentile box of the points.

    Measured on a sample of consistent pixels: raw depth maps carry outliers far beyond the
    scene that would inflate it (2.5x on fountain-P11). None when no pixel is consistent.
    """
    by_view = _views_of(depths)
    samples: list[np.ndarray] = []
    for d in depths:
        rows, cols = np.nonzero(np.isfinite(d.depth))
        pick = np.linspace(0, len(rows) - 1, min(len(rows), _EXTENT_SAMPLES)).astype(np.intp)
        rows, cols = rows[pick], cols[pick]
        keep = _consistent(d, rows, cols, by_view, views, config)
        rows, cols = rows[keep], cols[keep]
        samples.append(backproject_pixels(views[d.view], rows, cols, d.depth[rows, cols]))
    points = np.concatenate(samples) if samples else np.zeros((0, 3))
    if len(points) == 0:
        return None
    low, high = np.percentile(points, [2.0, 98.0], axis=0)
    return max(float(np.linalg.norm(high - low)) * config.auto_voxel_fraction, 1e-12)


def _pixel_stride(depths: Sequence[DepthMap], view: View, voxel: float) -> int:
    """Pixel step for a view such that each voxel still gets about one sample of it.

    Back-projecting every pixel when a voxel spans many of them costs time and memory in
    every later step for nothing: the voxel merge averages them into one point anyway.
    """
    z = np.concatenate([d.depth[np.isfinite(d.depth)] for d in depths])
    if len(z) == 0:
        return 1
    footprint = float(np.median(z)) / (0.5 * (view.K[0, 0] + view.K[1, 1]))
    return int(np.clip(math.floor(voxel / footprint), 1, _MAX_STRIDE))


_MAX_STRIDE = 8


def fuse(
    depths: Sequence[DepthMap], views: Sequence[View], config: FusionConfig
) -> open3d.geometry.PointCloud:
    """One point cloud from the depth maps: consistent pixels, coloured, voxel-merged.

    Works like :func:`filter_consistent` followed by back-projection, but only on the pixels
    it needs: where a voxel spans several pixels, every ``stride``-th pixel of each view, so
    that each voxel still gets about one sample per view (overlapping views add more). The
    kept depths of one view (one per stereo partner) are averaged per pixel. Points carry RGB
    colours (float in [0, 1], from their own pixels, thesis §5.3.5) and unit normals oriented
    towards the cameras that saw them (the sign follows the mean direction from the voxel's
    points to their cameras). Empty when no pixel survives.
    """
    import open3d as o3d  # heavy import: only when fusing

    cloud = o3d.geometry.PointCloud()
    voxel = config.voxel_size or _auto_voxel_size(depths, views, config)
    if voxel is None:
        return cloud
    by_view = _views_of(depths)
    chunks_points: list[np.ndarray] = []
    chunks_colours: list[np.ndarray] = []
    chunks_towards: list[np.ndarray] = []
    for index, maps in sorted(by_view.items()):
        view = views[index]
        stride = _pixel_stride(maps, view, voxel)
        total = np.zeros(maps[0].depth[::stride, ::stride].shape, dtype=np.float64)
        count = np.zeros(total.shape, dtype=np.int32)
        for own in maps:
            rows, cols = np.nonzero(np.isfinite(own.depth[::stride, ::stride]))
            keep = _consistent(own, rows * stride, cols * stride, by_view, views, config)
            rows, cols = rows[keep], cols[keep]
            total[rows, cols] += own.depth[rows * stride, cols * stride]
            count[rows, cols] += 1
        rows, cols = np.nonzero(count)
        if len(rows) == 0:
            continue
        rows_full, cols_full = rows * stride, cols * stride
        points = backproject_pixels(
            view, rows_full, cols_full, total[rows, cols] / count[rows, cols]
        )
        towards = view.center_in_world - points
        towards /= np.linalg.norm(towards, axis=1, keepdims=True)
        chunks_points.append(points)
        chunks_colours.append(view.image_bgr[rows_full, cols_full][:, ::-1])
        chunks_towards.append(towards)
    if not chunks_points:
        return cloud
    cloud.points = o3d.utility.Vector3dVector(np.concatenate(chunks_points))
    cloud.colors = o3d.utility.Vector3dVector(np.concatenate(chunks_colours) / 255.0)
    # The normals slot carries the direction to the camera through the voxel merge (which
    # averages it), then orients the estimated normals. Open3D's estimate_normals already
    # keeps the sign of normals present before it; the explicit flip below does not rely on it.
    cloud.normals = o3d.utility.Vector3dVector(np.concatenate(chunks_towards))
    cloud = cloud.voxel_down_sample(voxel)
    towards = np.asarray(cloud.normals).copy()
    radius = config.normal_radius or 3.0 * voxel
    cloud.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=config.normal_max_nn)
    )
    normals = np.asarray(cloud.normals)
    flip = np.sum(normals * towards, axis=1) < 0
    normals[flip] *= -1.0
    cloud.normals = o3d.utility.Vector3dVector(normals)
    return cloud
