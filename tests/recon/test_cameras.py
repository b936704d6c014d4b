"""The camera type: projection against hand-computed values and OpenCV; its JSON file."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.cameras import (
    CAMERAS_FORMAT,
    Camera,
    look_at,
    read_cameras_json,
    write_cameras_json,
)

K_VGA = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])


def _rot_y(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def _camera(dist=(), R=None, t=(0.0, 0.0, 5.0)) -> Camera:
    R = np.eye(3) if R is None else R
    return Camera("c", 640, 480, K_VGA, np.column_stack([R, t]), dist)


def test_project_known_point_by_hand():
    # x_cam = (1, 0.5, 5) -> (320 + 500 * 1 / 5, 240 + 500 * 0.5 / 5).
    uv, depth = _camera().project(np.array([[1.0, 0.5, 0.0]]))
    np.testing.assert_allclose(uv, [[420.0, 290.0]], atol=1e-12)
    np.testing.assert_allclose(depth, [5.0])
    # Rotated 90 degrees about y: world +X is the camera's forward axis -> x_cam = R @ X.
    R = _rot_y(-90.0)  # rows: camera axes in the world; R @ (1, 0, 0) = (0, 0, 1)
    uv, depth = _camera(R=R, t=(0.0, 0.0, 0.0)).project(np.array([[4.0, 0.4, 0.0]]))
    np.testing.assert_allclose(depth, [4.0], atol=1e-12)
    np.testing.assert_allclose(uv, [[320.0, 290.0]], atol=1e-9)


def test_project_matches_opencv_with_distortion_and_marks_points_behind():
    rng = np.random.default_rng(0)
    R = cv2.Rodrigues(np.array([0.1, -0.3, 0.05]))[0]
    camera = _camera(DIST, R, (0.2, -0.1, 4.0))
    points = rng.uniform(-1.0, 1.0, (200, 3))
    uv, depth = camera.project(points)
    expected, _ = cv2.projectPoints(points, cv2.Rodrigues(R)[0], camera.t, K_VGA, DIST)
    np.testing.assert_allclose(uv, expected.reshape(-1, 2), atol=1e-9)
    behind = np.array([[0.0, 0.0, -10.0]]) @ R  # far behind along -z of the camera
    uv_b, depth_b = camera.project(behind)
    assert depth_b[0] < 0 and np.isnan(uv_b).all()


def test_center_and_look_at():
    center = np.array([1.0, 2.0, 3.0])
    cam_from_world = look_at(center, np.zeros(3))
    camera = Camera("c", 640, 480, K_VGA, cam_from_world)
    np.testing.assert_allclose(camera.center_in_world, center, atol=1e-12)
    uv, depth = camera.project(np.zeros((1, 3)))
    np.testing.assert_allclose(uv, [[320.0, 240.0]], atol=1e-9)  # the target is centred
    assert depth[0] == pytest.approx(np.linalg.norm(center))


def test_pixel_rays_invert_the_distortion():
    camera = _camera(DIST)
    rays = camera.pixel_rays_in_camera
    assert rays.shape == (480, 640, 3)
    sample = rays[::37, ::41].reshape(-1, 3)
    u, v = np.meshgrid(np.arange(0, 640, 41) + 0.5, np.arange(0, 480, 37) + 0.5)
    points_in_world = (sample * 3.0 - camera.t) @ camera.R  # R = I: any depth along the ray
    uv, _ = camera.project(points_in_world)
    np.testing.assert_allclose(uv, np.stack([u.ravel(), v.ravel()], 1), atol=1e-6)


def test_scaled_maps_pixel_edges_exactly():
    camera = _camera(DIST)
    points = np.random.default_rng(1).uniform(-1.0, 1.0, (50, 3))
    uv, _ = camera.project(points)
    half = camera.scaled(0.5)
    assert (half.width, half.height) == (320, 240)
    np.testing.assert_allclose(half.project(points)[0], uv / 2, atol=1e-9)
    # Odd sizes: each axis keeps its own exact ratio, so the image corners still match.
    odd = Camera("o", 641, 481, K_VGA, camera.cam_from_world).scaled(0.5)
    assert (odd.width, odd.height) == (320, 240)
    np.testing.assert_allclose(np.diag(odd.K)[:2], [500 * 320 / 641, 500 * 240 / 481])


def test_invalid_parameters_are_refused():
    with pytest.raises(ValueError, match="not a rotation"):
        Camera("c", 640, 480, K_VGA, np.column_stack([2 * np.eye(3), np.zeros(3)]))
    with pytest.raises(ValueError, match="positive integer"):
        Camera("c", 0, 480, K_VGA, np.column_stack([np.eye(3), np.zeros(3)]))
    with pytest.raises(ValueError, match="at most 5"):
        _camera(dist=np.zeros(8))


def test_look_at_rolls_the_picture_counter_clockwise() -> None:
    # Z up (the synthetic room's world): a 90 degree roll turns the camera's right onto its
    # down, so a point to the right of the target (world +X seen from -Y) rises in the image.
    center, target = np.array([0.0, -3.0, 1.0]), np.array([0.0, 0.0, 1.0])
    upright = Camera("u", 640, 480, K_VGA, look_at(center, target, (0.0, 0.0, 1.0)))
    rolled = Camera("r", 640, 480, K_VGA, look_at(center, target, (0.0, 0.0, 1.0), 90.0))
    right = np.array([[0.5, 0.0, 1.0]])
    np.testing.assert_allclose(upright.project(right)[0], [[320.0 + 500 * 0.5 / 3, 240.0]],
                               atol=1e-9)
    np.testing.assert_allclose(rolled.project(right)[0], [[320.0, 240.0 - 500 * 0.5 / 3]],
                               atol=1e-9)
    np.testing.assert_allclose(rolled.center_in_world, center, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# mocap-cameras-v1


def test_json_round_trip_is_exact(tmp_path):
    cams = [Camera(f"cam{k}", 640, 480, K_VGA,
                   look_at([3.0 * math.sin(k), 1.2, 3.0 * math.cos(k)], np.zeros(3)))
            for k in range(3)] + [_camera(DIST)]
    path = tmp_path / "rig.json"
    write_cameras_json(path, cams)
    assert json.loads(path.read_text())["format"] == CAMERAS_FORMAT
    assert read_cameras_json(path) == cams  # exactly, in the given order
    assert not list(tmp_path.glob("*partial*"))


def test_reads_files_without_distortion_as_pinhole_cameras(tmp_path: Path) -> None:
    # Ground truth written before the camera types were one has no "dist": it reads as zeros.
    pose = look_at([1.0, 2.0, 3.0], np.zeros(3))
    path = tmp_path / "truth.json"
    path.write_text(json.dumps({"format": "mocap-cameras-v1", "cameras": {
        "view_001.png": {"width": 640, "height": 480, "K": K_VGA.tolist(),
                         "cam_from_world": pose.tolist()},
        "view_000.png": {"width": 640, "height": 480, "K": K_VGA.tolist(),
                         "cam_from_world": pose.tolist()}}}))
    cams = read_cameras_json(path)
    assert [c.name for c in cams] == ["view_001.png", "view_000.png"]  # file order
    assert not any(c.has_distortion for c in cams)
    np.testing.assert_array_equal(cams[0].cam_from_world, pose)
    assert cams[0].focal_px == 500.0


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not valid JSON"),
        ('{"format": "other", "cameras": {}}', "mocap-cameras-v1"),
        ('{"format": "mocap-cameras-v1"}', "cameras"),
        ('{"format": "mocap-cameras-v1", "cameras": {}}', "empty"),
        (
            '{"format": "mocap-cameras-v1", "cameras": {"a.png": {"width": 4, "height": 3, '
            '"K": [[1, 0, 0], [0, 1, 0]], "cam_from_world": [[1, 0, 0, 0], [0, 1, 0, 0], '
            "[0, 0, 1, 0]]}}}",
            "K has shape",
        ),
        ('{"format": "mocap-cameras-v1", "cameras": {"a.png": {"width": 4}}}', "lacks"),
        ('{"format": "mocap-cameras-v1", "cameras": {"a": {"width": 4, "height": 3, "K": '
         '"x", "cam_from_world": []}}}', "numeric"),
    ],
)
def test_malformed_files_give_one_line_value_errors(tmp_path: Path, content: str,
                                                    message: str) -> None:
    path = tmp_path / "cameras.json"
    path.write_text(content)
    with pytest.raises(ValueError, match=message) as info:
        read_cameras_json(path)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


def test_write_refuses_duplicate_names(tmp_path: Path):
    cam = _camera()
    with pytest.raises(ValueError, match="unique"):
        write_cameras_json(tmp_path / "x.json", [cam, cam])
    assert not (tmp_path / "x.json").exists()
