"""Pose sequences of our body model as BVH, and back: BVH → model → BVH → model."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from recon.errors import UserError
from tests.helpers import shared_dataset
from tracking.body.bvh import CMU_METRES_PER_UNIT, format_bvh, parse_bvh, read_bvh
from tracking.body.model import NODE_NAMES, BodyShape, Pose, node_positions_in_world
from tracking.body.motion import (
    is_body_skeleton,
    motion_from_poses,
    poses_from_motion,
    read_pose_file,
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
    poses = [Pose(np.concatenate([rng.uniform(-1, 1, 3), rng.uniform(-0.6, 0.6, 21)]))
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
