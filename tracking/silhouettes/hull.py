"""Visual hulls on a voxel grid, and the multi-view consistency of silhouettes built on them.

A voxel is inside a view's silhouette cone when its centre projects into the silhouette. The
*visual hull* of a set of calibrated silhouettes is the set of voxels inside every cone (Laurentini
1994). Two uses:

* :func:`visual_hull` gives the tracker its first guess of the body (`tracking.track.tracker`).
* :func:`consistent_silhouettes` keeps, in each view, only the silhouette pixels that the other
  views confirm: the pixels under the projection of the hull. A foreground blob that only one
  camera sees (a reflection on the floor, a person in one camera's background photo, a
  background that changed behind one camera) has no 3D point inside the other views'
  silhouettes and goes; the subject, seen by all, stays. This is the silhouette-consistency
  test of multi-view segmentation (e.g. Campbell et al., "Automatic object segmentation from
  calibrated images", 2011), here with a tolerance: every silhouette is dilated before the
  carving, so a body part that one view segments a few pixels too thin is not cut from the
  others.

A voxel that projects outside a view's image (or its content box, see
`tracking.rig.video.content_box`) is not carved by that view: a subject leaving one camera's field
of view stays in the others. Views whose silhouette is empty take no part in the carving. For
the check a voxel must be seen by all the views but one (at least two): with fewer, a blob seen
by one camera could be "confirmed" by a single other camera whose silhouette happens to lie
along the same rays (on the Pose2Sim demo, reflections on a mat in front of one camera, rays
that only one other camera sees, through the subject's silhouette in it).

Pure numpy and OpenCV; no I/O.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from recon.cameras import Camera
from recon.errors import UserError

Box = tuple[int, int, int, int]
"""(x0, y0, x1, y1), end exclusive: the part of an image that holds the picture."""


def rays_meeting_point(cameras: Sequence[Camera], masks: Sequence[np.ndarray]) -> np.ndarray:
    """Least-squares meeting point (3,) of the rays through every non-empty silhouette's
    centroid, world frame; ValueError when fewer than two silhouettes have pixels."""
    a, b = np.zeros((3, 3)), np.zeros(3)
    used = 0
    for cam, mask in zip(cameras, masks, strict=True):
        rows, cols = np.nonzero(mask)
        if len(rows) == 0:
            continue
        # Pixel centres are at +0.5 (the convention of `tracking.rig.cameras`).
        pixel = np.array([cols.mean() + 0.5, rows.mean() + 0.5, 1.0])
        xy = cam.undistort((np.linalg.solve(cam.K, pixel)[:2])[None])  # normalised
        direction = cam.R.T @ np.array([xy[0, 0], xy[0, 1], 1.0])
        direction /= np.linalg.norm(direction)
        proj = np.eye(3) - np.outer(direction, direction)
        a += proj
        b += proj @ cam.center_in_world
        used += 1
    if used < 2:
        empty = [c.name for c, m in zip(cameras, masks, strict=True) if not m.any()]
        raise ValueError(f"empty silhouette in {', '.join(empty)}")
    return np.linalg.solve(a, b)


def check_voxel_grid(size_m: float, voxel_m: float, size_flag: str, voxel_flag: str) -> None:
    """One-line errors (naming the flags) for a cube of side `size_m` and voxels of `voxel_m`
    (> 0) that :func:`voxel_centres` cannot make: under two voxels, over 64 million."""
    if not size_m > 2 * voxel_m:
        raise UserError(f"{size_flag} {size_m} must exceed two voxels ({voxel_flag} {voxel_m})")
    if (size_m / voxel_m) ** 3 > 64e6:
        raise UserError(f"{size_flag} {size_m} / {voxel_flag} {voxel_m}: more than 64 million "
                        "voxels")


def voxel_centres(centre: np.ndarray, size_m: float, voxel_m: float) -> tuple[np.ndarray, int]:
    """((n**3, 3) centres, n) of the cube of side ``size_m`` around ``centre``, ``voxel_m``
    apart, in C order over (x, y, z)."""
    grid, n = _centred_grid(size_m, voxel_m)
    return grid + np.asarray(centre, dtype=float), n


@functools.lru_cache(maxsize=4)
def _centred_grid(size_m: float, voxel_m: float) -> tuple[np.ndarray, int]:
    """`voxel_centres` around the origin, made once per cube: the tracker carves a
    hull every frame, and making this grid took a quarter of the carving's time."""
    n = int(np.ceil(size_m / voxel_m))
    axis = (np.arange(n) - (n - 1) / 2) * voxel_m
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    grid.flags.writeable = False
    return grid, n


_BLOCK = 4
"""Voxels per side of the blocks :func:`hull_candidates` tests before the voxels themselves."""


def hull_candidates(cameras: Sequence[Camera], masks: Sequence[np.ndarray], centre: np.ndarray,
                    size_m: float, voxel_m: float, *, dilate_px: int = 0,
                    boxes: Sequence[Box | None] | None = None, min_views: int | None = None,
                    unknown: Sequence[np.ndarray | None] | None = None, misses: int = 0,
                    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(points (M, 3), index (M,)): the voxels of :func:`voxel_centres`' cube (``index`` into
    its C order, increasing) that :func:`carve`, with the same arguments, could keep; every
    other voxel it would carve away.

    Coarse to fine: the cube is cut into blocks of ``_BLOCK``³ voxels, and a block goes when
    more than ``misses`` views each see the whole of it and its projection lies farther from
    the view's (dilated) silhouette than the block's projected radius (a distance transform
    per view), or when fewer views than ``min_views`` can see any of it, less those that
    rejected it. The test is conservative (the radius is bounded off the axis, enlarged by a
    quarter for the distortion and by 2 px for the pixel grid), so that carving
    the candidates gives the very hull the whole cube gives, in about a hundredth of the
    projections (a body fills ~1% of a 3 m cube)."""
    n = int(np.ceil(size_m / voxel_m))
    axis = (np.arange(n) - (n - 1) / 2) * voxel_m
    first = np.arange(0, n, _BLOCK)
    last = np.minimum(first + _BLOCK, n) - 1
    centre = np.asarray(centre, dtype=float)
    block_axis = (axis[first] + axis[last]) / 2
    blocks = np.stack(np.meshgrid(block_axis, block_axis, block_axis, indexing="ij"),
                      -1).reshape(-1, 3) + centre
    reach_m = math.sqrt(3) * float((axis[last] - axis[first]).max()) / 2
    masks = _with_unknown(masks, unknown)
    boxes = list(boxes) if boxes is not None else [None] * len(cameras)
    rejected = np.zeros(len(blocks), np.int32)
    may_see = np.zeros(len(blocks), np.int32)
    views = 0
    for cam, mask, box in zip(cameras, masks, boxes, strict=True):
        mask = np.asarray(mask, bool)
        if not mask.any():
            continue
        views += 1
        x0, y0, x1, y1 = box if box is not None else (0, 0, cam.width, cam.height)
        if dilate_px > 1:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (dilate_px, dilate_px))
            mask = cv2.dilate(mask.astype(np.uint8), disc).astype(bool)
        uv, depth = cam.project(blocks)
        in_cam = blocks @ cam.R.T + cam.t
        near = depth - reach_m
        with np.errstate(divide="ignore", invalid="ignore"):
            # How far off-axis the block reaches (normalised radius), and the largest shift
            # of a voxel's pixel from the block centre's: f d / z, times sqrt(1 + r^2) off the
            # axis, times 1.25 for the distortion's local magnification, plus the pixel grid.
            spread = np.sqrt((in_cam[:, :2] ** 2).sum(axis=1)) / depth + reach_m / near
            radius = (1.25 * float(np.abs(cam.K[:2, :2]).max()) * reach_m / near
                      * np.sqrt(1.0 + spread**2) + 2.0)
            whole = ((near > 0) & (spread**2 < cam.max_radius2) & (uv[:, 0] - radius >= x0)
                     & (uv[:, 0] + radius < x1) & (uv[:, 1] - radius >= y0)
                     & (uv[:, 1] + radius < y1))
            # Some voxel may be seen: in front, and the block's disc meets the box.
            partly = ((depth + reach_m > 0) & ~((near > 0) & ((uv[:, 0] + radius < x0)
                      | (uv[:, 0] - radius >= x1) | (uv[:, 1] + radius < y0)
                      | (uv[:, 1] - radius >= y1))))  # fmt: skip
        col = np.where(whole, uv[:, 0], 0).astype(np.int64)
        row = np.where(whole, uv[:, 1], 0).astype(np.int64)
        rejected += whole & (_silhouette_distance(mask, row, col, radius, whole) > radius)
        may_see += partly
    enough = may_see - rejected >= max(2, views if min_views is None else min_views)
    keep = (rejected <= misses) & enough
    nb = len(first)
    bi, bj, bk = np.unravel_index(np.flatnonzero(keep), (nb, nb, nb))
    offsets = np.stack(np.meshgrid(*[np.arange(_BLOCK)] * 3, indexing="ij"), -1).reshape(-1, 3)
    fine = (np.stack([bi, bj, bk], -1)[:, None, :] * _BLOCK + offsets[None]).reshape(-1, 3)
    fine = fine[(fine < n).all(axis=1)]
    index = np.sort((fine[:, 0] * n + fine[:, 1]) * n + fine[:, 2])
    i, j, k = np.unravel_index(index, (n, n, n))
    return np.stack([axis[i], axis[j], axis[k]], -1) + centre, index


def _silhouette_distance(mask: np.ndarray, row: np.ndarray, col: np.ndarray,
                         radius: np.ndarray, tested: np.ndarray) -> np.ndarray:  # fmt: skip
    """(N,) the distance from pixel (row, col) to the nearest pixel of ``mask`` (0 on it), where
    it matters: for the ``tested`` pixels, as far as their ``radius``; inf where it is farther.
    The exact distance transform of the silhouette's bounding box widened by the largest
    tested radius only (a body fills a tenth of a frame, so about a fifth of the full
    transform's 3 ms at 640x480): every silhouette pixel is in that box, so the distances in
    it are the full image's, and a pixel out of it is farther than any radius tested."""
    out = np.full(len(row), np.inf)
    if not tested.any():
        return out
    reach = int(np.ceil(np.max(radius[tested]))) + 1
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    y0, y1 = max(rows[0] - reach, 0), min(rows[-1] + reach + 1, mask.shape[0])
    x0, x1 = max(cols[0] - reach, 0), min(cols[-1] + reach + 1, mask.shape[1])
    distance = cv2.distanceTransform((~mask[y0:y1, x0:x1]).astype(np.uint8), cv2.DIST_L2,
                                     cv2.DIST_MASK_PRECISE)  # fmt: skip
    inside = tested & (row >= y0) & (row < y1) & (col >= x0) & (col < x1)
    out[inside] = distance[row[inside] - y0, col[inside] - x0]
    return out


@dataclass(frozen=True)
class Projection:
    """Where a view sees the voxels: integer pixel (col, row), depth, and ``seen`` (in front of
    the camera, inside the undistortable field and the image's content box)."""

    col: np.ndarray
    row: np.ndarray
    depth: np.ndarray
    seen: np.ndarray


def project_voxels(camera: Camera, points: np.ndarray, box: Box | None = None) -> Projection:
    """The pixels of (N, 3) world points in ``camera`` (pixel (i, j) covers [i, i+1) x
    [j, j+1)), ``seen`` only within ``box`` (default: the whole image)."""
    x0, y0, x1, y1 = box if box is not None else (0, 0, camera.width, camera.height)
    uv, depth = camera.project(points)
    in_cam = points @ camera.R.T + camera.t
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = ((in_cam[:, :2] / in_cam[:, 2:3]) ** 2).sum(axis=1)
        # Beyond the distortion's fold-back radius a far point could land inside the image.
        seen = (depth > 0) & (r2 < camera.max_radius2)
        col = np.floor(uv[:, 0])
        row = np.floor(uv[:, 1])
        seen &= (col >= x0) & (col < x1) & (row >= y0) & (row < y1)
    col = np.where(seen, col, 0).astype(np.int64)
    row = np.where(seen, row, 0).astype(np.int64)
    return Projection(col, row, depth, seen)


def carve(cameras: Sequence[Camera], masks: Sequence[np.ndarray], points: np.ndarray, *,
          dilate_px: int = 0, boxes: Sequence[Box | None] | None = None,
          min_views: int | None = None, unknown: Sequence[np.ndarray | None] | None = None,
          misses: int = 0) -> tuple[np.ndarray, list[Projection]]:  # fmt: skip
    """(N,) bool: the voxels (N, 3) inside the visual hull of the non-empty ``masks``, each
    dilated by a disc of ``dilate_px`` pixels first (0: exact); and each view's projection.

    A voxel is kept when every non-empty view that sees it (:func:`project_voxels`) has it in
    its silhouette, but for at most ``misses`` of them, and at least ``min_views`` views have
    it in their silhouette (default: all the non-empty
    views; never fewer than two). ``unknown``: per view, None or (H, W) bool pixels whose
    label the view cannot tell: they count as silhouette (they do not carve).
    """
    masks = _with_unknown(masks, unknown)
    boxes = list(boxes) if boxes is not None else [None] * len(cameras)
    outside = np.zeros(len(points), np.int32)
    seen_by = np.zeros(len(points), np.int32)
    projections = []
    for cam, mask, box in zip(cameras, masks, boxes, strict=True):
        proj = project_voxels(cam, points, box)
        projections.append(proj)
        if not mask.any():
            continue
        if dilate_px > 1:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (dilate_px, dilate_px))
            mask = cv2.dilate(mask.astype(np.uint8), disc).astype(bool)
        hit = mask[proj.row, proj.col] & proj.seen
        outside += proj.seen & ~hit
        seen_by += proj.seen
    views = sum(bool(m.any()) for m in masks)
    enough = seen_by - outside >= max(2, views if min_views is None else min_views)
    return (outside <= misses) & enough, projections


def _with_unknown(masks: Sequence[np.ndarray], unknown: Sequence[np.ndarray | None] | None
                  ) -> Sequence[np.ndarray]:  # fmt: skip
    """Each mask with its view's unknown pixels added (they do not carve)."""
    if unknown is None:
        return masks
    return [m if u is None else m | u for m, u in zip(masks, unknown, strict=True)]


def visual_hull(cameras: Sequence[Camera], masks: Sequence[np.ndarray], *, size_m: float,
                voxel_m: float, unknown: Sequence[np.ndarray | None] | None = None,
                min_views: int | None = None) -> tuple[np.ndarray, int, np.ndarray]:
    """(centres (n**3, 3), n, occupied (n**3,) bool): the exact visual hull on a cube of side
    ``size_m`` around the point where the centroid rays of the silhouettes and their unknown
    pixels meet (``unknown``, ``min_views``: as in :func:`carve`; by default every view with a
    silhouette must see a voxel, see :func:`hull_min_views`)."""
    centre, occupied = _carved(cameras, masks, size_m, voxel_m, unknown, min_views)
    points, n = voxel_centres(centre, size_m, voxel_m)
    return points, n, occupied


def hull_surface_points(cameras: Sequence[Camera], masks: Sequence[np.ndarray], *,
                        size_m: float, voxel_m: float,
                        unknown: Sequence[np.ndarray | None] | None = None,
                        min_views: int | None = None) -> np.ndarray:  # fmt: skip
    """(N, 3) centres of the surface voxels (:func:`surface_voxels`) of :func:`visual_hull`,
    the same floats, without the whole cube's centres (16 MB for the tracker's 87**3 voxels,
    a fifth of a frame's hull)."""
    centre, occupied = _carved(cameras, masks, size_m, voxel_m, unknown, min_views)
    grid, n = _centred_grid(size_m, voxel_m)
    return grid[surface_voxels(occupied, n)] + centre


def _carved(cameras: Sequence[Camera], masks: Sequence[np.ndarray], size_m: float,
            voxel_m: float, unknown: Sequence[np.ndarray | None] | None,
            min_views: int | None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(centre (3,), occupied (n**3,) bool) of :func:`visual_hull`."""
    centre = rays_meeting_point(cameras, _with_unknown(masks, unknown))
    n = _centred_grid(size_m, voxel_m)[1]
    candidates, index = hull_candidates(cameras, masks, centre, size_m, voxel_m,
                                        unknown=unknown, min_views=min_views)
    occupied = np.zeros(n**3, bool)
    occupied[index] = carve(cameras, masks, candidates, unknown=unknown,
                            min_views=min_views)[0]
    return centre, occupied


def cut_by_border(masks: Sequence[np.ndarray]) -> list[int]:
    """Indices of the views whose silhouette touches its image's border: the subject is partly
    outside that view (or a background blob reaches the edge)."""
    out = []
    for k, mask in enumerate(masks):
        mask = np.asarray(mask, bool)
        if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
            out.append(k)
    return out


def hull_min_views(masks: Sequence[np.ndarray]) -> int | None:
    """``min_views`` for :func:`visual_hull` of a subject: None (every view with a silhouette)
    unless a silhouette touches its image border, then all those views but one (at least two).
    A view cannot carve what lies outside its image, and demanding it see every voxel cuts
    from the hull what is out of its image (a head out of one of 4 views: the hull 0.55 m short,
    the start 1.55 m tall for 1.75 and 223 mm off). One view less keeps it, and no more: a
    voxel out of one view's image must lie inside all the other cones, which two opposite
    views alone do not make (their cones meet along a line other views see across)."""
    views = sum(bool(np.asarray(m).any()) for m in masks)
    if views < 3 or not cut_by_border(masks):
        return None
    return views - 1


@dataclass(frozen=True)
class HullPart:
    """A connected part of a visual hull (26-neighbours): its volume (m^3), its extent along
    the rig's up (m; along its longest side when the rig gives no up) and its centre (3,)."""

    volume_m3: float
    height_m: float
    centre: np.ndarray


SUBJECT_MIN_HEIGHT_M = 0.8
"""A hull part this tall (along up) and ...  """
SUBJECT_MIN_VOLUME_M3 = 0.02
"""... this large is of human size: a standing or walking adult's hull is 1.5-1.9 m tall and
0.07-0.2 m^3 (fatter than the body with few views); a child of 1 m or a crouching adult
passes too. A hand or a foot cut off by a view (a few litres) and the slivers that few views
leave around one body do not."""


def hull_parts(cameras: Sequence[Camera], masks: Sequence[np.ndarray], *, size_m: float,
               voxel_m: float, up: np.ndarray | None = None,
               unknown: Sequence[np.ndarray | None] | None = None,
               min_views: int | None = None) -> list[HullPart]:
    """The connected parts of the visual hull of ``masks`` (:func:`visual_hull` on a cube of
    side ``size_m``), largest first. One subject makes one part (its silhouettes are connected
    in every view); two subjects apart make two or more (each, and the ghosts where the rays
    of the one meet those of the other). Empty when fewer than two views have a silhouette."""
    from scipy import ndimage

    if sum(bool(np.asarray(m).any()) for m in masks) < 2:
        return []
    centre, occupied = _carved(cameras, masks, size_m, voxel_m, unknown, min_views)
    grid, n = _centred_grid(size_m, voxel_m)
    labels, count = ndimage.label(occupied.reshape(n, n, n), np.ones((3, 3, 3), bool))
    labels = labels.ravel()
    parts = []
    for label in range(1, count + 1):
        inside = grid[labels == label] + centre  # `visual_hull`'s centres, the same floats
        if up is not None:
            height = float(np.ptp(inside @ np.asarray(up, float))) + voxel_m
        else:
            height = float(np.ptp(inside, axis=0).max()) + voxel_m
        parts.append(HullPart(len(inside) * voxel_m**3, height, inside.mean(axis=0)))
    return sorted(parts, key=lambda p: -p.volume_m3)


def subject_sized(parts: Sequence[HullPart]) -> list[HullPart]:
    """The parts of human size (`SUBJECT_MIN_HEIGHT_M`, `SUBJECT_MIN_VOLUME_M3`)."""
    return [p for p in parts
            if p.height_m >= SUBJECT_MIN_HEIGHT_M and p.volume_m3 >= SUBJECT_MIN_VOLUME_M3]


def hull_diameter(points: np.ndarray) -> float:
    """The largest distance between two of the (N, 3) points (metres): the longest extent of
    a visual hull in any direction, its height when the subject stands, and the reach of a
    body bent over or lying, whose extent along up is far below its height."""
    points = np.asarray(points, float)
    if len(points) < 2:
        return 0.0
    try:
        from scipy.spatial import ConvexHull, QhullError

        points = points[ConvexHull(points).vertices]  # the farthest pair is on the hull
    except (QhullError, ValueError):  # flat or too few points: all of them
        pass
    gaps = points[:, None] - points[None]
    return float(np.sqrt(np.max(np.einsum("ijk,ijk->ij", gaps, gaps))))


def surface_voxels(occupied: np.ndarray, n: int) -> np.ndarray:
    """(n**3,) bool: occupied voxels with at least one empty 6-neighbour."""
    occupied = occupied.reshape(n, n, n)
    padded = np.pad(occupied, 1)
    interior = occupied.copy()
    for axis in range(3):
        for shift in (-1, 1):
            interior &= np.roll(padded, shift, axis=axis)[1:-1, 1:-1, 1:-1]
    return (occupied & ~interior).ravel()


# Multi-view consistency of silhouettes -----------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class HullCheckConfig:
    """Settings of :func:`consistent_silhouettes`. Field help is the CLI's help."""

    multi_view_check: bool = field(
        default=True,
        metadata={"help": "keep only the silhouette pixels the other cameras confirm: under the "
                  "projection of the visual hull of all views (removes what one camera alone "
                  "sees: reflections, people in a background photo, a changed background)"},
    )  # fmt: skip
    check_tolerance: float = field(
        default=0.01,
        metadata={"help": "silhouettes are dilated by this fraction of the image's larger side "
                  "before the carving, so that a part one view segments too thin is kept"},
    )  # fmt: skip
    check_misses: int = field(
        default=0,
        metadata={"help": "views that may see a voxel of the consistency hull outside their "
                  "silhouette (at most the views with a silhouette less two): with 1, a part "
                  "one camera loses (the subject in its median background, a limb the colour "
                  "of the wall) stays in the others, but more of a blob attached to the "
                  "subject in one view stays too"},
    )  # fmt: skip
    check_voxel_m: float = field(
        default=0.03, metadata={"help": "voxel size of the consistency hull, metres"})
    check_size_m: float = field(
        default=3.0,
        metadata={"help": "side of the cube, centred where the views' silhouettes meet, in "
                  "which the consistency hull is carved, metres: silhouette parts outside "
                  "it are removed"},
    )  # fmt: skip

    def __post_init__(self) -> None:
        if not 0 <= self.check_tolerance < 0.5:
            raise UserError(f"--check-tolerance must be in [0, 0.5), got {self.check_tolerance}")
        if self.check_misses < 0:
            raise UserError(f"--check-misses must be >= 0, got {self.check_misses}")
        if not self.check_voxel_m > 0:
            raise UserError(f"--check-voxel-m must be > 0, got {self.check_voxel_m}")
        check_voxel_grid(self.check_size_m, self.check_voxel_m, "--check-size-m",
                         "--check-voxel-m")


_SPLAT_DOWNSCALE = 4
"""The hull is splatted into each view at up to 1/4 of its size, then scaled up (voxels project
to ~10 px or more in HD video); the mask is ANDed at full size."""


def consistent_silhouettes(cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                           config: HullCheckConfig | None = None,
                           boxes: Sequence[Box | None] | None = None,
                           unknown: Sequence[np.ndarray | None] | None = None,
                           ) -> list[np.ndarray]:  # fmt: skip
    """Each (H, W) bool mask reduced to the pixels under the projection of the views' common
    visual hull (module docstring). Masks come back unchanged when fewer than two views have a
    silhouette, and empty when the views have no 3D point in common.

    ``unknown``: per view, None or (H, W) bool pixels whose label the view cannot tell (its
    background there is unknown): they do not carve the hull.
    """
    config = config or HullCheckConfig()
    masks = [np.asarray(m, bool) for m in masks]
    if not config.multi_view_check or sum(bool(m.any()) for m in masks) < 2:
        return masks
    size = max(max(m.shape) for m in masks)
    dilate = 2 * round(config.check_tolerance * size / 2) + 1
    # Seen by all views but one: a subject partly out of one camera's field stays; a blob
    # whose rays only one other camera sees (behind the subject, below the floor) does not.
    views = sum(bool(m.any()) for m in masks)
    settings = {"dilate_px": dilate, "boxes": boxes, "min_views": max(2, views - 1),
                "unknown": unknown, "misses": max(0, min(config.check_misses, views - 2))}
    points, _ = hull_candidates(cameras, masks, rays_meeting_point(cameras, masks),
                                config.check_size_m, config.check_voxel_m, **settings)
    kept, projections = carve(cameras, masks, points, **settings)
    out = []
    for cam, mask, proj in zip(cameras, masks, projections, strict=True):
        on = kept & proj.seen
        if not on.any() or not mask.any():
            out.append(np.zeros_like(mask))
            continue
        out.append(mask & splat(cam, proj, on, config.check_voxel_m))
    return out


def splat(camera: Camera, proj: Projection, on: np.ndarray, voxel_m: float,
          tight: bool = False) -> np.ndarray:  # fmt: skip
    """(H, W) bool: the pixels covered by the voxels ``on`` (of side ``voxel_m``) that ``proj``
    projects into ``camera``; by default a little more (half a voxel's diagonal around each
    centre), ``tight``: half a voxel, the gaps between centres closed."""
    # Voxel centres land about `footprint` pixels apart (the nearest voxels the farthest): each
    # is spread over half the diagonal of its cell (or half the cell, then closed), on an image
    # reduced so that a cell is still 3 pixels or more.
    h, w = camera.height, camera.width
    if not on.any():
        return np.zeros((h, w), bool)
    footprint = voxel_m * camera.K[0, 0] / np.percentile(proj.depth[on], 5)
    ds = int(np.clip(footprint // 3, 1, _SPLAT_DOWNSCALE))
    radius = max(1, int(np.ceil((0.5 if tight else 0.71) * footprint / ds)))
    small = np.zeros(((h + ds - 1) // ds, (w + ds - 1) // ds), np.uint8)
    small[proj.row[on] // ds, proj.col[on] // ds] = 1
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    small = cv2.dilate(small, disc)
    if tight:
        small = cv2.morphologyEx(small, cv2.MORPH_CLOSE, disc)
    under = small if ds == 1 else cv2.resize(small, (small.shape[1] * ds, small.shape[0] * ds),
                                             interpolation=cv2.INTER_NEAREST)
    return under[:h, :w].astype(bool)


def lowest_band(points: np.ndarray, up: np.ndarray, band_m: float) -> np.ndarray:
    """(N,) bool: the voxels ``points`` (N, 3) within ``band_m`` of the lowest along ``up``
    (a unit vector)."""
    height = np.asarray(points, float) @ np.asarray(up, float)
    return height < height.min() + band_m if len(height) else np.zeros(0, bool)


def floor_only(points: np.ndarray, up: np.ndarray, *, band_m: float,
               voxel_m: float) -> np.ndarray:  # fmt: skip
    """(N,) bool: the voxels ``points`` (N, 3) under a gap at the hull's bottom: below its
    lowest layer (``voxel_m`` thick across ``up``) that holds no voxel, when they lie within
    ``band_m`` of the lowest. A floor shadow's slab under feet off the floor; none when the
    body stands on the slab, or there is no slab."""
    points = np.asarray(points, float)
    if not len(points):
        return np.zeros(0, bool)
    height = points @ np.asarray(up, float)
    layer = np.round((height - height.min()) / voxel_m).astype(np.int64)
    held = np.zeros(int(np.ceil(band_m / voxel_m)) + 1, bool)
    held[layer[layer < len(held)]] = True
    empty = np.flatnonzero(~held)
    if not len(empty) or empty[0] * voxel_m > band_m:  # what lies under it: above the band
        return np.zeros(len(points), bool)
    return layer < empty[0]


def lowest_band_pixels(cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                       points: np.ndarray, up: np.ndarray, *, band_m: float,
                       voxel_m: float) -> list[np.ndarray]:  # fmt: skip
    """Per view, the (H, W) bool pixels of ``masks`` that the visual hull's lowest band covers
    and nothing above it does: the voxels ``points`` (N, 3; the hull's surface voxels, whose
    projection is the hull's) within ``band_m`` of the lowest along ``up`` (a unit vector),
    against the others (:func:`splat`).

    A cast shadow that background subtraction keeps (`tracking.silhouettes.subtraction`'s test
    misses dark ones) lies on the floor: every view sees it, so the hull holds it as a slab
    a few voxels thick at the bottom, and its pixels are the band's alone. So are the lowest
    few centimetres of a foot on the floor. Empty views, and every view when there are no
    points, give no pixels."""
    masks = [np.asarray(m, bool) for m in masks]
    if not len(points):
        return [np.zeros_like(m) for m in masks]
    low = lowest_band(points, up, band_m)
    out = []
    for cam, mask in zip(cameras, masks, strict=True):
        proj = project_voxels(cam, points)
        band = splat(cam, proj, low & proj.seen, voxel_m)
        above = splat(cam, proj, ~low & proj.seen, voxel_m)
        out.append(band & ~above & mask)
    return out


def hull_silhouettes(cameras: Sequence[Camera], masks: Sequence[np.ndarray], *, size_m: float,
                     voxel_m: float, unknown: Sequence[np.ndarray | None] | None = None,
                     ) -> list[np.ndarray]:  # fmt: skip
    """Per view, the (H, W) bool silhouette of the exact visual hull of ``masks`` (``unknown``
    pixels do not carve): the largest body the views agree on, so its overlap with each mask
    bounds what any 3D model can reach with these silhouettes and this calibration (up to the
    voxel size)."""
    masks = [np.asarray(m, bool) for m in masks]
    points, _ = hull_candidates(cameras, masks, rays_meeting_point(cameras, masks), size_m,
                                voxel_m, unknown=unknown)
    kept, projections = carve(cameras, masks, points, unknown=unknown)
    return [splat(cam, proj, kept & proj.seen, voxel_m, tight=True)
            for cam, proj in zip(cameras, projections, strict=True)]
