"""Calibrated cameras for tracking: rigs, and the readers of calibration files.

The camera type and its own format (``mocap-cameras-v1``) are :mod:`recon.cameras`'s, with its
conventions: RDF camera axes, ``cam_from_world = [R | t]`` (world units are metres here), pixel
centres at +0.5 and OpenCV's ``k1, k2, p1, p2, k3`` distortion. OpenCV, Qualisys and Pose2Sim
put pixel centres at integers, so their ``cx, cy`` are 0.5 smaller; the readers convert.

Everything down to :func:`upright_frame` is pure geometry; the readers below it touch the disk.
"""

from __future__ import annotations

import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from recon.cameras import Camera, look_at, read_cameras_json

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


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
    ``Calib.toml`` or ``mocap-cameras-v1`` JSON (:func:`recon.cameras.read_cameras_json`).

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
        is_json = path.suffix.lower() == ".json" or head.startswith(b"{")
        if not is_json and path.suffix.lower() == ".toml":
            return _parse_toml(tomllib.loads(path.read_text(encoding="utf-8")))
        if not is_json:
            raise ValueError("unknown camera file format (expected a COLMAP model folder, a "
                             "Qualisys .qca.txt, a Pose2Sim Calib.toml or mocap-cameras-v1 "
                             "JSON)")
    except (ValueError, KeyError, TypeError, ET.ParseError, UnicodeDecodeError,
            tomllib.TOMLDecodeError) as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{path}: {message}") from None
    return read_cameras_json(path)  # its errors name the file already


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
