"""Rigs of cameras and the readers of calibration files, against OpenCV, pycolmap and the
Pose2Sim demo (the camera type itself: tests/recon/test_cameras.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pycolmap
import pytest

from recon.cameras import Camera, write_cameras_json
from tests.helpers import shared_dataset
from tracking.rig.cameras import read_cameras, rig_up, ring_cameras, upright_frame

K_VGA = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])


def test_ring_cameras_look_at_the_target_from_a_circle():
    target = np.array([0.5, 1.0, -0.2])
    cams = ring_cameras(6, 3.0, 1.6, target, 640, 480, 550.0)
    assert [c.name for c in cams] == [f"cam{k:02d}" for k in range(6)]
    for k, cam in enumerate(cams):
        c = cam.center_in_world
        assert c[1] == pytest.approx(1.6)
        assert math.hypot(c[0] - target[0], c[2] - target[2]) == pytest.approx(3.0)
        uv, _ = cam.project(target[None])
        np.testing.assert_allclose(uv, [[320.0, 240.0]], atol=1e-9)
        # Image up is world up: a point above the target is higher in the image (smaller v).
        assert cam.project((target + [0, 0.3, 0])[None])[0][0, 1] < 240.0
        azimuth = math.degrees(math.atan2(c[0] - target[0], c[2] - target[2])) % 360
        assert azimuth == pytest.approx(60.0 * k, abs=1e-9)
    # cam00 is on +Z, in front of a body facing +Z: the body's left (+X) is on the image right.
    assert cams[0].project((target + [0.3, 0, 0])[None])[0][0, 0] > 320.0


def test_upright_frame_of_a_z_up_rig_and_cameras_in_it():
    """A ring of cameras above the subject in a Z-up world (Qualisys, Pose2Sim): the rig's up
    is +Z, its upright frame takes +Y there, and a camera moved into that frame projects the
    frame's points where the world camera projects their world positions."""
    world_from_yup = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # Y -> Z
    yup = ring_cameras(4, 4.0, 2.5, (0.3, 0.9, -0.2))
    zup = [c.in_frame(world_from_yup.T) for c in yup]
    subject = world_from_yup @ np.array([0.3, 0.9, -0.2])
    assert np.allclose(rig_up(zup, subject), [0.0, 0.0, 1.0])
    frame = upright_frame(zup, subject)
    assert np.allclose(frame @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    assert np.allclose(frame @ frame.T, np.eye(3)) and np.isclose(np.linalg.det(frame), 1.0)
    points = np.random.default_rng(0).uniform(-1.0, 1.0, (20, 3)) + [0.3, 0.9, -0.2]
    for cam_yup, cam_zup in zip(yup, zup, strict=True):
        uv, depth = cam_zup.in_frame(frame).project(points)  # points in the upright frame
        uv0, depth0 = cam_zup.project(points @ frame.T)  # ... and in the world
        assert np.allclose(uv, uv0) and np.allclose(depth, depth0)
        assert np.allclose(cam_yup.project(points)[0],
                           cam_zup.project(points @ world_from_yup.T)[0])
    # A Y-up rig needs no rotation; a level rig (or two cameras) tells nothing.
    assert np.array_equal(upright_frame(yup, [0.3, 0.9, -0.2]), np.eye(3))
    level = ring_cameras(4, 4.0, 0.9, (0.0, 0.9, 0.0))
    assert rig_up(level, [0.0, 0.9, 0.0]) is None and rig_up(yup[:2], [0.0, 0.9, 0.0]) is None
    assert np.array_equal(upright_frame(level, [0.0, 0.9, 0.0]), np.eye(3))


def test_reads_mocap_cameras_json_by_suffix_or_content(tmp_path):
    cams = [*ring_cameras(2, 2.0, 1.0),
            Camera("d", 640, 480, K_VGA, ring_cameras(1, 3.0, 1.0)[0].cam_from_world, DIST)]
    write_cameras_json(tmp_path / "rig.json", cams)
    (tmp_path / "calibration").write_bytes((tmp_path / "rig.json").read_bytes())
    assert read_cameras(tmp_path / "rig.json") == cams
    assert read_cameras(tmp_path / "calibration") == cams


def test_colmap_model_projects_like_pycolmap(tmp_path):
    pycolmap.set_random_seed(0)
    options = pycolmap.SyntheticDatasetOptions(num_rigs=1, num_cameras_per_rig=1,
                                               num_frames_per_rig=3, num_points3D=40)
    options.camera_model_id = pycolmap.CameraModelId.OPENCV
    options.camera_params = [700.0, 710.0, 300.0, 250.0, -0.1, 0.02, 0.001, -0.002]
    with pycolmap.Database.open(tmp_path / "db.db") as db:
        truth = pycolmap.synthesize_dataset(options, db)
    (tmp_path / "model").mkdir()
    truth.write(tmp_path / "model")
    cams = read_cameras(tmp_path / "model")
    images = sorted(truth.images.values(), key=lambda im: im.name)
    assert [c.name for c in cams] == [im.name for im in images]
    points = np.array([p.xyz for p in truth.points3D.values()])
    for cam, image in zip(cams, images, strict=True):
        colmap_cam = truth.cameras[image.camera_id]
        expected = np.array([colmap_cam.img_from_cam(image.cam_from_world() * p)
                             for p in points])
        np.testing.assert_allclose(cam.project(points)[0], expected, atol=1e-6)


def _toml_camera(name: str, *, K=K_VGA, dist=DIST[:4], rotation=(0.1, -0.3, 0.05),
                 translation=(0.2, -0.1, 4.0), size=(640, 480), fisheye=False) -> str:
    """One camera table of a Pose2Sim Calib.toml, in OpenCV's conventions (pixel centres at
    integers), as Pose2Sim's calibration writes it."""
    def row(values) -> str:
        return "[ " + ", ".join(repr(float(v)) for v in values) + "]"

    K = np.asarray(K, dtype=float)
    return (f'[{name}]\nname = "{name}"\nsize = {row(size)}\n'
            f"matrix = [ {', '.join(row(r) for r in K)}]\n"
            f"distortions = {row(dist)}\nrotation = {row(rotation)}\n"
            f"translation = {row(translation)}\nfisheye = {str(fisheye).lower()}\n\n")


def test_pose2sim_toml_projects_like_opencv(tmp_path):
    # Two cameras and Pose2Sim's [metadata] table; OpenCV's projectPoints with the file's own
    # numbers is the reference, half a pixel off (pixel centres at integers there).
    rvecs = [np.array([0.1, -0.3, 0.05]), np.array([1.69, 1.05, -0.42])]
    tvecs = [np.array([0.2, -0.1, 4.0]), np.array([0.32, 0.96, 2.89])]
    K_opencv = np.array([[1681.2, 0.0, 533.0], [0.0, 1681.1, 948.1], [0.0, 0.0, 1.0]])
    path = tmp_path / "Calib.toml"
    path.write_text(_toml_camera("cam_01", rotation=rvecs[0], translation=tvecs[0])
                    + _toml_camera("cam_02", K=K_opencv, dist=DIST, rotation=rvecs[1],
                                   translation=tvecs[1], size=(1088, 1920))
                    + "[metadata]\nadjusted = false\nerror = 0.0\n")
    cams = read_cameras(path)
    assert [(c.name, c.width, c.height) for c in cams] == [("cam_01", 640, 480),
                                                          ("cam_02", 1088, 1920)]
    points = np.random.default_rng(1).uniform(-1.0, 1.0, (100, 3))
    for cam, K, dist, rvec, tvec in zip(cams, [K_VGA, K_opencv], [DIST[:4], DIST], rvecs,
                                        tvecs, strict=True):
        np.testing.assert_allclose(cam.R, cv2.Rodrigues(rvec)[0], atol=1e-12)
        expected, _ = cv2.projectPoints(points, rvec, tvec, K, dist)
        np.testing.assert_allclose(cam.project(points)[0], expected.reshape(-1, 2) + 0.5,
                                   atol=1e-9)


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("x.yaml", "a: 1\n", "unknown camera file format"),
        ("x.json", "{not json", "Expecting"),
        ("x.json", '{"format": "other"}', "mocap-cameras-v1"),
        ("x.json", '{"format": "mocap-cameras-v1", "cameras": {"a": {"width": 4}}}', "lacks"),
        ("x.qca.txt", "<calibration><cameras><camera serial='a'/></cameras></calibration>",
         "lacks"),
        ("x.qca.txt", "<other/>", "expected Qualisys"),
        ("x.qca.txt", "<calibration", "unclosed token"),
        ("x.toml", "[cam_1\n", "Expected"),
        ("x.toml", "[metadata]\nadjusted = false\n", "no camera table"),
        ("x.toml", "[c]\nmatrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n", "lacks"),
        ("x.toml", _toml_camera("c", fisheye=True), "fisheye"),
        ("x.toml", _toml_camera("c", rotation=[0.1, 0.2]), "Rodrigues"),
        ("x.toml", _toml_camera("c", size=[640.5, 480]), "whole pixels"),
    ],
)
def test_bad_files_give_one_line_value_errors(tmp_path, name, content, says):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(ValueError, match=says) as info:
        read_cameras(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_folder_that_is_not_a_model_and_missing_path(tmp_path):
    with pytest.raises(ValueError, match="not a COLMAP model"):
        read_cameras(tmp_path)
    with pytest.raises(ValueError, match="no such file"):
        read_cameras(tmp_path / "absent.json")


# ---------------------------------------------------------------------------------------------
# Real data: the Pose2Sim demo's Qualisys calibration


@pytest.mark.shared_data
def test_qualisys_calibration_of_the_pose2sim_demo():
    folder = shared_dataset("pose2sim_demo") / "calibration"
    cams = read_cameras(folder / "Calib.qca.txt")
    assert [c.name for c in cams] == ["cam01", "cam02", "cam03", "cam04"]
    document = (folder / "Calib.qca.txt").read_text()
    for cam in cams:
        # Portrait frames: the size must be that of the camera's own extrinsic shot.
        image = cv2.imread(str(folder / "extrinsics" / f"{cam.name}_ext.png"))
        assert (cam.height, cam.width) == image.shape[:2] == (1920, 1088)
        # 1/64 px -> px, with our +0.5 pixel-centre shift.
        assert 1670 < cam.K[0, 0] < 1690 and cam.K[0, 2] == pytest.approx(
            float(_attribute(document, cam.name, "centerPointU")) / 64 + 0.5)
        assert cam.K[1, 2] == pytest.approx(
            float(_attribute(document, cam.name, "centerPointV")) / 64 + 0.5)
        assert cam.dist[0] == pytest.approx(float(_attribute(document, cam.name,
                                                             "radialDistortion1")))
        # Position in mm -> metres, cameras 1.7-2.1 m above the Z-up lab floor.
        position_mm = [float(_attribute(document, cam.name, k)) for k in "xyz"]
        np.testing.assert_allclose(cam.center_in_world, np.array(position_mm) / 1000,
                                   atol=1e-9)
        assert 1.6 < cam.center_in_world[2] < 2.2
        # Every camera looks at the force plate around the lab origin, 2.5-4.5 m away, and
        # sees it well inside the frame; the lab's up (+Z) is up in the (portrait) image.
        uv, depth = cam.project(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
        assert 2.5 < depth[0] < 4.5
        assert 0.15 * cam.width < uv[0, 0] < 0.85 * cam.width
        assert 0.25 * cam.height < uv[0, 1] < 0.9 * cam.height
        assert uv[1, 1] < uv[0, 1] - 300  # 1 m up is > 300 px higher
        # ... within 27 degrees of the image vertical (the cameras look down and roll a bit).
        assert abs(uv[1, 0] - uv[0, 0]) < 0.5 * abs(uv[1, 1] - uv[0, 1])


@pytest.mark.shared_data
def test_pose2sim_toml_of_the_demo_reads_as_its_qualisys_file(tmp_path):
    # Pose2Sim converts Calib.qca.txt to Calib.toml (OpenCV's conventions: Rodrigues rotation,
    # metres, pixel centres at integers, cameras named cam_01...): the same cameras come back.
    cams = read_cameras(shared_dataset("pose2sim_demo") / "calibration" / "Calib.qca.txt")
    path = tmp_path / "Calib.toml"
    path.write_text("".join(
        _toml_camera(f"cam_{c.name[3:]}", K=c.K - np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]),
                     dist=c.dist, rotation=cv2.Rodrigues(c.R)[0].ravel(), translation=c.t,
                     size=(c.width, c.height))
        for c in cams))
    back = read_cameras(path)
    assert [c.name for c in back] == ["cam_01", "cam_02", "cam_03", "cam_04"]
    points = np.random.default_rng(2).uniform(-1.0, 1.0, (50, 3)) + [0.0, 0.0, 1.0]
    for a, b in zip(cams, back, strict=True):
        np.testing.assert_allclose(b.K, a.K, atol=1e-9)
        np.testing.assert_allclose(b.cam_from_world, a.cam_from_world, atol=1e-9)
        np.testing.assert_allclose(b.project(points)[0], a.project(points)[0], atol=1e-6)


def _attribute(document: str, serial: str, key: str) -> str:
    block = document.split(f'serial="{serial}"', 1)[1].split("</camera>", 1)[0]
    return block.split(f'{key}="', 1)[1].split('"', 1)[0]


@pytest.mark.shared_data
def test_qualisys_intrinsics_agree_with_the_demo_checkerboard():
    """An independent calibration from the demo's own checkerboard shots (7x4 inner corners)
    confirms the focal length in 1/64 px and the scale of the distortion terms (unscaled:
    Pose2Sim's extra /64 would make them ~0)."""
    folder = shared_dataset("pose2sim_demo") / "calibration"
    cam = read_cameras(folder / "Calib.qca.txt")[0]
    board = np.zeros((28, 3), np.float32)
    board[:, :2] = np.mgrid[0:7, 0:4].T.reshape(-1, 2)
    objects, corners = [], []
    for path in sorted((folder / "intrinsics" / "int_cam01_img").glob("*.jpg")):
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, points = cv2.findChessboardCorners(gray, (7, 4))
        if found:
            objects.append(board)
            corners.append(cv2.cornerSubPix(gray, points, (5, 5), (-1, -1), (3, 30, 0.01)))
    assert len(objects) >= 5
    K_cv = cam.K.copy()
    K_cv[:2, 2] -= 0.5  # OpenCV's pixel centres are at integers
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    _, K_fit, dist_fit, _, _ = cv2.calibrateCamera(objects, corners, (cam.width, cam.height),
                                                   K_cv, np.zeros(5), flags=flags)
    assert K_fit[0, 0] == pytest.approx(cam.K[0, 0], rel=0.02)
    # Same sign and order of magnitude as the file's k1 = -0.046, k2 = 0.14.
    assert -0.15 < dist_fit.ravel()[0] < -0.01 and 0.03 < dist_fit.ravel()[1] < 0.6


