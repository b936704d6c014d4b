"""Ground-truth cameras: readers for two public data sets and any supported ground truth, and
pure-numpy comparison of estimated cameras with the truth.

The cameras are :class:`recon.cameras.Camera` (their conventions: RDF camera axes,
``cam_from_world = [R | t]``, pixel centres at +0.5), named by their image; our own ground
truth is ``mocap-cameras-v1`` JSON (:func:`recon.cameras.read_cameras_json`).

Reading functions do I/O; everything from :func:`camera_center` on is pure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon.cameras import Camera, read_cameras_json

# ---------------------------------------------------------------------------------------------
# Public data sets


def read_middlebury_par(
    path: Path, *, width: int = 640, height: int = 480
) -> dict[str, Camera]:
    """Cameras of a Middlebury multi-view ``*_par.txt`` file (e.g. ``templeSR_par.txt``).

    First line: the number of images; then one line per image,
    ``name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 .. r33 t1 t2 t3`` with ``P = K [R | t]``,
    i.e. ``[R | t]`` is already ``cam_from_world``. The file does not give the image size,
    hence ``width``/``height`` (640x480 for the temple and dino sets).
    """
    lines = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    if not lines:
        raise ValueError(f"{path}: empty file")
    try:
        count = int(lines[0][0])
    except ValueError:
        raise ValueError(f"{path}: first line should be the number of images") from None
    if len(lines) - 1 != count:
        raise ValueError(f"{path}: header says {count} images but {len(lines) - 1} lines follow")
    cameras: dict[str, Camera] = {}
    for number, fields in enumerate(lines[1:], start=2):
        if len(fields) != 22:
            raise ValueError(f"{path}:{number}: expected a name and 21 numbers")
        try:
            values = np.array([float(v) for v in fields[1:]], dtype=np.float64)
        except ValueError:
            raise ValueError(f"{path}:{number}: non-numeric camera parameter") from None
        K = values[0:9].reshape(3, 3)
        R = values[9:18].reshape(3, 3)
        t = values[18:21]
        try:
            cameras[fields[0]] = Camera(fields[0], width, height, K, np.column_stack([R, t]))
        except ValueError as exc:
            raise ValueError(f"{path}:{number}: {exc}") from None
    return cameras


def read_strecha_camera(path: Path) -> Camera:
    """One Strecha et al. (2008) ``*.camera`` file.

    Rows: 3 of K, 1 of distortion (zero for the published, undistorted images), 3 of R, 1 of
    the camera centre C, 1 of ``width height``; ``P = K [R^T | -R^T C]``, so R here is
    world_from_cam and ``cam_from_world = [R^T | -R^T C]``. The camera is named by the file
    name without ``.camera`` (``0000.jpg.camera`` → ``0000.jpg``).
    """
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    try:
        numbers = [[float(v) for v in row] for row in rows]
    except ValueError:
        raise ValueError(f"{path}: non-numeric content") from None
    if len(numbers) != 9 or [len(r) for r in numbers[:3]] != [3, 3, 3] or len(numbers[8]) != 2:
        raise ValueError(f"{path}: expected 9 rows (K, distortion, R, centre, width height)")
    if any(len(r) != 3 for r in numbers[4:8]):
        raise ValueError(f"{path}: rows 5-8 (R and centre) must have 3 numbers each")
    K = np.array(numbers[0:3], dtype=np.float64)
    world_from_cam_rotation = np.array(numbers[4:7], dtype=np.float64)
    center = np.array(numbers[7], dtype=np.float64)
    R = world_from_cam_rotation.T
    try:
        return Camera(Path(path).name.removesuffix(".camera"), int(numbers[8][0]),
                      int(numbers[8][1]), K, np.column_stack([R, -R @ center]))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def read_strecha_cameras(folder: Path) -> dict[str, Camera]:
    """All ``*.camera`` files of a folder (e.g. ``fountain_p11/gt_dense_cameras``).

    The image name is the file name without ``.camera`` (``0000.jpg.camera`` → ``0000.jpg``).
    """
    paths = sorted(Path(folder).glob("*.camera"))
    if not paths:
        raise ValueError(f"{folder}: no *.camera files")
    cameras = (read_strecha_camera(p) for p in paths)
    return {camera.name: camera for camera in cameras}


# ---------------------------------------------------------------------------------------------
# Pure evaluation


def camera_center(cam_from_world: np.ndarray) -> np.ndarray:
    """(3,) centre ``-R^T t`` of a (3, 4) ``cam_from_world``."""
    R = cam_from_world[:, :3]
    return -R.T @ cam_from_world[:, 3]


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a (3, 3) rotation matrix in degrees, accurate near 0 and 180 degrees."""
    # atan2 of (2 sin, 2 cos) avoids arccos' loss of precision for small angles.
    axis_times_sin = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return math.degrees(math.atan2(float(np.linalg.norm(axis_times_sin)), float(np.trace(R) - 1)))


def umeyama_sim3(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity (scale, R (3, 3), t (3,)) minimising sum ||dst - (scale R src + t)||^2.

    src, dst: (N, 3) corresponding points. Umeyama (1991), with the reflection fix so that R is
    a proper rotation. ValueError for N < 3, non-finite input, or points that do not fix a
    rotation (coincident or collinear).
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 3 or src.shape != dst.shape:
        raise ValueError(f"src and dst must both be (N, 3), got {src.shape} and {dst.shape}")
    if len(src) < 3:
        raise ValueError(f"a similarity needs at least 3 point pairs, got {len(src)}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise ValueError("points must be finite")
    mean_src = src.mean(axis=0)
    mean_dst = dst.mean(axis=0)
    src_c = src - mean_src
    dst_c = dst - mean_dst
    # Collinear (or coincident) points leave the rotation about their line undetermined.
    for name, centred in (("src", src_c), ("dst", dst_c)):
        sv = np.linalg.svd(centred, compute_uv=False)
        if sv[0] == 0.0 or sv[1] <= 1e-9 * sv[0]:
            raise ValueError(f"{name} points are coincident or collinear: rotation undetermined")
    var_src = float((src_c**2).sum() / len(src))
    covariance = dst_c.T @ src_c / len(src)
    U, D, Vt = np.linalg.svd(covariance)
    S = np.ones(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2] = -1.0
    R = U @ np.diag(S) @ Vt
    scale = float((D * S).sum() / var_src)
    t = mean_dst - scale * R @ mean_src
    return scale, R, t


@dataclass(frozen=True)
class PoseErrors:
    """Per-image pose errors after aligning the estimate to the truth by a similarity."""

    rotation_deg: dict[str, float]  # image name -> angle between aligned and true rotation
    center: dict[str, float]  # image name -> camera-centre distance, in truth units
    scale: float  # similarity scale taking estimated units to truth units

    @property
    def median_rotation_deg(self) -> float:
        return float(np.median(list(self.rotation_deg.values())))

    @property
    def max_rotation_deg(self) -> float:
        return max(self.rotation_deg.values())

    @property
    def median_center(self) -> float:
        return float(np.median(list(self.center.values())))

    @property
    def max_center(self) -> float:
        return max(self.center.values())

    def summary(self) -> str:
        """One line for logs and reports."""
        return (
            f"{len(self.rotation_deg)} cameras: rotation median {self.median_rotation_deg:.3f} "
            f"max {self.max_rotation_deg:.3f} deg; centre median {self.median_center:.4g} "
            f"max {self.max_center:.4g} (truth units); scale {self.scale:.6g}"
        )


def _check_pose(name: str, pose: np.ndarray, what: str) -> np.ndarray:
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (3, 4) or not np.isfinite(pose).all():
        raise ValueError(f"{what} pose of {name!r} must be a finite (3, 4) cam_from_world")
    return pose


def pose_errors(estimated: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray]) -> PoseErrors:
    """Rotation and centre errors of estimated (3, 4) ``cam_from_world`` poses.

    Only images present in both mappings count (at least 3, not all on one line). The
    estimate's world is first mapped onto the truth's by the similarity
    ``x_truth = s R_a x_est + t_a`` fitted (Umeyama) to the camera centres. Under that change of
    world a camera's rotation becomes ``R_est R_a^T`` (since ``x_cam ∝ R_est x_est``) and its
    centre ``s R_a C_est + t_a``; the errors are the angle of ``R_true^T R_est R_a^T`` and the
    distance between centres.
    """
    names = sorted(set(estimated) & set(truth))
    if len(names) < 3:
        raise ValueError(f"need at least 3 images in common to align poses, got {len(names)}")
    est = {n: _check_pose(n, estimated[n], "estimated") for n in names}
    true = {n: _check_pose(n, truth[n], "true") for n in names}
    centers_est = np.array([camera_center(est[n]) for n in names])
    centers_true = np.array([camera_center(true[n]) for n in names])
    scale, R_a, t_a = umeyama_sim3(centers_est, centers_true)
    rotation_deg: dict[str, float] = {}
    center: dict[str, float] = {}
    for i, n in enumerate(names):
        R_est_aligned = est[n][:, :3] @ R_a.T
        rotation_deg[n] = rotation_angle_deg(true[n][:, :3].T @ R_est_aligned)
        aligned_center = scale * R_a @ centers_est[i] + t_a
        center[n] = float(np.linalg.norm(aligned_center - centers_true[i]))
    return PoseErrors(rotation_deg=rotation_deg, center=center, scale=scale)


def focal_error(estimated_px: float, true_px: float) -> float:
    """Signed relative focal-length error ``(estimated - true) / true`` (+0.01: 1 % too long)."""
    if not (math.isfinite(true_px) and true_px > 0):
        raise ValueError(f"true focal length must be positive and finite, got {true_px}")
    if not math.isfinite(estimated_px):
        raise ValueError(f"estimated focal length must be finite, got {estimated_px}")
    return (estimated_px - true_px) / true_px


# ---------------------------------------------------------------------------------------------
# Any supported ground truth, by what the path looks like


@dataclass(frozen=True)
class GroundTruth:
    focal_px: float
    """Mean of fx and fy over the cameras, in pixels."""
    cameras: dict[str, Camera] | None
    """Per-image cameras when the source has poses (not for a bare K.txt)."""
    source: str
    principal_point_px: tuple[float, float] | None = None
    """Mean ``(cx, cy)`` over the cameras, in pixels (in the ground truth's own convention)."""


def read_k_txt(path: Path) -> np.ndarray:
    """A 3x3 calibration matrix written as 3 rows of 3 numbers (Strecha's ``K.txt``)."""
    try:
        rows = [[float(v) for v in line.split()] for line in Path(path).read_text().splitlines()
                if line.strip()]
        K = np.array(rows, dtype=np.float64)
    except ValueError:
        raise ValueError(f"{path}: not a 3x3 matrix of numbers") from None
    if K.shape != (3, 3):
        raise ValueError(f"{path}: expected 3 rows of 3 numbers, got shape {K.shape}")
    return K


def load_ground_truth(path: Path) -> GroundTruth:
    """Ground truth from a Middlebury ``*_par.txt``, a folder of Strecha ``*.camera`` files, a
    Strecha ``K.txt``, a COLMAP model folder, or our ``mocap-cameras-v1`` JSON.

    ValueError with a one-line message naming the path when it is none of these.
    """
    path = Path(path)
    cameras: dict[str, Camera]
    if path.is_dir() and any(path.glob("*.camera")):
        cameras, kind = read_strecha_cameras(path), "Strecha cameras"
    elif path.is_dir() and any((path / f"cameras.{ext}").exists() for ext in ("bin", "txt")):
        import pycolmap

        model = pycolmap.Reconstruction(path)
        cameras = {
            # K and the pose of any camera model; its distortion is left out (truth is pinhole).
            im.name: Camera(
                im.name,
                model.cameras[im.camera_id].width,
                model.cameras[im.camera_id].height,
                model.cameras[im.camera_id].calibration_matrix(),
                im.cam_from_world().matrix(),
            )
            for im in model.images.values()
            if im.has_pose
        }
        kind = "COLMAP model"
    elif path.is_file() and path.suffix == ".json":
        cameras, kind = {c.name: c for c in read_cameras_json(path)}, "mocap-cameras-v1"
    elif path.is_file() and path.name.endswith("_par.txt"):
        cameras, kind = read_middlebury_par(path), "Middlebury par"
    elif path.is_file() and path.suffix == ".txt":
        K = read_k_txt(path)
        return GroundTruth(float(0.5 * (K[0, 0] + K[1, 1])), None, f"K matrix {path}",
                           (float(K[0, 2]), float(K[1, 2])))
    else:
        raise ValueError(
            f"{path}: not a ground truth this tool reads (Middlebury *_par.txt, a folder of "
            "Strecha *.camera files, K.txt, a COLMAP model folder, or mocap-cameras-v1 JSON)"
        )
    if not cameras:
        raise ValueError(f"{path}: no cameras in this {kind}")
    focal = float(np.mean([c.focal_px for c in cameras.values()]))
    pp = np.mean([c.K[:2, 2] for c in cameras.values()], axis=0)
    return GroundTruth(focal, cameras, f"{kind} {path}", (float(pp[0]), float(pp[1])))
