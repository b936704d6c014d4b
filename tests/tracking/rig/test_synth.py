"""`mocap synth` against truth: joints from the poses, silhouettes from a fresh render, noise of
a moderate and stated size, the subject inside every view, and bad input as one line."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from plugins.registry import create
from recon.cameras import Camera
from recon.errors import UserError
from tests.helpers import read_recording, recording_entities, run_cli, shared_dataset
from tracking.body.bvh import write_bvh
from tracking.body.model import NODE_NAMES, BodyModel, BodyShape, Pose, node_positions_in_world
from tracking.body.motion import motion_from_poses
from tracking.body.mpfb.subject import MpfbModel
from tracking.rig.cameras import read_cameras
from tracking.rig.synth import (
    SynthConfig,
    hole_mask,
    iou,
    jitter_boundary,
    parse_size,
    place_cameras,
    select_clip_frames,
    shadow_polygon_in_world,
    synthesize,
)
from tracking.track.render import DEFAULT_RENDERER

# ---------------------------------------------------------------------------------------------
# Helpers


def _gt(root: Path) -> tuple[BodyShape, list[Pose], dict]:
    data = json.loads((root / "gt" / "pose.json").read_text())
    shape = BodyShape(**data["shape"])
    poses = [Pose(np.array(f["params"])) for f in sorted(data["frames"], key=lambda f: f["frame"])]
    return shape, poses, data


def _mask(root: Path, camera: str, frame: int) -> np.ndarray:
    image = cv2.imread(str(root / "silhouettes" / camera / f"{frame:06d}.png"),
                       cv2.IMREAD_UNCHANGED)
    assert image is not None and image.dtype == np.uint8 and image.ndim == 2
    assert set(np.unique(image)) <= {0, 255}
    return image > 0


def _fresh_renders(root: Path) -> dict[tuple[str, int], np.ndarray]:
    """The exact silhouettes of the gt poses through the workspace's cameras."""
    shape, poses, _ = _gt(root)
    model, renderer = BodyModel(shape), create("renderer", DEFAULT_RENDERER)
    cameras = read_cameras(root / "cameras.json")
    return {(c.name, k): renderer.render(model.posed_vertices(p), model.faces, c)
            for k, p in enumerate(poses) for c in cameras}


def _walking_body_bvh(path: Path, frames: int = 6) -> tuple[list[Pose], BodyShape]:
    """A body-model BVH: striding along +Z at 1.2 m/s, legs and arms swinging, 30 Hz."""
    shape = BodyShape.default(1.75)
    pelvis_height = shape.thigh + shape.shank + shape.ankle_height
    poses = []
    for k in range(frames):
        phase = 2 * np.pi * k / 15
        swing = 0.4 * np.sin(phase)
        poses.append(Pose.from_dict({
            "root_ty": pelvis_height - 0.02, "root_tz": -0.5 + 1.2 * k / 30,
            "l_hip_rx": -swing, "r_hip_rx": swing, "l_knee_flex": 0.3 + 0.3 * max(swing, 0),
            "r_knee_flex": 0.3 + 0.3 * max(-swing, 0), "l_shoulder_rx": swing / 2,
            "r_shoulder_rx": -swing / 2, "l_elbow_flex": 0.3, "r_elbow_flex": 0.3,
        }))  # fmt: skip
    write_bvh(motion_from_poses(poses, shape, 1 / 30), path)
    return poses, shape


@pytest.fixture(scope="module")
def body_bvh(tmp_path_factory) -> tuple[Path, list[Pose]]:
    path = tmp_path_factory.mktemp("bvh") / "stride.bvh"
    poses, _ = _walking_body_bvh(path)
    return path, poses


@pytest.fixture(scope="module")
def walk_clean(tmp_path_factory) -> Path:
    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    root = tmp_path_factory.mktemp("walk") / "clean"
    synthesize(root, SynthConfig(bvh=walk, body="superquadric", frames=4, cameras=4, clean=True))
    return root


@pytest.fixture(scope="module")
def walk_noisy(tmp_path_factory) -> Path:
    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    root = tmp_path_factory.mktemp("walk") / "noisy"
    synthesize(root, SynthConfig(bvh=walk, body="superquadric", frames=4, cameras=4, step=40))
    return root


# ---------------------------------------------------------------------------------------------
# Real clip (CMU walk, retargeted)


@pytest.mark.shared_data
def test_joints_csv_is_the_forward_kinematics_of_pose_json(walk_clean):
    shape, poses, data = _gt(walk_clean)
    assert data["frame_rate"] == pytest.approx(30.0, abs=0.01)  # 120 Hz clip, every 4th frame
    assert [f["clip_frame"] for f in data["frames"]] == [0, 4, 8, 12]
    with (walk_clean / "gt" / "joints.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["frame", "joint", "x", "y", "z"]
    assert len(rows) == len(poses) * len(NODE_NAMES) == 4 * 16
    for row in rows:
        truth = node_positions_in_world(poses[int(row["frame"])], shape)[row["joint"]]
        # Written with 6 decimals: micrometres.
        np.testing.assert_allclose([float(row[a]) for a in "xyz"], truth, atol=1e-6)
    # The retargeted subject is a plausible adult standing on the floor.
    assert 1.5 < shape.height < 2.0
    feet = np.array([[float(r["y"]) for r in rows if r["joint"].endswith("ankle")]])
    assert 0.0 < feet.min() < 0.2


@pytest.mark.shared_data
def test_clean_silhouettes_are_the_exact_renders(walk_clean):
    for (camera, frame), render in _fresh_renders(walk_clean).items():
        written = _mask(walk_clean, camera, frame)
        # Same renderer, same camera: at most 0.5% of the silhouette may differ (in fact 0).
        assert np.count_nonzero(written ^ render) <= 0.005 * np.count_nonzero(render)


@pytest.mark.shared_data
def test_subject_is_inside_every_view(walk_clean, walk_noisy):
    for root in (walk_clean, walk_noisy):
        summary = json.loads((root / "run.json").read_text())["steps"]["synth"]["summary"]
        assert summary["min_edge_margin_px"] >= 3.0
        shape, poses, _ = _gt(root)
        for camera in read_cameras(root / "cameras.json"):
            for k, pose in enumerate(poses):
                mask = _mask(root, camera.name, k)
                assert mask.sum() > 1000  # a person of ~200 px height is in view
                border = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
                assert not border.any(), (camera.name, k)
                joints = np.array(list(node_positions_in_world(pose, shape).values()))
                uv, depth = camera.project(joints)
                assert (depth > 0).all()
                assert (uv > 0).all() and (uv < [camera.width, camera.height]).all()


@pytest.mark.shared_data
def test_noise_is_present_but_moderate(walk_noisy):
    # The noisy silhouettes against the exact renders of the same poses and cameras. At the
    # defaults (jitter 0.6 px RMS, 2 holes of 2.5 cm, a 40 x 20 cm floor shadow) and 640x480,
    # the walk's IoU is ~0.89 (0.85-0.93 over the clip): the bounds leave room for that spread.
    summary = json.loads((walk_noisy / "run.json").read_text())["steps"]["synth"]["summary"]
    shape, poses, _ = _gt(walk_noisy)
    cameras = {c.name: c for c in read_cameras(walk_noisy / "cameras.json")}
    values = []
    for (camera, frame), clean in _fresh_renders(walk_noisy).items():
        noisy = _mask(walk_noisy, camera, frame)
        values.append(iou(noisy, clean))
        added, removed = noisy & ~clean, clean & ~noisy
        assert added.any() and removed.any()  # shadow/jitter add, jitter/holes remove
        # Whatever is added lies on the body or the shadow ellipse under the feet, give or take
        # the jitter (0.6 px RMS: 4 px is > 6 RMS): no specks, no drift.
        joints = node_positions_in_world(poses[frame], shape)
        outline = shadow_polygon_in_world(np.array([joints["l_ankle"], joints["r_ankle"]]),
                                          summary["floor_y_m"], SynthConfig(bvh=Path("x")))
        uv, _ = cameras[camera].project(outline)
        shadow = np.zeros_like(clean, dtype=np.uint8)
        cv2.fillPoly(shadow, [np.round(uv - 0.5).astype(np.int32)], 1)
        near = cv2.dilate((clean | (shadow > 0)).astype(np.uint8), np.ones((9, 9), np.uint8))
        assert not (added & (near == 0)).any()
        assert np.count_nonzero(noisy & (shadow > 0) & ~clean) > 20  # the shadow is there
    assert 0.85 <= np.mean(values) <= 0.97
    assert min(values) >= 0.78 and max(values) <= 0.99
    assert summary["noise"]["mean_iou"] == pytest.approx(np.mean(values), abs=1e-9)


@pytest.mark.shared_data
def test_cameras_ring_reads_back(walk_noisy):
    cameras = read_cameras(walk_noisy / "cameras.json")
    assert [c.name for c in cameras] == ["cam00", "cam01", "cam02", "cam03"]
    summary = json.loads((walk_noisy / "run.json").read_text())["steps"]["synth"]["summary"]
    shape, poses, _ = _gt(walk_noisy)
    pelvis = np.array([node_positions_in_world(p, shape)["pelvis"] for p in poses]).mean(axis=0)
    for camera in cameras:
        assert (camera.width, camera.height) == (640, 480)
        fov = 2 * math.degrees(math.atan(camera.width / 2 / camera.K[0, 0]))
        assert fov == pytest.approx(50.0, abs=1e-9)
        centre = camera.center_in_world
        assert math.hypot(*(centre - pelvis)[[0, 2]]) == pytest.approx(summary["radius_m"],
                                                                         abs=1e-6)
        assert centre[1] - summary["floor_y_m"] == pytest.approx(1.5, abs=1e-9)
    entities = recording_entities(walk_noisy / "logs" / "synth.rrd")
    assert "/world/cameras/cam00/image@Pinhole:image_from_camera" in entities
    assert "/world/cameras/cam00@Transform3D:mat3x3" in entities
    assert "/world/cameras/cam03/image@SegmentationImage:buffer" in entities
    assert "/world/gt/joints@Points3D:positions" in entities
    read = read_recording(walk_noisy / "logs" / "synth.rrd")
    assert read.timeline == "frame" and read.layout_problems() == []


# ---------------------------------------------------------------------------------------------
# Body-model BVH (no retargeting: the poses come back exactly)


def test_body_bvh_poses_are_the_ground_truth(body_bvh, tmp_path):
    path, poses = body_bvh
    result = synthesize(tmp_path / "ws", SynthConfig(bvh=path, body="superquadric", cameras=2,
                                                     size="320x240", clean=True))
    shape, gt_poses, data = _gt(tmp_path / "ws")
    assert result.summary["frames"] == len(poses) == len(gt_poses)
    assert data["frame_rate"] == pytest.approx(30.0)
    for truth, got in zip(poses, gt_poses, strict=True):
        np.testing.assert_allclose(got.params, truth.params, atol=1e-5)  # BVH text precision
    for (camera, frame), render in _fresh_renders(tmp_path / "ws").items():
        assert np.array_equal(_mask(tmp_path / "ws", camera, frame), render)


def test_rerun_is_skipped_and_overwrite_redoes(body_bvh, tmp_path):
    path, _ = body_bvh
    ws = tmp_path / "ws"
    args = ("synth", ws, "--bvh", path, "--cameras", "2", "--size", "200x150", "--frames", "3")
    first = run_cli(*args)
    assert first.returncode == 0, first.stderr
    assert "3 frames x 2 cameras 200x150" in first.stdout
    finished = json.loads((ws / "run.json").read_text())["steps"]["synth"]["finished"]
    stamp = (ws / "silhouettes" / "cam01" / "000002.png").stat().st_mtime_ns
    again = run_cli(*args)
    assert again.returncode == 0 and "up to date" in again.stdout
    assert json.loads((ws / "run.json").read_text())["steps"]["synth"]["finished"] == finished
    assert (ws / "silhouettes" / "cam01" / "000002.png").stat().st_mtime_ns == stamp
    assert sorted(p.name for p in (ws / "silhouettes" / "cam00").iterdir()) == [
        "000000.png", "000001.png", "000002.png"]  # fmt: skip
    redo = run_cli(*args, "--overwrite")
    assert redo.returncode == 0 and "up to date" not in redo.stdout
    # A new seed is a new config: recomputed, and the noise differs.
    before = _mask(ws, "cam00", 1)
    reseeded = run_cli(*args, "--seed", "7")
    assert reseeded.returncode == 0 and "up to date" not in reseeded.stdout
    assert not np.array_equal(_mask(ws, "cam00", 1), before)
    assert not list(ws.rglob("*.partial*"))


def _decoded(video: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(video))
    frames = []
    while (read := capture.read())[0]:
        frames.append(read[1])
    capture.release()
    return frames


def test_videos_show_the_subject_over_the_empty_scene(body_bvh, tmp_path):
    """--videos: per camera a video whose frame k shows the exact silhouette of frame k in the
    subject's red over the camera's empty scene, which is also written as a photo."""
    path, _ = body_bvh
    ws = tmp_path / "ws"
    config = SynthConfig(bvh=path, body="superquadric", cameras=2, size="200x150", frames=3,
                         clean=True, videos=True)
    result = synthesize(ws, config)
    assert any(line.startswith("videos      ") for line in result.lines())
    for camera in ("cam00", "cam01"):
        frames = _decoded(ws / "render" / "videos" / f"{camera}.avi")
        photo = cv2.imread(str(ws / "render" / "backgrounds" / f"{camera}.png"))
        assert len(frames) == 3 and photo.shape == frames[0].shape == (150, 200, 3)
        for k, frame in enumerate(frames):
            mask = _mask(ws, camera, k).astype(np.uint8)
            inside = cv2.erode(mask, np.ones((5, 5), np.uint8)) > 0
            outside = cv2.dilate(mask, np.ones((7, 7), np.uint8)) == 0
            assert inside.sum() > 200
            # MJPG at quality 95: a grey level or two away from the exact pictures.
            assert np.abs(frame[outside].astype(int) - photo[outside]).mean() < 3.0
            assert frame[inside][:, 2].mean() > 200 and frame[inside][:, 0].mean() < 80
    # The same settings again: reused; without --videos, the videos of the old settings go.
    assert synthesize(ws, config).reused
    synthesize(ws, replace(config, videos=False))
    assert not (ws / "render").exists()


def _assert_one_line_error(result, needle: str) -> None:
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], result.stderr


def test_bad_input_is_one_line(body_bvh, tmp_path):
    path, _ = body_bvh
    garbage = tmp_path / "garbage.bvh"
    garbage.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    ws = tmp_path / "ws"
    _assert_one_line_error(run_cli("synth", ws, "--bvh", tmp_path / "nope.bvh"), "nope.bvh")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", garbage), "garbage.bvh")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", path, "--size", "640by480"), "--size")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", path, "--frames", "7"), "--frames 7")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", path, "--frames", "0"), "--frames 0")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", path, "--seed", "-1"), "--seed")
    _assert_one_line_error(run_cli("synth", ws, "--bvh", path, "--radius", "1"),
                           "leaves the view")
    assert not ws.exists() or not any(ws.iterdir())


# ---------------------------------------------------------------------------------------------
# Pure parts


def test_clip_frames_and_size():
    frames, step = select_clip_frames(343, 120.0048, step=None, fps=30.0, frames=None)
    assert step == 4 and len(frames) == 86 and frames[-1] == 340
    frames, step = select_clip_frames(343, 120.0, step=10, fps=30.0, frames=5)
    assert step == 10 and list(frames) == [0, 10, 20, 30, 40]
    with pytest.raises(UserError, match="1..35"):
        select_clip_frames(343, 120.0, step=10, fps=30.0, frames=36)
    with pytest.raises(UserError, match="--step"):
        select_clip_frames(343, 120.0, step=0, fps=30.0, frames=None)
    assert parse_size("640x480") == (640, 480)
    for bad in ("640", "x480", "0x480", "-1x3", "640x480x3"):
        with pytest.raises(UserError, match="--size"):
            parse_size(bad)


def _disc(size: int = 200, radius: float = 50.0) -> np.ndarray:
    ys, xs = np.mgrid[:size, :size] + 0.5
    return (xs - size / 2) ** 2 + (ys - size / 2) ** 2 <= radius**2


def test_jitter_moves_the_outline_by_about_its_amplitude():
    disc = _disc()
    perimeter = 2 * np.pi * 50.0
    for amplitude in (0.6, 1.5):
        out = jitter_boundary(disc, amplitude, 12.0, np.random.default_rng(1))
        # Symmetric difference / perimeter = mean |normal displacement| ~ 0.8 x RMS (Gaussian).
        mean_shift = np.count_nonzero(out ^ disc) / perimeter
        assert 0.4 * amplitude < mean_shift < 1.2 * amplitude
        # Every change sits within 4 RMS of the true outline.
        ys, xs = np.nonzero(out ^ disc)
        r = np.hypot(xs + 0.5 - 100, ys + 0.5 - 100)
        assert np.abs(r - 50).max() < 4 * amplitude + 1
    same = jitter_boundary(disc, 1.0, 12.0, np.random.default_rng(3))
    assert np.array_equal(same, jitter_boundary(disc, 1.0, 12.0, np.random.default_rng(3)))
    assert np.array_equal(jitter_boundary(disc, 0.0, 12.0, np.random.default_rng(3)), disc)


def test_holes_stay_well_inside_the_body():
    disc = _disc()
    rng = np.random.default_rng(0)
    counts = []
    for _ in range(40):
        holes = hole_mask(disc, 3.0, 4.0, 5.0, rng)
        counts.append(cv2.connectedComponents(holes.astype(np.uint8))[0] - 1)
        ys, xs = np.nonzero(holes)
        if len(ys):
            # Centre at least 6 px (max semi-axis) + 5 px keep-out inside: the hole ends >= 5 px
            # (1 px of rasterisation aside) from the outline.
            assert np.hypot(xs + 0.5 - 100, ys + 0.5 - 100).max() <= 50 - 4
    assert 2.0 < np.mean(counts) <= 3.5  # Poisson(3), minus overlaps


def test_shadow_lies_on_the_floor_under_the_feet():
    config = SynthConfig(bvh=Path("x"), shadow_length_m=0.4, shadow_width_m=0.2,
                         shadow_offset_m=0.1, shadow_azimuth_deg=90.0)
    feet = np.array([[0.9, 0.1, 2.0], [1.1, 0.12, 2.2]])
    outline = shadow_polygon_in_world(feet, 0.02, config)
    np.testing.assert_allclose(outline[:, 1], 0.02)
    centre = outline.mean(axis=0)
    np.testing.assert_allclose(centre[[0, 2]], [1.0 + 0.1, 2.1], atol=1e-12)  # azimuth 90: +X
    np.testing.assert_allclose(np.ptp(outline[:, 0]), 0.4, atol=1e-3)
    np.testing.assert_allclose(np.ptp(outline[:, 2]), 0.2, atol=1e-3)


def test_ring_grows_until_the_subject_fits():
    # A 1.8 m pole walking 4 m along Z: a 4 m ring would put a camera on its path.
    ys = np.linspace(0.0, 1.8, 10)
    frames = [np.stack([np.zeros(10), ys, np.full(10, z)], axis=1) for z in np.linspace(-2, 2, 5)]
    vertices = np.stack(frames)
    pelvis = vertices[:, 5]
    config = SynthConfig(bvh=Path("x"), cameras=3)
    cameras, radius, margin = place_cameras(vertices, pelvis, 0.0, 1.8, (320, 240), config)
    assert radius > 4.0 and margin >= 3.0
    assert all(isinstance(c, Camera) for c in cameras)
    again, _, _ = place_cameras(vertices, pelvis, 0.0, 1.8, (320, 240),
                                  replace(config, radius_m=radius))
    assert again[0] == cameras[0]  # an explicit radius gives the same ring
    with pytest.raises(UserError, match="leaves the view of cam0[02]"):
        place_cameras(vertices, pelvis, 0.0, 1.8, (320, 240), replace(config, radius_m=4.0))


@pytest.mark.shared_data
@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
def test_report_of_a_synthetic_sequence_reports_its_ground_truth_only_when_asked(tmp_path):
    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    ws = tmp_path / "walk"
    made = run_cli("synth", ws, "--bvh", walk, "--frames", "24", "--size", "160x120", "--clean")
    assert made.returncode == 0, made.stderr
    # Not tracked yet: refused in one line that points at --truth, and nothing is written, so
    # no report of the truth can pass for one of a tracked motion.
    refused = run_cli("report", ws)
    assert refused.returncode == 2 and refused.stderr.strip().count("\n") == 0
    assert "tracks/pose.json not found" in refused.stderr and "--truth" in refused.stderr
    assert not (ws / "report").exists() and not (ws / "logs" / "report.rrd").exists()
    report = run_cli("report", ws, "--truth")
    assert report.returncode == 0, report.stderr
    assert "gt/pose.json" in report.stdout and str(ws / "gt" / "report") in report.stdout
    assert (ws / "logs" / "report-truth.rrd").is_file() and not (ws / "report").exists()
    with (ws / "gt" / "report" / "center_of_mass.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 24
    # The CMU walk moves at about 1.25 m/s along Z: the centre of mass follows.
    speed = (float(rows[-1]["z"]) - float(rows[0]["z"])) / (float(rows[-1]["time_s"]))
    assert 1.0 < abs(speed) < 1.5


def test_clip_frames_from_a_first_frame():
    frames, step = select_clip_frames(343, 120.0, step=4, fps=30.0, frames=None, first=1)
    assert step == 4 and frames[0] == 1 and frames[-1] == 341 and len(frames) == 86
    with pytest.raises(UserError, match="--first-frame 343"):
        select_clip_frames(343, 120.0, step=4, fps=30.0, frames=None, first=343)


def test_the_default_subject_is_not_the_trackers_start(body_bvh, tmp_path):
    """mocap synth's default body is mpfb with `SUBJECT_SHAPE` in `SUBJECT_CLOTHES_CM` of
    clothes (the tracker starts at MakeHuman's average, unclothed); --shape and --clothes
    change it, and are refused for another body."""
    path, _ = body_bvh
    common = ("--bvh", path, "--cameras", "2", "--size", "320x240", "--frames", "2", "--clean")
    assert run_cli("synth", tmp_path / "default", *common).returncode == 0
    _, _, data = _gt(tmp_path / "default")
    assert data["body"]["options"] == [
        "gender=0.2", "weight=0.7", "height=0.4", "age_years=40", "clothes_cm=2"]
    # The subject as a pose file describes it: mocap track --init-pose gt/pose.json reads it.
    subject = MpfbModel.from_record(data["body"])
    assert (subject.macro.gender, subject.macro.weight, subject.clothes_cm) == (0.2, 0.7, 2.0)
    assert run_cli("synth", tmp_path / "bare", *common, "--shape",
                   "gender=0.2,weight=0.7,height=0.4,age_years=40", "--clothes", "0"
                   ).returncode == 0  # fmt: skip
    assert json.loads((tmp_path / "bare" / "gt" / "pose.json").read_text())["body"][
        "options"][-1] == "clothes_cm=0"
    # 2 cm of clothes on the trunk and legs: a larger silhouette in every view and frame.
    for camera in ("cam00", "cam01"):
        for frame in range(2):
            clothed = _mask(tmp_path / "default", camera, frame)
            bare = _mask(tmp_path / "bare", camera, frame)
            assert np.count_nonzero(clothed) > 1.03 * np.count_nonzero(bare)
    ws = tmp_path / "ws"
    _assert_one_line_error(run_cli("synth", ws, *common, "--body", "superquadric", "--clothes",
                                   "1"), "--shape and --clothes shape the mpfb body")
    _assert_one_line_error(run_cli("synth", ws, *common, "--shape", "gender"), "--shape")
    _assert_one_line_error(run_cli("synth", ws, *common, "--shape", "weight=3"), "weight")
    assert not ws.exists() or not any(ws.iterdir())
