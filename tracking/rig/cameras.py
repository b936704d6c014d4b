"""Calibrated cameras for tracking: projection with lens distortion, pyramids, rigs, readers.

Conventions (those of :mod:`recon.evaluation.truth`, COLMAP and Open3D's ``create_rays_pinhole``):

* Camera axes are RDF: x right, y down, z forward along the optical axis.
* ``cam_from_world`` is a (3, 4) matrix ``[R | t]`` with ``x_cam = R @ x_world + t``; the camera
  centre is ``C = -R.T @ t``. World units are metres.
* Pixel coordinates have their origin at the top-left *corner* of the image: pixel (column i,
  row j) covers ``[i, i+1) x [j, j+1)`` and its centre is ``(i + 0.5, j + 0.5)``. A centred
  camera has ``cx = width / 2``. OpenCV, Qualisys and Pose2Sim put pixel centres at integers,
  so their ``cx, cy`` are 0.5 smaller; the readers convert.
* ``dist`` holds OpenCV's ``k1, k2, p1, p2, k3`` (Brown-Conrady), applied to the normalised
  coordinates ``(x/z, y/z)`` before ``K``, exactly as ``cv2.projectPoints`` does.

Everything down to :func:`ring_cameras` is pure geometry; the readers and the writer below it
touch the disk.
"""

from __future__ import annotations

import json
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

CAMERAS_FORMAT = "mocap-cameras-v1"
"""The JSON format of :mod:`recon.evaluation.truth`, extended by an optional ``dist`` per camera."""


def _readonly(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera. Arrays are float64 and read-only.

    K: (3, 3) intrinsics (pixel centres at +0.5); cam_from_world: (3, 4) ``[R | t]``;
    dist: (5,) OpenCV ``k1, k2, p1, p2, k3`` (shorter input is padded with zeros).
    Two cameras are equal when every field is exactly equal.
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
        K = np.array(self.K, dtype=np.float64)
        cam_from_world = np.array(self.cam_from_world, dtype=np.float64)
        dist = np.array(self.dist, dtype=np.float64).ravel()
        if K.shape != (3, 3) or cam_from_world.shape != (3, 4) or len(dist) > 5:
            raise ValueError(f"camera {self.name!r}: K must be 3x3, cam_from_world 3x4 and dist "
                             f"at most 5 values; got {K.shape}, {cam_from_world.shape}, "
                             f"{dist.shape}")
        dist = np.concatenate([dist, np.zeros(5 - len(dist))])
        if not (np.isfinite(K).all() and np.isfinite(cam_from_world).all()
                and np.isfinite(dist).all()):
            raise ValueError(f"camera {self.name!r}: non-finite parameters")
        R = cam_from_world[:, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
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
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = in_cam[:, :2] / depth[:, None]
        xy[depth <= 0] = np.nan
        if self.has_distortion:
            xy = self.distort(xy)
        K = self.K
        uv = np.stack([K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2],
                       K[1, 1] * xy[:, 1] + K[1, 2]], axis=1)
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
            up_in_world: Sequence[float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    """(3, 4) cam_from_world of a camera at ``center`` looking at ``target``, image up = world up.

    RDF camera axes: z = forward (towards the target), x = right = z x up, y = down = z x x.
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
    return np.concatenate([R, (-R @ center)[:, None]], axis=1)


def ring_cameras(n: int, radius_m: float, height_m: float,
                 target_in_world: Sequence[float] = (0.0, 0.0, 0.0), width: int = 640,
                 height: int = 480, focal_px: float = 600.0) -> list[Camera]:
    """``n`` pinhole cameras evenly on a horizontal circle, all looking at the target.

    World Y is up (the body model's frame). Camera k (named ``cam00``, ...) sits at azimuth
    ``2 pi k / n`` from +Z towards +X: ``target + (r sin a, ., r cos a)`` at world height
    ``height_m``, so ``cam00`` is in front of a body facing +Z. Image up is world up; the
    principal point is the image centre (``cx = width / 2``, pixel centres at +0.5).
    """
    if n < 1:
        raise ValueError(f"ring_cameras needs n >= 1, got {n}")
    target = np.asarray(target_in_world, dtype=np.float64)
    K = np.array([[focal_px, 0.0, width / 2], [0.0, focal_px, height / 2], [0.0, 0.0, 1.0]])
    cameras = []
    for k in range(n):
        a = 2.0 * math.pi * k / n
        center = np.array([target[0] + radius_m * math.sin(a), height_m,
                           target[2] + radius_m * math.cos(a)])
        cameras.append(Camera(f"cam{k:02d}", width, height, K, look_at(center, target)))
    return cameras


def rig_up(cameras: Sequence[Camera], subject_in_world: np.ndarray) -> np.ndarray | None:
    """The world's up direction as a camera rig shows it: the normal of the plane through the
    camera centres, towards the cameras (mounted above the subject's middle, around it).
    None when the rig gives no such hint (fewer than 3 cameras, or cameras level with it)."""
    centres = np.array([c.center_in_world for c in cameras])
    if len(centres) < 3:
        return None
    mean = centres.mean(axis=0)
    normal = np.linalg.svd(centres - mean)[2][-1]
    height = (mean - np.asarray(subject_in_world, dtype=float)) @ normal
    spread = np.linalg.norm(centres - mean, axis=1).mean()
    if abs(height) < 0.05 * spread:
        return None
    return normal * np.sign(height)


def upright_frame(cameras: Sequence[Camera], subject_in_world: np.ndarray) -> np.ndarray:
    """(3, 3) world_from_upright: the least rotation taking +Y (the body model's up) to the
    rig's up (`rig_up`), or the identity when the rig does not tell (world Y is then up).

    Tracking in this frame keeps an upright body far from the gimbal lock of the root's ZXY
    angles (at a 90 degree pitch), which a Z-up world (Qualisys, Pose2Sim) puts it in.
    """
    up = rig_up(cameras, subject_in_world)
    y = np.array([0.0, 1.0, 0.0])
    if up is None or np.allclose(up, y, atol=1e-9):
        return np.eye(3)
    if up @ y < -1.0 + 1e-9:  # upside down: half a turn about X
        return np.diag([1.0, -1.0, -1.0])
    v, c = np.cross(y, up), float(y @ up)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


# ---------------------------------------------------------------------------------------------
# Readers and writer (disk)


def read_cameras(path: Path | str) -> list[Camera]:
    """Cameras of a COLMAP model folder, a Qualisys ``.qca.txt`` file, a Pose2Sim / Anipose
    ``Calib.toml`` or ``mocap-cameras-v1`` JSON.

    COLMAP: one camera per registered image, named by the image, sorted by name. Qualisys:
    one per camera, named by its serial, in file order. TOML and JSON: in file order. Anything
    else, or a malformed file, raises ValueError with one line naming the file.
    """
    path = Path(path)
    try:
        if path.is_dir():
            if any((path / f"cameras{ext}").is_file() for ext in (".bin", ".txt")):
                return _read_colmap(path)
            raise ValueError("folder is not a COLMAP model (no cameras.bin or cameras.txt)")
        if not path.is_file():
            raise ValueError("no such file or folder")
        head = path.read_bytes()[:4096].lstrip()
        if path.name.lower().endswith(".qca.txt") or head.startswith(b"<?xml") \
                or head.startswith(b"<calibration"):
            return _read_qualisys(path)
        if path.suffix.lower() == ".json" or head.startswith(b"{"):
            return _parse_json(json.loads(path.read_text(encoding="utf-8")))
        if path.suffix.lower() == ".toml":
            return _parse_toml(tomllib.loads(path.read_text(encoding="utf-8")))
        raise ValueError("unknown camera file format (expected a COLMAP model folder, a "
                         "Qualisys .qca.txt, a Pose2Sim Calib.toml or mocap-cameras-v1 JSON)")
    except (ValueError, KeyError, TypeError, ET.ParseError, UnicodeDecodeError,
            tomllib.TOMLDecodeError) as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{path}: {message}") from None


# COLMAP camera models that are OpenCV's model with some coefficients fixed at 0, as
# (model name) -> (indices of fx, fy, cx, cy in params; indices of k1, k2, p1, p2).
_COLMAP_MODELS: dict[str, tuple[tuple[int, int, int, int], tuple[int | None, ...]]] = {
    "SIMPLE_PINHOLE": ((0, 0, 1, 2), ()),
    "PINHOLE": ((0, 1, 2, 3), ()),
    "SIMPLE_RADIAL": ((0, 0, 1, 2), (3,)),
    "RADIAL": ((0, 0, 1, 2), (3, 4)),
    "OPENCV": ((0, 1, 2, 3), (4, 5, 6, 7)),
}


def _read_colmap(folder: Path) -> list[Camera]:
    import pycolmap

    try:
        model = pycolmap.Reconstruction(folder)
    except Exception as exc:  # noqa: BLE001 - pycolmap raises its own types for bad models
        raise ValueError(f"not a readable COLMAP model ({exc})") from None
    cameras = []
    for image in sorted(model.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            continue
        camera = model.cameras[image.camera_id]
        name = camera.model.name
        if name not in _COLMAP_MODELS:
            raise ValueError(f"image {image.name}: COLMAP camera model {name} is not supported "
                             f"(supported: {', '.join(_COLMAP_MODELS)})")
        (fx, fy, cx, cy), extra = _COLMAP_MODELS[name]
        p = np.asarray(camera.params, dtype=np.float64)
        K = np.array([[p[fx], 0.0, p[cx]], [0.0, p[fy], p[cy]], [0.0, 0.0, 1.0]])
        # COLMAP already puts pixel centres at +0.5, like us.
        cameras.append(Camera(image.name, camera.width, camera.height, K,
                              image.cam_from_world().matrix(), [p[i] for i in extra]))
    if not cameras:
        raise ValueError("COLMAP model has no registered image")
    return cameras


def _read_qualisys(path: Path) -> list[Camera]:
    """Qualisys QTM calibration export (what Pose2Sim's ``calib_qca_fun`` reads).

    Per camera: ``fov_video`` gives the image rectangle (inclusive pixel bounds); focal
    lengths and principal point are in 1/64 pixel (sub-pixel units of the sensor), relative to
    the sensor origin, so ``fov_video``'s left/top is subtracted; distortion coefficients are
    OpenCV's, unscaled (a checkerboard calibration of the demo's own intrinsic shots gives
    k1, k2 of the same size; Pose2Sim's extra division by 64 would make them vanish);
    ``transform`` holds the camera position in mm and a rotation whose *rows* are the
    camera's axes in the world, for a camera looking down its -Z with +Y up in the image
    (Pose2Sim: transpose of the by-column matrix, inverted, then turned by pi about x).
    So ``R = diag(1, -1, -1) @ M`` gives RDF axes and ``t = -R @ position``. The world is
    Qualisys' lab frame: Z up, metres.
    """
    root = ET.parse(path).getroot()
    if root.tag != "calibration":
        raise ValueError(f"XML root is <{root.tag}>, expected Qualisys <calibration>")
    cameras = []
    for number, node in enumerate(root.iter("camera"), start=1):
        name = node.get("serial") or f"camera{number}"
        fov, transform, intrinsic = (node.find(tag) for tag in ("fov_video", "transform",
                                                                "intrinsic"))
        if fov is None or transform is None or intrinsic is None:
            raise ValueError(f"camera {name} lacks fov_video, transform or intrinsic")

        def num(element: ET.Element, key: str, _name: str = name) -> float:
            value = element.get(key)
            if value is None:
                raise ValueError(f"camera {_name}: attribute {key} is missing")
            return float(value)

        left, top = num(fov, "left"), num(fov, "top")
        width = round(num(fov, "right") - left + 1)
        height = round(num(fov, "bottom") - top + 1)
        fu, fv = num(intrinsic, "focalLengthU") / 64, num(intrinsic, "focalLengthV") / 64
        # 1/64 px with pixel centres at integers -> our +0.5 convention.
        cu = num(intrinsic, "centerPointU") / 64 - left + 0.5
        cv = num(intrinsic, "centerPointV") / 64 - top + 0.5
        skew = float(intrinsic.get("skew", 0.0))
        K = np.array([[fu, skew, cu], [0.0, fv, cv], [0.0, 0.0, 1.0]])
        dist = [num(intrinsic, k) for k in ("radialDistortion1", "radialDistortion2",
                                            "tangentalDistortion1", "tangentalDistortion2",
                                            "radialDistortion3")]
        M = np.array([[num(transform, f"r{i}{j}") for j in "123"] for i in "123"])
        position_m = np.array([num(transform, k) for k in "xyz"]) / 1000.0
        R = np.diag([1.0, -1.0, -1.0]) @ M
        cameras.append(Camera(name, width, height, K,
                              np.concatenate([R, (-R @ position_m)[:, None]], axis=1), dist))
    if not cameras:
        raise ValueError("Qualisys calibration has no <camera>")
    return cameras


def _parse_toml(document: dict[str, Any]) -> list[Camera]:
    """Pose2Sim's ``Calib.toml`` (Anipose's format, written by Pose2Sim's calibration and its
    converters): one table per camera with ``name``, ``size`` ``[width, height]``, ``matrix``
    (3x3, OpenCV: pixel centres at integers, so ``cx, cy`` gain 0.5 here), ``distortions``
    (OpenCV ``k1, k2, p1, p2[, k3]``), ``rotation`` (Rodrigues vector of the world-to-camera
    rotation) and ``translation`` (world-to-camera, metres): what ``cv2.projectPoints`` takes.
    Tables without a ``matrix`` (Pose2Sim's ``[metadata]``) are skipped; a fisheye camera is
    refused (its distortion is another model)."""
    cameras = []
    for key, entry in document.items():
        if not isinstance(entry, dict) or "matrix" not in entry:
            continue
        name = str(entry.get("name", key))
        missing = {"size", "rotation", "translation"} - entry.keys()
        if missing:
            raise ValueError(f"camera {name!r} lacks {', '.join(sorted(missing))}")
        if entry.get("fisheye", False):
            raise ValueError(f"camera {name!r} is a fisheye camera: only OpenCV's pinhole "
                             "distortion model is supported")
        size = np.asarray(entry["size"], dtype=np.float64)
        if size.shape != (2,) or not np.allclose(size, np.round(size)):
            raise ValueError(f"camera {name!r}: size must be [width, height] in whole pixels")
        K = np.array(entry["matrix"], dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"camera {name!r}: matrix must be 3x3, got shape {K.shape}")
        K[:2, 2] += 0.5  # OpenCV's pixel centres at integers -> ours at +0.5
        R = _rodrigues(np.asarray(entry["rotation"], dtype=np.float64), name)
        t = np.asarray(entry["translation"], dtype=np.float64)
        if t.shape != (3,):
            raise ValueError(f"camera {name!r}: translation must have 3 values")
        cameras.append(Camera(name, round(size[0]), round(size[1]), K,
                              np.column_stack([R, t]), entry.get("distortions", ())))
    if not cameras:
        raise ValueError("TOML has no camera table (one with a 'matrix')")
    return cameras


def _rodrigues(rvec: np.ndarray, name: str) -> np.ndarray:
    """(3, 3) rotation of a Rodrigues (axis times angle) vector, as ``cv2.Rodrigues``."""
    from scipy.spatial.transform import Rotation

    if rvec.shape != (3,) or not np.isfinite(rvec).all():
        raise ValueError(f"camera {name!r}: rotation must be a Rodrigues vector of 3 values")
    return Rotation.from_rotvec(rvec).as_matrix()


def _parse_json(document: Any) -> list[Camera]:
    if not isinstance(document, dict) or document.get("format") != CAMERAS_FORMAT:
        raise ValueError(f"JSON is not {CAMERAS_FORMAT} (its \"format\" field)")
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


def write_cameras_json(path: Path | str, cameras: Sequence[Camera]) -> None:
    """Write cameras as ``mocap-cameras-v1`` JSON (atomically), readable by :func:`read_cameras`.

    ``{"format": "mocap-cameras-v1", "cameras": {name: {"width", "height", "K" (3x3),
    "cam_from_world" (3x4), "dist" ([k1, k2, p1, p2, k3], OpenCV)}}}`` in the conventions of
    this module; Python's float repr round-trips, so values read back exactly. ``dist`` is
    our extension: :func:`recon.evaluation.truth.read_truth` reads the same file but ignores it.
    """
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
