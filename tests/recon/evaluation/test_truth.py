"""Ground truth by path, public data-set readers, similarity alignment and pose errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from recon.cameras import Camera, write_cameras_json
from recon.evaluation.truth import (
    camera_center,
    focal_error,
    load_ground_truth,
    pose_errors,
    read_middlebury_par,
    read_strecha_cameras,
    rotation_angle_deg,
    umeyama_sim3,
)
from tests.helpers import shared_dataset


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def axis_angle(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rodrigues' formula, written out so the test does not rely on cv2.Rodrigues."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = math.radians(angle_deg)
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K


def ring_of_cameras(rng: np.random.Generator, n: int = 8) -> dict[str, np.ndarray]:
    """cam_from_world of n cameras at random positions looking roughly at the origin."""
    poses = {}
    for i in range(n):
        R = random_rotation(rng)
        center = rng.uniform(-3, 3, 3)
        poses[f"img_{i:02d}.jpg"] = np.column_stack([R, -R @ center])
    return poses


def transform_world(pose: np.ndarray, scale: float, R_a: np.ndarray, t_a: np.ndarray) -> np.ndarray:
    """cam_from_world of the same camera in a world' with x' = scale R_a x + t_a.

    x_cam' (in world' units) = scale x_cam = R R_a^T (x' - t_a) + scale t.
    """
    R, t = pose[:, :3], pose[:, 3]
    R_new = R @ R_a.T
    return np.column_stack([R_new, scale * t - R_new @ t_a])


# ---------------------------------------------------------------------------------------------
# Umeyama


def test_umeyama_recovers_known_similarity() -> None:
    rng = np.random.default_rng(1)
    src = rng.uniform(-5, 5, (20, 3))
    R_true = random_rotation(rng)
    scale_true, t_true = 0.37, np.array([1.5, -2.0, 10.0])
    dst = scale_true * src @ R_true.T + t_true
    scale, R, t = umeyama_sim3(src, dst)
    assert abs(scale - scale_true) < 1e-9
    np.testing.assert_allclose(R, R_true, atol=1e-9)
    np.testing.assert_allclose(t, t_true, atol=1e-9)


def test_umeyama_minimal_and_planar_input() -> None:
    rng = np.random.default_rng(2)
    src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0]])  # 3 points: a plane, still unique
    R_true = random_rotation(rng)
    dst = 2.5 * src @ R_true.T + 1.0
    scale, R, t = umeyama_sim3(src, dst)
    assert abs(scale - 2.5) < 1e-9
    np.testing.assert_allclose(R, R_true, atol=1e-9)
    np.testing.assert_allclose(t, [1.0, 1.0, 1.0], atol=1e-9)


def test_umeyama_returns_a_rotation_for_mirrored_points() -> None:
    rng = np.random.default_rng(3)
    src = rng.standard_normal((10, 3))
    dst = src * [1, 1, -1]  # a reflection: the best proper rotation is not the identity
    _, R, _ = umeyama_sim3(src, dst)
    assert abs(np.linalg.det(R) - 1) < 1e-12
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize(
    ("src", "message"),
    [
        (np.zeros((2, 3)), "at least 3"),
        (np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2], [5, 5, 5]]), "collinear"),
        (np.ones((4, 3)), "coincident"),
    ],
)
def test_umeyama_rejects_degenerate_input(src: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        umeyama_sim3(src, src + 1.0)


def test_umeyama_rejects_mismatched_shapes() -> None:
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        umeyama_sim3(np.zeros((4, 3)), np.zeros((5, 3)))


# ---------------------------------------------------------------------------------------------
# Pose errors


def test_rotation_angle_is_accurate_for_small_and_large_angles() -> None:
    axis = np.array([1.0, -2.0, 0.5])
    for angle in (1e-6, 0.01, 2.0, 90.0, 179.9):
        assert rotation_angle_deg(axis_angle(axis, angle)) == pytest.approx(angle, rel=1e-9)


def test_pose_errors_vanish_for_a_similar_copy_of_the_truth() -> None:
    rng = np.random.default_rng(4)
    truth = ring_of_cameras(rng)
    scale, R_a, t_a = 4.2, random_rotation(rng), rng.uniform(-10, 10, 3)
    estimated = {n: transform_world(p, scale, R_a, t_a) for n, p in truth.items()}
    # The estimated cameras really are the same cameras: their centres moved by the similarity.
    for n in truth:
        c_true, c_est = camera_center(truth[n]), camera_center(estimated[n])
        np.testing.assert_allclose(c_est, scale * R_a @ c_true + t_a, atol=1e-9)
    errors = pose_errors(estimated, truth)
    assert errors.scale == pytest.approx(1 / scale, rel=1e-9)
    assert set(errors.rotation_deg) == set(truth)
    assert errors.max_rotation_deg < 1e-6
    assert errors.max_center < 1e-9


def test_pose_errors_detect_a_two_degree_rotation() -> None:
    rng = np.random.default_rng(5)
    truth = ring_of_cameras(rng)
    R_a = random_rotation(rng)
    estimated = {n: transform_world(p, 0.5, R_a, np.ones(3)) for n, p in truth.items()}
    name = "img_03.jpg"
    R, t = estimated[name][:, :3], estimated[name][:, 3]
    center = -R.T @ t
    R_turned = axis_angle(np.array([0.3, 1.0, -0.2]), 2.0) @ R  # turn the camera, keep its centre
    estimated[name] = np.column_stack([R_turned, -R_turned @ center])
    errors = pose_errors(estimated, truth)
    assert errors.rotation_deg[name] == pytest.approx(2.0, abs=1e-9)
    others = [e for n, e in errors.rotation_deg.items() if n != name]
    assert max(others) < 1e-6
    assert errors.max_rotation_deg == pytest.approx(2.0, abs=1e-9)
    assert errors.median_rotation_deg < 1e-6
    assert errors.max_center < 1e-9  # the centre did not move
    assert "8 cameras" in errors.summary()


def test_pose_errors_measure_a_moved_centre_in_truth_units() -> None:
    rng = np.random.default_rng(6)
    truth = ring_of_cameras(rng, n=12)
    estimated = {n: transform_world(p, 3.0, np.eye(3), np.zeros(3)) for n, p in truth.items()}
    name = "img_05.jpg"
    R, t = estimated[name][:, :3], estimated[name][:, 3]
    moved = -R.T @ t + np.array([0.0, 0.0, 3.0 * 0.1])  # 0.1 truth units in estimate units
    estimated[name] = np.column_stack([R, -R @ moved])
    errors = pose_errors(estimated, truth)
    # The similarity absorbs a little of the move (and turns the other cameras slightly), so
    # the error is a bit under 0.1.
    assert 0.08 < errors.center[name] < 0.1
    assert errors.max_center == errors.center[name]
    assert errors.scale == pytest.approx(1 / 3.0, rel=0.01)


def test_pose_errors_use_only_common_images() -> None:
    rng = np.random.default_rng(7)
    truth = ring_of_cameras(rng)
    estimated = {n: p for n, p in truth.items() if n != "img_00.jpg"}
    estimated["not_in_truth.jpg"] = truth["img_00.jpg"]
    errors = pose_errors(estimated, truth)
    assert set(errors.center) == set(truth) - {"img_00.jpg"}
    with pytest.raises(ValueError, match="at least 3"):
        pose_errors({n: truth[n] for n in list(truth)[:2]}, truth)


def test_focal_error_is_signed_relative() -> None:
    assert focal_error(606.0, 600.0) == pytest.approx(0.01)
    assert focal_error(594.0, 600.0) == pytest.approx(-0.01)
    with pytest.raises(ValueError):
        focal_error(600.0, 0.0)


# ---------------------------------------------------------------------------------------------
# Ground truth by path (the file format itself: tests/recon/test_cameras.py)


def test_ground_truth_json_loads_exactly_with_its_mean_focal(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    cameras = [
        Camera(name, 640, 480, [[600.0 + k, 0.0, 320.0], [0.0, 601.0 + k, 240.0], [0, 0, 1]], pose)
        for k, (name, pose) in enumerate(ring_of_cameras(rng, n=3).items())
    ]
    path = tmp_path / "sub" / "truth.json"
    write_cameras_json(path, cameras)
    truth = load_ground_truth(path)
    assert truth.focal_px == pytest.approx(601.5)  # mean of fx and fy over the cameras
    assert truth.cameras is not None and set(truth.cameras) == {c.name for c in cameras}
    for cam in cameras:
        assert truth.cameras[cam.name] == cam
        np.testing.assert_allclose(truth.cameras[cam.name].center_in_world,
                                   camera_center(cam.cam_from_world))
    with pytest.raises(ValueError, match="not a ground truth"):
        load_ground_truth(tmp_path / "sub")


# ---------------------------------------------------------------------------------------------
# Public data sets (../shared/data, absent in a fresh clone)


def _converging_point(cameras: dict[str, Camera]) -> np.ndarray:
    """Least-squares point closest to every optical axis."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for cam in cameras.values():
        axis = cam.cam_from_world[2, :3]  # the camera's z axis in world coordinates
        P = np.eye(3) - np.outer(axis, axis)
        A += P
        b += P @ cam.center_in_world
    return np.linalg.solve(A, b)


def _assert_rotations_proper(cameras: dict[str, Camera]) -> None:
    for cam in cameras.values():
        R = cam.cam_from_world[:, :3]
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-5)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-5)


@pytest.mark.shared_data
def test_read_middlebury_temple_ring() -> None:
    path = shared_dataset("temple_sparse_ring") / "templeSR_par.txt"
    cameras = read_middlebury_par(path)
    assert len(cameras) == 16
    assert sorted(cameras)[0] == "templeSR0001.png"
    assert all(path.with_name(n).exists() for n in cameras)
    _assert_rotations_proper(cameras)
    for cam in cameras.values():
        assert (cam.width, cam.height) == (640, 480)
        np.testing.assert_allclose(
            cam.K, [[1520.4, 0, 302.32], [0, 1525.9, 246.87], [0, 0, 1]], atol=1e-9
        )
        # The centre of the temple's bounding box (from its README) is in view of every camera.
        center = np.array([-0.073568 + 0.028855, 0.021728 + 0.181892, -0.012445 + 0.062736]) / 2
        x = cam.K @ (cam.cam_from_world[:, :3] @ center + cam.cam_from_world[:, 3])
        assert x[2] > 0
        assert 0 < x[0] / x[2] < 640 and 0 < x[1] / x[2] < 480


@pytest.mark.shared_data
def test_read_strecha_fountain() -> None:
    folder = shared_dataset("fountain_p11") / "gt_dense_cameras"
    cameras = read_strecha_cameras(folder)
    assert sorted(cameras) == [f"{i:04d}.jpg" for i in range(11)]
    K_txt = np.loadtxt(folder.parent / "images" / "K.txt")
    _assert_rotations_proper(cameras)
    for name, cam in cameras.items():
        assert (cam.width, cam.height) == (3072, 2048)
        np.testing.assert_allclose(cam.K, K_txt, atol=1e-9)
        # The file's eighth row is the camera centre, recovered from [R^T | -R^T C] up to the
        # rounding of R to 6 digits in the file.
        rows = (folder / f"{name}.camera").read_text().split("\n")
        np.testing.assert_allclose(
            cam.center_in_world, [float(v) for v in rows[7].split()], atol=1e-4
        )
    # With the right convention all optical axes converge in front of every camera.
    point = _converging_point(cameras)
    for cam in cameras.values():
        x = cam.K @ (cam.cam_from_world[:, :3] @ point + cam.cam_from_world[:, 3])
        assert x[2] > 0
        assert 0 < x[0] / x[2] < 3072 and 0 < x[1] / x[2] < 2048
