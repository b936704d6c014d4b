"""Pose sequences of our body model as BVH, and back: BVH → model → BVH → model."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from recon.errors import UserError
from tests.helpers import shared_dataset
from tracking.body.bvh import (
    CMU_METRES_PER_UNIT,
    euler_to_rotations,
    format_bvh,
    parse_bvh,
    read_bvh,
)
from tracking.body.model import (
    LEGACY_POSE_PARAMS,
    LIMIT_TOLERANCE_RAD,
    N_POSE_PARAMS,
    NODE_NAMES,
    PARAM_INDEX,
    BodyShape,
    Pose,
    node_positions_in_world,
    pose_params_problem,
)
from tracking.body.motion import (
    is_body_skeleton,
    motion_from_poses,
    poses_from_motion,
    read_pose_file,
    zxy_twin,
)
from tracking.body.retarget import retarget


def _round_trip(poses, shape, frame_time_s=1 / 30):
    text = format_bvh(motion_from_poses(poses, shape, frame_time_s))
    motion = parse_bvh(text)
    assert motion.num_frames == len(poses) and motion.frame_time_s == pytest.approx(frame_time_s)
    back, back_shape = poses_from_motion(motion)
    return text, back, back_shape


def test_hand_made_pose_writes_the_expected_channels():
    shape = BodyShape.default(1.8)
    pose = Pose.from_dict({"root_tx": 0.5, "root_ty": 0.9, "l_elbow_flex": np.pi / 2,
                           "r_knee_flex": np.pi / 3, "l_shoulder_rz": np.pi / 4})  # fmt: skip
    motion = motion_from_poses([pose], shape, 0.01)
    assert motion.joints[0].name == "pelvis" and motion.joints[0].channels[:3] == (
        "Xposition", "Yposition", "Zposition")  # fmt: skip
    row = motion.channels[0]
    np.testing.assert_allclose(row[:3], [0.5, 0.9, 0.0], atol=1e-12)
    # Channels are ZXY per joint; the elbow hinges about -X, so flexion is a negative X angle.
    np.testing.assert_allclose(row[motion.channel_slice("l_elbow")], [0, -90, 0], atol=1e-9)
    np.testing.assert_allclose(row[motion.channel_slice("r_knee")], [0, 60, 0], atol=1e-9)
    np.testing.assert_allclose(row[motion.channel_slice("l_shoulder")], [45, 0, 0], atol=1e-9)
    # End Sites carry the bone lengths: the forearm below the elbow.
    names = [j.name for j in motion.joints]
    wrist = motion.joints[names.index("l_wrist")]
    np.testing.assert_allclose(wrist.offset, [0, -shape.forearm, 0])


def test_random_poses_round_trip_exactly():
    rng = np.random.default_rng(0)
    shape = BodyShape.default(1.7)
    poses = [Pose(np.concatenate([rng.uniform(-1, 1, 3),
                                  rng.uniform(-0.6, 0.6, N_POSE_PARAMS - 3)]))
             for _ in range(20)]  # fmt: skip
    poses = [p.clamped() for p in poses]
    _, back, back_shape = _round_trip(poses, shape)
    for a, b in zip(poses, back, strict=True):
        np.testing.assert_allclose(b.params, a.params, atol=1e-7)
        ja, jb = node_positions_in_world(a, shape), node_positions_in_world(b, back_shape)
        for name in NODE_NAMES:
            np.testing.assert_allclose(jb[name], ja[name], atol=1e-6)


@pytest.mark.shared_data
def test_cmu_clip_bvh_to_model_to_bvh_to_model():
    clip = read_bvh(shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh")
    result = retarget(clip, CMU_METRES_PER_UNIT, frames=range(0, clip.num_frames, 20))
    assert not is_body_skeleton(clip)
    text, back, back_shape = _round_trip(result.poses, result.shape, clip.frame_time_s * 20)
    for a, b in zip(result.poses, back, strict=True):
        ja, jb = node_positions_in_world(a, result.shape), node_positions_in_world(b, back_shape)
        for name in NODE_NAMES:  # joint positions survive to 1 micrometre
            assert np.linalg.norm(jb[name] - ja[name]) < 1e-6
    # Second trip: the text is identical (a fixed point), so nothing drifts.
    text2, _, _ = _round_trip(back, back_shape, clip.frame_time_s * 20)
    assert text2 == text


@pytest.mark.shared_data
def test_other_skeletons_are_refused():
    clip = read_bvh(shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh")
    with pytest.raises(ValueError, match="not a body-model skeleton"):
        poses_from_motion(clip)


def _pose_file(tmp_path, **changes):
    data = {"frame_rate": 30.0, "shape": dataclasses.asdict(BodyShape.default(1.7)),
            "frames": [{"frame": 1, "params": None},
                       {"frame": 0, "params": [0.0] * 24}], **changes}  # fmt: skip
    path = tmp_path / "pose.json"
    path.write_text(json.dumps(data))
    return path


def test_pose_file_frames_sorted_and_its_frame_rotation(tmp_path):
    read = read_pose_file(_pose_file(tmp_path))
    assert read.frame_rate == 30.0 and [f for f, _ in read.frames] == [0, 1]
    assert read.frames[1][1] is None and np.array_equal(read.world_from_upright, np.eye(3))
    z_up = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    assert np.array_equal(read_pose_file(_pose_file(tmp_path, world_from_upright=z_up))
                          .world_from_upright, z_up)


@pytest.mark.parametrize(("changes", "says"), [
    ({"world_from_upright": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}, "not a 3x3 rotation"),
    ({"world_from_upright": [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]}, "not a 3x3 rotation"),
    ({"world_from_upright": [1, 2]}, "not a 3x3 rotation"),
    ({"frames": []}, "holds no frames"),
    ({"frames": [{"frame": 0, "params": [0.0] * 23}]}, "23 pose parameters"),
    ({"shape": {"height": 1.7}}, "not a pose track"),
])  # fmt: skip
def test_bad_pose_files_are_one_line_user_errors(tmp_path, changes, says):
    with pytest.raises(UserError, match=says) as error:
        read_pose_file(_pose_file(tmp_path, **changes))
    assert "\n" not in str(error.value)


def test_large_flexions_come_back_from_a_bvh():
    """A hinge past 90 degrees and a limb lifted past the horizontal: the BVH's rotations are
    read back as the model's own parameters (the ZXY decomposition alone turns a 150 degree
    knee into 30 degrees with Z and Y at 180), inside the joint limits."""
    shape = BodyShape.default(1.75)
    pose = Pose.from_dict({"root_ty": 0.9, "root_ry": 3.0, "l_knee_flex": np.deg2rad(150),
                           "r_elbow_flex": np.deg2rad(120), "l_shoulder_rx": np.deg2rad(-150),
                           "r_shoulder_rx": np.deg2rad(-120), "r_shoulder_ry": 0.3,
                           "l_hip_rx": np.deg2rad(-120), "l_hip_rz": np.deg2rad(20)})  # fmt: skip
    _, back, _ = _round_trip([pose], shape)
    np.testing.assert_allclose(back[0].params, pose.params, atol=1e-7)
    assert back[0].violations() == ()


# Issue 23: a pose file that no writer produces is refused, naming the file, frame and parameter.
def _frames(**rows):
    """Frames 0-4 of in-limits poses; `rows` replace entries by index (f3={...})."""
    frames = [{"frame": k, "params": [0.0, 0.9, 0.1 * k] + [0.0] * 21} for k in range(5)]
    for key, value in rows.items():
        frames[int(key[1:])] = value
    return frames


def _params(**named):
    params = [0.0, 0.9, 0.0] + [0.0] * (N_POSE_PARAMS - 3)
    for name, value in named.items():
        params[PARAM_INDEX[name]] = value
    return params


_TOL = LIMIT_TOLERANCE_RAD


@pytest.mark.parametrize(("frames", "says"), [
    (_frames(f0={"frame": -3, "params": _params()}), r"frame -3 is not a frame number"),
    (_frames(f2={"frame": 1, "params": _params()}), r"frame 1 appears more than once"),
    (_frames(f2={"frame": 2.5, "params": _params()}), r"frame 2\.5 is not a frame number"),
    (_frames(f2={"frame": "2", "params": _params()}), r"frame '2' is not a frame number"),
    (_frames(f2={"frame": True, "params": _params()}), r"frame True is not a frame number"),
    (_frames(f2={"frame": 2**31, "params": _params()}), r"frame 2147483648 is not a frame"),
    (_frames(f2={"params": _params()}), r"not a pose track \('frame'\)"),
    (_frames(f2={"frame": 2, "params": _params(l_knee_flex=1e300)}),
     r"frame 2: l_knee_flex = 5\.72958e\+301 deg is outside its joint limits 0\.\.150 deg"),
    (_frames(f2={"frame": 2, "params": _params(root_tx=1e300)}),
     r"frame 2: root_tx = 1e\+300 m is beyond the \+-1000 m"),
    (_frames(f2={"frame": 2, "params": _params(root_tz=-1000.5)}),
     r"frame 2: root_tz = -1000\.5 m"),
    (_frames(f2={"frame": 2, "params": _params(neck_flex=float("nan"))}),
     r"frame 2: neck_flex is nan \(not a finite number\)"),
    (_frames(f2={"frame": 2, "params": _params(root_ty=float("inf"))}), r"frame 2: root_ty is inf"),
    (_frames(f2={"frame": 2, "params": _params(r_knee_flex=-3 * _TOL)}),
     r"frame 2: r_knee_flex = -0\.003 deg is outside .* \(tolerance 0\.001 deg\)"),
    (_frames(f2={"frame": 2, "params": _params(root_ry=np.pi + 3 * _TOL)}),
     r"frame 2: root_ry = 180\.003 deg is outside its joint limits -180\.\.180"),
    (_frames(f2={"frame": 2, "params": ["a"] * 24}), r"frame 2: params is not a list of numbers"),
])  # fmt: skip
def test_impossible_frames_and_poses_are_refused(tmp_path, frames, says):
    with pytest.raises(UserError, match=r"pose\.json: " + says) as error:
        read_pose_file(_pose_file(tmp_path, frames=frames))
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(("changes", "says"), [
    ({"frame_rate": 0}, r"frame_rate 0 is not a positive number"),
    ({"frame_rate": float("nan")}, r"frame_rate nan is not a positive number"),
    ({"shape": {**dataclasses.asdict(BodyShape.default(1.7)), "thigh_radius": 1e300}},
     r"shape thigh_radius = 1e\+300 m is beyond 10 m"),
])  # fmt: skip
def test_impossible_frame_rates_and_shapes_are_refused(tmp_path, changes, says):
    with pytest.raises(UserError, match=says):
        read_pose_file(_pose_file(tmp_path, frames=_frames(), **changes))


def test_what_writers_produce_is_read(tmp_path):
    """Limits reached exactly (the tracker clips to them) or within the tolerance (text), a
    lost frame as null or as NaN, entries in any order, integral floats as frame numbers."""
    frames = [
        {"frame": 3, "params": _params(l_knee_flex=0.0, r_knee_flex=np.deg2rad(150),
                                       l_hip_rx=np.deg2rad(-125), root_ry=-np.pi)},
        {"frame": 0, "params": _params(r_elbow_flex=-0.5 * _TOL, root_tx=-999.0)},
        {"frame": 1.0, "params": None},
        {"frame": 2, "params": [float("nan")] * 24},
    ]  # fmt: skip
    read = read_pose_file(_pose_file(tmp_path, frames=frames))
    assert [f for f, _ in read.frames] == [0, 1, 2, 3]
    assert read.frames[1][1] is None and read.frames[2][1] is None
    assert read.frames[3][1][PARAM_INDEX["r_knee_flex"]] == np.deg2rad(150)


def test_a_file_of_the_thesis_24_parameters_reads_with_the_spine_bend_and_twist_0(tmp_path):
    legacy = _params(spine_flex=0.3)[:LEGACY_POSE_PARAMS]
    frames = [{"frame": 0, "params": legacy}, {"frame": 1, "params": [float("nan")] * 24}]
    read = read_pose_file(_pose_file(tmp_path, frames=frames))
    np.testing.assert_array_equal(read.frames[0][1], legacy + [0.0, 0.0])
    assert read.frames[1][1] is None
    frames = [{"frame": 0, "params": legacy[:-1]}]
    with pytest.raises(UserError, match="has 23 pose parameters, not 26 \\(or the thesis' 24\\)"):
        read_pose_file(_pose_file(tmp_path, frames=frames))


def test_pose_params_problem_names_the_first_bad_parameter():
    ok = np.array(_params())
    assert pose_params_problem(ok) is None
    bad = ok.copy()
    bad[PARAM_INDEX["l_shoulder_ry"]] = np.deg2rad(100)
    assert pose_params_problem(bad) == ("l_shoulder_ry = 100 deg is outside its joint limits "
                                        "-90..90 deg (tolerance 0.001 deg)")
    # Without the joint limits (a BVH's rotations): only finiteness and the root's bound.
    assert pose_params_problem(bad, joint_limits=False) is None
    bad[PARAM_INDEX["root_tx"]] = 2000.0
    assert pose_params_problem(bad, joint_limits=False).startswith("root_tx = 2000 m")
    assert pose_params_problem(np.zeros(23)) == "23 pose parameters, not 26"


def test_zxy_twin_is_the_same_rotation() -> None:
    rng = np.random.default_rng(3)
    zxy = rng.uniform(-np.pi, np.pi, (50, 3))
    twin = zxy_twin(zxy)
    assert np.all(np.abs(twin) <= np.pi)
    assert not np.allclose(twin, zxy)
    np.testing.assert_allclose(euler_to_rotations(np.degrees(twin), "ZXY"),
                               euler_to_rotations(np.degrees(zxy), "ZXY"), atol=1e-12)
    # The run's tracked left shoulder (raised and flexed past 90 degrees) is a lowered arm.
    z, x, _ = zxy_twin(np.array([3.13, -2.53, 0.1]))
    assert abs(z) < 0.05 and -0.7 < x < -0.5
