"""BVH reader/writer, forward kinematics and Euler conversion, against hand-computed poses and
the real CMU clips in ../shared/data/mocap_bvh."""

from __future__ import annotations

import dataclasses
import os
import re
import stat
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import shared_dataset
from tracking.body.bvh import (
    CMU_METRES_PER_UNIT,
    ROTATION_CHANNELS,
    Joint,
    Motion,
    blend_frames,
    euler_to_rotations,
    forward_kinematics,
    leading_reference_frames,
    local_rotations,
    motion_from_rotations,
    parse_bvh,
    read_bvh,
    rotations_to_channels,
    write_bvh,
)
from tracking.body.retarget import bvh_metres_per_unit

WALK = "cmu_02_01_walk.bvh"
START_WALK_STOP = "cmu_131_01_start_walk_stop.bvh"
ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


def cmu(name: str) -> Path:
    return shared_dataset("mocap_bvh") / name


def two_joint_bvh(root_channels: str, root_values: str) -> str:
    """Root at the origin with 6 channels, a child 10 units up, its end site 5 units along z."""
    return f"""HIERARCHY
ROOT Root
{{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition {root_channels}
\tJOINT Child
\t{{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{{
\t\t\tOFFSET 0 0 5
\t\t}}
\t}}
}}
MOTION
Frames: 1
Frame Time: 0.04
{root_values}
"""


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) rotations from QR of Gaussian matrices, reflections removed."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0] *= -1.0
    return q


# ----------------------------------------------------------------------------- real clips


@pytest.mark.shared_data
@pytest.mark.parametrize(("name", "reference"), [
    (WALK, 0), (START_WALK_STOP, 0), ("cmu_wave.bvh", 0),  # moving from frame 0
    ("cmu_run.bvh", 1), ("cmu_squat.bvh", 1), ("cmu_boxing.bvh", 1),  # a T-pose in frame 0
    # Daz's rest pose, then 4 frames (3 for the kick) that ease the arms down into the capture
    ("cmu_kick.bvh", 4), ("cmu_sit_stand.bvh", 5), ("cmu_climb_steps.bvh", 5),
])  # fmt: skip
def test_a_leading_t_pose_is_a_reference_frame(name: str, reference: int) -> None:
    motion = read_bvh(cmu(name))
    assert leading_reference_frames(motion) == reference
    # Without its leading frames no clip starts with a reference pose.
    rest = dataclasses.replace(motion, channels=motion.channels[reference:])
    assert leading_reference_frames(rest) == 0
    # What is skipped is no capture: after it no joint moves 20 cm about the root between a
    # 30 fps sequence's first two frames (at most 7.6 cm, wave; from frame 1 the Daz clips'
    # hands moved 65 cm).
    first_two = forward_kinematics(motion, bvh_metres_per_unit(motion))[reference:reference + 5:4]
    about_root = first_two - first_two[:, :1]
    assert np.linalg.norm(about_root[1] - about_root[0], axis=1).max() < 0.2


def test_a_blend_is_the_leading_steps_faster_than_any_later_one():
    """`blend_frames` counts the leading steps faster than every later one, up to its bound; a
    clip that moves faster later has none."""
    assert blend_frames(np.array([24.0, 21.0, 15.0, 6.0, 0.6, 3.2, 1.9]), 12) == 4
    assert blend_frames(np.array([24.0, 21.0, 15.0, 6.0, 0.6, 10.0]), 12) == 3
    assert blend_frames(np.array([18.3, 1.5, 1.1, 38.6]), 12) == 0
    assert blend_frames(np.array([9.0, 8.0, 7.0, 6.0, 5.0, 4.0]), 2) == 2  # the bound


@pytest.mark.shared_data
@pytest.mark.parametrize(("name", "frames"), [(WALK, 343), (START_WALK_STOP, 994)])
def test_parses_cmu_clips(name: str, frames: int) -> None:
    motion = read_bvh(cmu(name))
    end_sites = [j for j in motion.joints if not j.channels]
    assert len(motion.joints) - len(end_sites) == 31
    assert len(end_sites) == 7
    assert all(j.name.endswith("_end") for j in end_sites)
    assert motion.num_frames == frames
    assert motion.channels.shape == (frames, 6 + 30 * 3)
    assert motion.frame_time_s == pytest.approx(1 / 120, abs=1e-5)
    assert motion.fps == pytest.approx(120, abs=0.1)
    root = motion.joints[0]
    assert root.parent == -1 and root.name == "Hips"
    assert root.channels == (
        "Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation",
    )  # fmt: skip
    assert motion.channel_slice("Hips") == slice(0, 6)
    assert motion.channel_slice(1) == slice(6, 9)


@pytest.mark.shared_data
def test_walk_first_values_match_the_file() -> None:
    motion = read_bvh(cmu(WALK))
    np.testing.assert_array_equal(
        motion.channels[0, :6], [11.077051, 17.759173, -32.000170, -3.144128, -13.081670, 1.872652]
    )
    np.testing.assert_array_equal(
        motion.joints[motion.joint_index("LeftUpLeg")].offset, [1.363060, -1.794630, 0.839290]
    )


@pytest.mark.shared_data
@pytest.mark.parametrize("name", [WALK, START_WALK_STOP])
def test_read_write_read_round_trip(name: str, tmp_path: Path) -> None:
    motion = read_bvh(cmu(name))
    out = tmp_path / "copy.bvh"
    write_bvh(motion, out)
    again = read_bvh(out)
    assert [j.name for j in again.joints] == [j.name for j in motion.joints]
    assert [j.parent for j in again.joints] == [j.parent for j in motion.joints]
    assert [j.channels for j in again.joints] == [j.channels for j in motion.joints]
    np.testing.assert_allclose(again.offsets, motion.offsets, atol=1e-6, rtol=0)
    np.testing.assert_allclose(again.channels, motion.channels, atol=1e-6, rtol=0)
    assert again.frame_time_s == motion.frame_time_s
    assert list(tmp_path.iterdir()) == [out]  # the temporary file was renamed, not left behind
    # The layout Blender's importer expects.
    text = out.read_text()
    lines = text.splitlines()
    assert lines[:3] == ["HIERARCHY", "ROOT Hips", "{"]
    assert "\tEnd Site" in text and "MOTION\nFrames: " in text and "\nFrame Time: " in text
    assert not re.search(r"\de[-+]?\d", text)  # no exponent notation


@pytest.mark.shared_data
@pytest.mark.parametrize("name", [WALK, START_WALK_STOP])
def test_cmu_first_frame_is_a_plausible_human(name: str) -> None:
    motion = read_bvh(cmu(name))
    joint_in_world = forward_kinematics(motion, scale=CMU_METRES_PER_UNIT)
    assert joint_in_world.shape == (motion.num_frames, len(motion.joints), 3)
    height = joint_in_world[0, :, 1]
    # Toe to head joint: the top of the skull and the sole are not joints, so this is a bit
    # under the subject's stature.
    assert 1.4 < np.ptp(height) < 2.0
    names = motion.joint_names
    assert "Head" in names[int(np.argmax(height))]
    lowest = names[int(np.argmin(height))]
    assert "Toe" in lowest or "Foot" in lowest
    foot_like = [i for i, n in enumerate(names) if "Toe" in n or "Foot" in n or "Ankle" in n]
    assert height[foot_like].max() - height.min() < 0.15
    # The hip joint sits at about two thirds of the toe-to-head span.
    hips_fraction = (height[motion.joint_index("Hips")] - height.min()) / np.ptp(height)
    assert 0.55 < hips_fraction < 0.8


@pytest.mark.shared_data
def test_file_channel_order_keeps_stance_foot_still() -> None:
    """Truth from the clip itself: a walking stance foot barely moves. Reading the rotation
    channels in the reverse (wrong) order makes the feet skate."""
    motion = read_bvh(cmu(WALK))

    def stance_speed(m: Motion) -> float:
        joint_in_world = forward_kinematics(m, scale=CMU_METRES_PER_UNIT)
        toes = [m.joint_index("LeftToeBase"), m.joint_index("RightToeBase")]
        speed = np.linalg.norm(np.diff(joint_in_world[:, toes], axis=0), axis=-1) * m.fps
        return float(np.median(speed.min(axis=1)))

    joints, channels = [], motion.channels.copy()
    for index, joint in enumerate(motion.joints):
        rot = [k for k, c in enumerate(joint.channels) if c in ROTATION_CHANNELS]
        start = motion.channel_slice(index).start
        channels[:, [start + k for k in rot]] = motion.channels[:, [start + k for k in rot[::-1]]]
        reordered = list(joint.channels)
        for k, k_rev in zip(rot, rot[::-1], strict=True):
            reordered[k] = joint.channels[k_rev]
        joints.append(dataclasses.replace(joint, channels=tuple(reordered)))
    reversed_order = Motion(tuple(joints), motion.frame_time_s, channels)
    assert stance_speed(motion) < 0.2  # m/s
    assert stance_speed(reversed_order) > 1.5 * stance_speed(motion)


@pytest.mark.shared_data
def test_rotations_written_in_another_order_give_the_same_pose(tmp_path: Path) -> None:
    """A pose sequence (here the CMU one) written as BVH in XYZ order reads back the same."""
    motion = read_bvh(cmu(WALK))
    parent_from_joint = local_rotations(motion)
    joint_in_world = forward_kinematics(motion)
    joints = tuple(
        dataclasses.replace(
            j,
            channels=tuple(c for c in j.channels if "position" in c)
            + ("Xrotation", "Yrotation", "Zrotation"),
        )
        if j.channels
        else j
        for j in motion.joints
    )
    rebuilt = motion_from_rotations(
        joints, parent_from_joint, joint_in_world[:, 0], motion.frame_time_s
    )
    write_bvh(rebuilt, tmp_path / "xyz.bvh")
    again = read_bvh(tmp_path / "xyz.bvh")
    np.testing.assert_allclose(forward_kinematics(again), joint_in_world, atol=1e-4, rtol=0)


# ----------------------------------------------------------------------------- hand-made poses


def test_forward_kinematics_hand_computed() -> None:
    # Root at (1, 2, 3) turned 90 deg about Z; child turned 90 deg about X.
    # Child = root + Rz90 (0, 10, 0) = (1 - 10, 2, 3).
    # End = child + Rz90 Rx90 (0, 0, 5) = child + Rz90 (0, -5, 0) = child + (5, 0, 0).
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "1 2 3 90 0 0 0 90 0")
    motion = parse_bvh(text)
    assert motion.joint_names == ("Root", "Child", "Child_end")
    joint_in_world = forward_kinematics(motion)
    np.testing.assert_allclose(joint_in_world[0], [[1, 2, 3], [-9, 2, 3], [-4, 2, 3]], atol=1e-12)
    np.testing.assert_allclose(forward_kinematics(motion, scale=2.0), 2 * joint_in_world)


def test_channel_order_matters_hand_computed() -> None:
    # ZXY with Z=90, X=90: R = Rz90 Rx90; Rx90 (0,10,0) = (0,0,10); Rz90 (0,0,10) = (0,0,10).
    zxy = parse_bvh(two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 90 90 0 0 0 0"))
    # XYZ with X=90, Z=90: R = Rx90 Rz90; Rz90 (0,10,0) = (-10,0,0); Rx90 keeps it.
    xyz = parse_bvh(two_joint_bvh("Xrotation Yrotation Zrotation", "0 0 0 90 0 90 0 0 0"))
    np.testing.assert_allclose(forward_kinematics(zxy)[0, 1], [0, 0, 10], atol=1e-12)
    np.testing.assert_allclose(forward_kinematics(xyz)[0, 1], [-10, 0, 0], atol=1e-12)
    # A non-right angle fixes the sense of rotation: Rx(30) (0,10,0) = (0, 10 cos30, 10 sin30).
    tilt = parse_bvh(two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 30 0 0 0 0"))
    np.testing.assert_allclose(
        forward_kinematics(tilt)[0, 1], [0, 10 * np.cos(np.pi / 6), 5], atol=1e-12
    )
    rot = local_rotations(zxy)
    assert rot.shape == (1, 3, 3, 3)
    np.testing.assert_allclose(rot[0, 2], np.eye(3))  # End Site: no channels


# ----------------------------------------------------------------------------- Euler angles


@pytest.mark.parametrize("order", ORDERS)
def test_euler_round_trip_random_rotations(order: str) -> None:
    rng = np.random.default_rng(7)
    rotations = random_rotations(rng, 500)
    angles = rotations_to_channels(rotations, order)
    assert angles.shape == (500, 3)
    assert np.all(np.abs(angles[:, 1]) <= 90 + 1e-9)
    np.testing.assert_allclose(euler_to_rotations(angles, order), rotations, atol=1e-9)
    # Angles with the middle one inside (-90, 90) come back unchanged.
    angles = rng.uniform([-180, -89, -180], [180, 89, 180], size=(500, 3))
    channel_names = tuple(f"{axis}rotation" for axis in order)
    np.testing.assert_allclose(
        rotations_to_channels(euler_to_rotations(angles, channel_names), channel_names),
        angles,
        atol=1e-8,
    )


@pytest.mark.parametrize("order", ORDERS)
def test_euler_gimbal_lock(order: str) -> None:
    rotations = euler_to_rotations(np.array([[30.0, 90.0, 20.0], [-40.0, -90.0, 10.0]]), order)
    angles = rotations_to_channels(rotations, order)
    np.testing.assert_allclose(euler_to_rotations(angles, order), rotations, atol=1e-9)


def test_orders_differ() -> None:
    angles = np.array([20.0, 30.0, 40.0])
    assert not np.allclose(euler_to_rotations(angles, "XYZ"), euler_to_rotations(angles, "ZYX"))


# ----------------------------------------------------------------------------- malformed input


def test_truncated_motion_names_file_and_line() -> None:
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 0 0").replace(
        "Frames: 1", "Frames: 3"
    )
    with pytest.raises(ValueError, match=r"^clip\.bvh:19: truncated MOTION, 1 of 3 frames"):
        parse_bvh(text, source="clip.bvh")


def test_wrong_value_count_names_the_frame_line() -> None:
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 0")
    with pytest.raises(ValueError, match=r"^clip\.bvh:19: frame has 8 values, skeleton has 9"):
        parse_bvh(text, source="clip.bvh")


def test_bad_number_names_the_line() -> None:
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 1.2.3 0")
    with pytest.raises(ValueError, match=r"^clip\.bvh:19: bad number '1\.2\.3'"):
        parse_bvh(text, source="clip.bvh")
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 0 0").replace(
        "OFFSET 0 10 0", "OFFSET 0 ten 0"
    )
    with pytest.raises(ValueError, match=r"^clip\.bvh:8: bad number 'ten'"):
        parse_bvh(text, source="clip.bvh")


def test_a_rotation_beyond_any_joint_angle_is_refused() -> None:
    # 1e300 degrees parses as a float, but its rotation (the remainder modulo 360) is noise.
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 1e300 0")
    with pytest.raises(ValueError, match=r"^clip\.bvh: frame 0: Xrotation of .* is 1e\+300 "
                       r"degrees, beyond the \+-1e\+06"):
        parse_bvh(text, source="clip.bvh")
    # Unwrapped angles of a spinning subject (here 20 turns) are rotations like any other.
    parse_bvh(two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 7200 0 0 0 -7200 0"))


def test_wrong_channel_count_in_hierarchy_names_the_line() -> None:
    text = two_joint_bvh("Zrotation Xrotation Yrotation", "0 0 0 0 0 0 0 0 0").replace(
        "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Zrotation Xrotation Yrotation"
    )
    with pytest.raises(ValueError, match=r"^clip\.bvh:10: unknown channel 'End'"):
        parse_bvh(text, source="clip.bvh")


def test_read_bvh_error_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "broken.bvh"
    path.write_text("HIERARCHY\nROOT Hips\n{\n")
    with pytest.raises(ValueError, match=re.escape(str(path))):
        read_bvh(path)


def test_motion_validates_channel_count() -> None:
    joints = (Joint("Root", -1, np.zeros(3), ("Xrotation", "Yrotation", "Zrotation")),)
    with pytest.raises(ValueError, match=r"\(F, 3\)"):
        Motion(joints, 0.01, np.zeros((2, 4)))


def test_written_bvh_has_the_mode_of_any_new_file(tmp_path: Path) -> None:
    """Issue 21: tracks/motion.bvh came out 0600 (tempfile's mode) beside 0644 outputs."""
    from tracking.body.model import BodyShape
    from tracking.body.motion import motion_from_poses
    from tracking.body.synthetic import walking_poses

    shape = BodyShape.default(1.70)
    motion = motion_from_poses(walking_poses(5, 30.0, shape), shape, 1.0 / 30.0)
    out = tmp_path / "motion.bvh"
    old = os.umask(0o022)
    try:
        write_bvh(motion, out)
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert list(tmp_path.iterdir()) == [out] and read_bvh(out).num_frames == 5
