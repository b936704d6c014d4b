"""Calibrated cameras: one pinhole camera with lens distortion, and its file format.

The one camera type of the project: ground truth of photo sets (:mod:`recon.evaluation.truth`),
the synthetic room, and the calibrated video cameras of tracking (:mod:`tracking.rig.cameras`
adds rigs and the readers of other calibration formats).

Conventions (the same as COLMAP and OpenCV, and Open3D's ``create_rays_pinhole``):

* Camera axes are RDF: x right, y down, z forward along the optical axis.
* ``cam_from_world`` is a (3, 4) matrix ``[R | t]`` with ``x_cam = R @ x_world + t``; the camera
  centre is ``C = -R.T @ t``.
* Pixel coordinates have their origin at the top-left *corner* of the image: pixel (column i,
  row j) covers ``[i, i+1) x [j, j+1)`` and its centre is ``(i + 0.5, j + 0.5)``. A centred
  camera has ``cx = width / 2``. ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
* ``dist`` holds OpenCV's ``k1, k2, p1, p2, k3`` (Brown-Conrady), applied to the normalised
  coordinates ``(x/z, y/z)`` before ``K``, exactly as ``cv2.projectPoints`` does.

``mocap-cameras-v1`` JSON, one entry per camera (for photos: keyed by the image's name as COLMAP
knows it, its path relative to the image folder), in file order::

    {
      "format": "mocap-cameras-v1",
      "cameras": {
        "view_000.png": {
          "width": 640, "height": 480,
          "K": [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]],
          "cam_from_world": [[r11, r12, r13, t1], [r21, r22, r23, t2], [r31, r32, r33, t3]],
          "dist": [k1, k2, p1, p2, k3]
        }
      }
    }

``dist`` is optional (zeros when absent: files of pinhole ground truth have none). Everything
down to :func:`look_at` is pure geometry; :func:`read_cameras_json` and
:func:`write_cameras_json` touch the disk.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

CAMERAS_FORMAT = "mocap-cameras-v1"


def _readonly(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera. Arrays are float64 and read-only.

    name: the camera's (or, for photos, the image's) name; K: (3, 3) intrinsics (pixel
    centres at +0.5); cam_from_world: (3, 4) ``[R | t]``; dist: (5,) OpenCV ``k1, k2, p1, p2,
    k3`` (shorter input is padded with zeros; zeros for a pinhole camera). Two cameras are
    equal when every field is exactly equal.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    cam_from_world: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        for what in ("width", "height"):
            value = getattr(self, what)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"camera {self.name!r}: {what} must be a positive integer, "
                                 f"got {value!r}")
            object.__setattr__(self, what, int(value))
        try:
            K = np.array(self.K, dtype=np.float64)
            cam_from_world = np.array(self.cam_from_world, dtype=np.float64)
            dist = np.array(self.dist, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"camera {self.name!r}: K, cam_from_world and dist must be "
                             "numeric matrices") from None
        for what, array, shape in (("K", K, (3, 3)), ("cam_from_world", cam_from_world, (3, 4))):
            if array.shape != shape:
                raise ValueError(f"camera {self.name!r}: {what} has shape {array.shape}, "
                                 f"expected {shape}")
        if len(dist) > 5:
            raise ValueError(f"camera {self.name!r}: dist has {len(dist)} values, at most 5 "
                             "(OpenCV's k1, k2, p1, p2, k3)")
        dist = np.concatenate([dist, np.zeros(5 - len(dist))])
        if not (np.isfinite(K).all() and np.isfinite(cam_from_world).all()
                and np.isfinite(dist).all()):
            raise ValueError(f"camera {self.name!r}: non-finite parameters")
        R = cam_from_world[:, :3]
        # 1e-5: published rotations (Strecha's fountain) are orthonormal to ~1e-6 only.
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise ValueError(f"camera {self.name!r}: cam_from_world[:, :3] is not a rotation")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0.0, 0.0, 1.0]):
            raise ValueError(f"camera {self.name!r}: K is not [[fx, s, cx], [0, fy, cy], "
                             f"[0, 0, 1]] with positive focal lengths")
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "cam_from_world", _readonly(cam_from_world))
        object.__setattr__(self, "dist", _readonly(dist))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return self._key == other._key

    def __hash__(self) -> int:
        return hash(self._key)

    @cached_property
    def _key(self) -> tuple[Any, ...]:
        return (self.name, self.width, self.height, self.K.tobytes(),
                self.cam_from_world.tobytes(), self.dist.tobytes())

    # -- geometry ---------------------------------------------------------------------------

    @property
    def R(self) -> np.ndarray:
        """(3, 3) rotation of ``cam_from_world``."""
        return self.cam_from_world[:, :3]

    @property
    def t(self) -> np.ndarray:
        """(3,) translation of ``cam_from_world``."""
        return self.cam_from_world[:, 3]

    @property
    def center_in_world(self) -> np.ndarray:
        """(3,) camera centre ``-R.T @ t``."""
        return -self.R.T @ self.t

    @property
    def focal_px(self) -> float:
        """Mean of fx and fy, in pixels."""
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    @cached_property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) normalised image coordinates -> distorted normalised coordinates (OpenCV)."""
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort(self, xy_distorted: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Inverse of :meth:`distort` by Newton's method: (N, 2) -> (N, 2), NaN where it does
        not converge to 1e-10 (only past the monotonic radius, outside any sane image)."""
        k1, k2, p1, p2, k3 = self.dist
        target = np.asarray(xy_distorted, dtype=np.float64).reshape(-1, 2)
        x, y = target[:, 0].copy(), target[:, 1].copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            d_radial = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)  # d radial / d r2
            fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - target[:, 0]
            fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - target[:, 1]
            jxx = radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
            jyy = radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
            jxy = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
            det = jxx * jyy - jxy * jxy
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (jyy * fx - jxy * fy) / det
                dy = (jxx * fy - jxy * fx) / det
            x, y = x - dx, y - dy
            if max(np.abs(dx).max(), np.abs(dy).max()) < 1e-14:  # NaN never passes
                break
        xy = np.stack([x, y], axis=1)
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(self.distort(xy) - target).max(axis=1) < 1e-10)
        xy[bad] = np.nan
        return xy

    @cached_property
    def max_radius2(self) -> float:
        """Squared normalised radius up to which radial distortion is monotonic (inf if always).

        Beyond it the polynomial folds back, so a point far outside the field of view could
        project into the image; renderers drop geometry beyond it.
        """
        k1, k2, _, _, k3 = self.dist
        # d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] = 1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3, s = r^2.
        roots = np.roots([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]) if np.any([k1, k2, k3]) else []
        positive = [r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0]
        return float(min(positive)) if positive else math.inf

    def project(self, points_in_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels and depths of (N, 3) world points: uv (N, 2) px and depth (N,) metres.

        depth is z in the camera frame; uv is NaN where depth <= 0 (behind the camera), where
        a pixel position means nothing. Same result as ``cv2.projectPoints`` (+0.5 px shift of
        the pixel convention aside) for points in front of the camera.
        """
        points = np.asarray(points_in_world, dtype=np.float64).reshape(-1, 3)
        in_cam = points @ self.R.T + self.t
        depth = in_cam[:, 2]
        # NaN, not a division, where depth <= 0 (no errstate: it costs more than the rest for
        # a few points, and the tracker projects a few points very often).
        front = (depth > 0)[:, None]
        xy = np.divide(in_cam[:, :2], depth[:, None], out=np.full((len(points), 2), np.nan),
                       where=front)
        if self.has_distortion:
            xy = self.distort(xy)
        K = self.K
        uv = np.empty((len(points), 2))
        uv[:, 0] = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
        uv[:, 1] = K[1, 1] * xy[:, 1] + K[1, 2]
        return uv, depth
    @cached_property
    def pixel_rays_in_camera(self) -> np.ndarray:
        """(H, W, 3) direction (x, y, 1) in the camera frame through each pixel centre.

        Distortion is inverted by :meth:`undistort` (NaN rays where it cannot be); read-only
        and computed once per camera. (OpenCV's ``undistortPoints`` with an accuracy
        criterion takes ~30 s for a VGA image; Newton in numpy takes ~0.1 s.)
        """
        u, v = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        uv = np.stack([u.ravel(), v.ravel()], axis=1)
        xy = (uv - self.K[:2, 2]) / np.diag(self.K)[:2]
        xy[:, 0] -= self.K[0, 1] * xy[:, 1] / self.K[0, 0]
        if self.has_distortion:
            xy = self.undistort(xy)
        rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
        return _readonly(rays.reshape(self.height, self.width, 3))

    def scaled(self, factor: float) -> Camera:
        """The same camera for an image resized by ``factor`` (0.5: one pyramid level down).

        The new size is ``round(width * factor)`` x ``round(height * factor)`` and K's rows are
        scaled by the exact size ratios. With pixel centres at +0.5 the image *edges* map onto
        each other, so this is exact for ``cv2.resize(..., INTER_AREA)`` to the same size.
        Distortion acts on normalised coordinates and does not change.
        """
        if not factor > 0:
            raise ValueError(f"scale factor must be positive, got {factor}")
        width = max(1, round(self.width * factor))
        height = max(1, round(self.height * factor))
        K = np.diag([width / self.width, height / self.height, 1.0]) @ self.K
        return Camera(self.name, width, height, K, self.cam_from_world, self.dist)

    def in_frame(self, world_from_frame: np.ndarray) -> Camera:
        """The same camera, its pose taking points of another frame: ``world_from_frame`` is a
        (3, 3) rotation about the origin from that frame's coordinates to the world's."""
        rotation = self.cam_from_world[:, :3] @ np.asarray(world_from_frame, dtype=np.float64)
        return Camera(self.name, self.width, self.height, self.K,
                      np.concatenate([rotation, self.cam_from_world[:, 3:]], axis=1), self.dist)


def look_at(center_in_world: np.ndarray, target_in_world: np.ndarray,
            up_in_world: Sequence[float] = (0.0, 1.0, 0.0), roll_deg: float = 0.0) -> np.ndarray:
    """(3, 4) cam_from_world of a camera at ``center`` looking at ``target``, image up = world up.

    RDF camera axes: z = forward (towards the target), x = right = z x up, y = down = z x x.
    A positive ``roll_deg`` then turns the camera clockwise about its optical axis (seen from
    behind it), so the picture's content turns counter-clockwise.
    """
    center = np.asarray(center_in_world, dtype=np.float64)
    z = np.asarray(target_in_world, dtype=np.float64) - center
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up_in_world, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    if roll_deg:
        c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
        R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ R
    return np.concatenate([R, (-R @ center)[:, None]], axis=1)


# ---------------------------------------------------------------------------------------------
# mocap-cameras-v1 (disk)


def parse_cameras_json(document: Any) -> list[Camera]:
    """Cameras of an already-parsed ``mocap-cameras-v1`` document, in file order; ValueError
    (one line) when it is malformed."""
    if not isinstance(document, dict) or document.get("format") != CAMERAS_FORMAT:
        found = document.get("format") if isinstance(document, dict) else None
        raise ValueError(f"format is {found!r}, expected {CAMERAS_FORMAT!r} (its \"format\" "
                         "field)")
    entries = document.get("cameras")
    if not isinstance(entries, dict) or not entries:
        raise ValueError('"cameras" is missing, empty or not an object')
    cameras = []
    for name, entry in entries.items():
        if not isinstance(entry, dict):
            raise ValueError(f"camera {name!r} is not an object")
        missing = {"width", "height", "K", "cam_from_world"} - entry.keys()
        if missing:
            raise ValueError(f"camera {name!r} lacks {', '.join(sorted(missing))}")
        cameras.append(Camera(name, entry["width"], entry["height"], entry["K"],
                              entry["cam_from_world"], entry.get("dist", ())))
    return cameras


def read_cameras_json(path: Path | str) -> list[Camera]:
    """Cameras of a ``mocap-cameras-v1`` file, in file order.

    ValueError with one line naming the file when its content is malformed; a missing or
    unreadable file raises the usual OSError.
    """
    path = Path(path)
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file") from None
    try:
        return parse_cameras_json(document)
    except ValueError as exc:
        raise ValueError(f"{path}: {' '.join(str(exc).split())}") from None


def write_cameras_json(path: Path | str, cameras: Sequence[Camera]) -> None:
    """Write cameras as ``mocap-cameras-v1`` JSON (atomically), in the given order.

    Python's float repr round-trips, so :func:`read_cameras_json` reads back exactly the same
    cameras. ValueError when two cameras share a name.
    """
    # Imported here: the workspace module pulls in the image scanner, which pure users of the
    # camera type need not load.
    from recon.workspace import atomic_output

    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise ValueError(f"camera names must be unique, got {names}")
    document = {"format": CAMERAS_FORMAT, "cameras": {
        c.name: {"width": c.width, "height": c.height, "K": c.K.tolist(),
                 "cam_from_world": c.cam_from_world.tolist(), "dist": c.dist.tolist()}
        for c in cameras}}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
