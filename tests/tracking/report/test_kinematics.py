"""Tests of tracking.report.kinematics against motions with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from recon.errors import UserError
from tracking.body.model import N_POSE_PARAMS, PARAM_INDEX, BodyShape, Pose, forward_kinematics
from tracking.report.anthropometry import body_segments
from tracking.report.kinematics import (
    ANGLE_JOINTS,
    ANGLE_NAMES,
    MotionSequence,
    compute_kinematics,
    joint_angles,
    lowpass,
)

SHAPE = BodyShape.default(1.75)
SEGMENTS = body_segments(SHAPE, 70.0)
G = 9.80665


def params_over_time(n: int, **series: np.ndarray | float) -> np.ndarray:
    """(n, N_POSE_PARAMS) pose parameters: the named ones as given (arrays or constants), others 0,
    pelvis 1 m above the origin."""
    p = np.zeros((n, N_POSE_PARAMS))
    p[:, PARAM_INDEX["root_ty"]] = 1.0
    for name, value in series.items():
        p[:, PARAM_INDEX[name]] = value
    return p


def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rigidly_moved(world_from_node: np.ndarray, world_from_body: np.ndarray) -> np.ndarray:
    """(T, 16, 4, 4): a fixed body pose (16, 4, 4) carried by (T, 4, 4) rigid motions."""
    return world_from_body[:, None] @ world_from_node[None]


@pytest.mark.parametrize("cutoff_hz", [0.0, 6.0])
def test_hinge_at_constant_angular_velocity_is_exact(cutoff_hz: float) -> None:
    # Knee flexing at 1.5 rad/s while the body faces 30 degrees to the left (heading 0.5 rad).
    fs, n, omega, heading = 100.0, 150, 1.5, 0.5
    t = np.arange(n) / fs
    seq = MotionSequence.from_poses(
        params_over_time(n, l_knee_flex=0.1 + omega * t, root_ry=heading, l_hip_rx=-0.3),
        SHAPE, fs)  # fmt: skip
    kin = compute_kinematics(seq, SEGMENTS, cutoff_hz=cutoff_hz)
    knee = ANGLE_JOINTS.index("l_knee")
    # Exact up to float rounding, at every frame including the ends, filtered or not.
    np.testing.assert_allclose(kin.joint_angles[:, knee, 0], 0.1 + omega * t, atol=1e-9)
    np.testing.assert_allclose(kin.joint_angular_velocity[:, knee, 0], omega, atol=1e-8)
    shank = SEGMENTS.names.index("l_shank")
    # The knee axis is the thigh's +X; the thigh is flexed about X, which leaves X alone, and
    # the heading turns it about Y.
    axis = rot_y(heading) @ np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(kin.segment_angular_velocity[:, shank],
                               np.tile(omega * axis, (n, 1)), atol=1e-8)
    np.testing.assert_allclose(kin.segment_angular_acceleration[:, shank], 0.0, atol=1e-6)
    # Nothing else moves.
    hip = ANGLE_JOINTS.index("l_hip")
    np.testing.assert_allclose(kin.joint_angles[:, hip], [[0.3, 0.0, 0.0]] * n, atol=1e-9)
    thigh = SEGMENTS.names.index("l_thigh")
    np.testing.assert_allclose(kin.segment_angular_velocity[:, thigh], 0.0, atol=1e-9)


@pytest.mark.parametrize("cutoff_hz", [0.0, 6.0])
def test_free_falling_tumbling_body_has_com_acceleration_g(cutoff_hz: float) -> None:
    # A rigid body (fixed pose) thrown forward and up, tumbling at 2 rad/s about an axis
    # through its centre of mass.
    fs, n = 120.0, 120
    t = np.arange(n) / fs
    rest = forward_kinematics(Pose.from_dict({"root_ty": 1.0, "l_shoulder_rx": -0.8,
                                              "r_knee_flex": 0.6}), SHAPE)  # fmt: skip
    com0 = _com(rest)
    com = com0 + np.outer(t, [0.3, 2.0, 1.0]) + 0.5 * np.outer(t**2, [0.0, -G, 0.0])
    motion = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        r = rot_x(2.0 * t[k]) @ rot_y(0.4)
        motion[k, :3, :3] = r
        motion[k, :3, 3] = com[k] - r @ com0
    seq = MotionSequence(rigidly_moved(rest, motion), SHAPE, fs)
    kin = compute_kinematics(seq, SEGMENTS, cutoff_hz=cutoff_hz)
    np.testing.assert_allclose(kin.com, com, atol=1e-4)  # 0.1 mm
    # Unfiltered: exact; filtered: the tumbling pelvis is not a parabola, so the low-pass
    # touches it near the ends, still within 0.05 m/s^2 of g.
    tol = 1e-6 if cutoff_hz == 0 else 0.05
    np.testing.assert_allclose(kin.com_acceleration, [[0.0, -G, 0.0]] * n, atol=tol)


def _com(world_from_node: np.ndarray) -> np.ndarray:
    """Whole-body centre of mass of one frame (16, 4, 4), computed here from the table."""
    node = world_from_node[SEGMENTS.node]
    pos = np.einsum("sij,sj->si", node[:, :3, :3], SEGMENTS.com_in_node) + node[:, :3, 3]
    return SEGMENTS.mass_kg @ pos / SEGMENTS.total_mass_kg


def test_angle_signs_follow_the_clinical_conventions() -> None:
    deg = np.pi / 180
    pose = Pose.from_dict({
        "root_ty": 1.0, "spine_flex": 20 * deg, "neck_flex": -10 * deg,
        "l_hip_rx": -30 * deg,  # left hip flexion
        "r_hip_rz": -20 * deg,  # right hip abduction (mirror of the left's +Z)
        "l_shoulder_ry": -25 * deg,  # left shoulder internal rotation (+ry is external)
        "r_shoulder_rx": -40 * deg,  # right shoulder flexion
        "l_knee_flex": 45 * deg, "r_elbow_flex": 60 * deg,
    })  # fmt: skip
    angles = np.degrees(joint_angles(forward_kinematics(pose, SHAPE)[None])[0])
    got = {(j, a): angles[i, k] for i, j in enumerate(ANGLE_JOINTS)
           for k, a in enumerate(ANGLE_NAMES)}  # fmt: skip
    expected = {
        ("spine", "flexion"): 20, ("neck", "flexion"): -10, ("l_hip", "flexion"): 30,
        ("r_hip", "abduction"): 20, ("l_shoulder", "rotation"): 25,
        ("r_shoulder", "flexion"): 40, ("l_knee", "flexion"): 45, ("r_elbow", "flexion"): 60,
    }  # fmt: skip
    for key, value in got.items():
        assert value == pytest.approx(expected.get(key, 0.0), abs=1e-9), key


def test_pelvis_tilt_does_not_depend_on_the_walking_direction() -> None:
    rest = forward_kinematics(Pose.from_dict({"root_ty": 1.0}), SHAPE)
    motion = np.eye(4)[None].copy()
    # Facing +X (heading 90 degrees), tilted 10 degrees forward about its own medio-lateral axis.
    motion[0, :3, :3] = rot_y(np.pi / 2) @ rot_x(np.radians(10.0))
    angles = np.degrees(joint_angles(rigidly_moved(rest, motion))[0])
    pelvis = ANGLE_JOINTS.index("pelvis")
    np.testing.assert_allclose(angles[pelvis], [10.0, 0.0, 90.0], atol=1e-9)
    np.testing.assert_allclose(np.delete(angles, pelvis, axis=0), 0.0, atol=1e-9)


def test_lowpass_cutoff_is_the_minus_3_db_point_and_has_no_lag() -> None:
    fs, cutoff = 120.0, 6.0
    t = np.arange(1200) / fs
    interior = slice(240, -240)
    for freq, gain in ((1.0, 1.0), (cutoff, 1 / np.sqrt(2)), (30.0, 0.0)):
        x = np.sin(2 * np.pi * freq * t)
        y = lowpass(x, fs, cutoff, order=2)
        # Zero lag: the output is the input scaled, not shifted.
        np.testing.assert_allclose(y[interior], gain * x[interior], atol=0.01)


def test_short_gaps_are_interpolated_long_ones_left_and_both_reported() -> None:
    fs, n = 100.0, 200
    t = np.arange(n) / fs
    truth = params_over_time(n, l_knee_flex=0.8 + 0.5 * np.sin(2 * np.pi * t),
                             root_tz=1.2 * t)  # fmt: skip
    params = truth.copy()
    params[50:54] = np.nan  # 4 frames: interpolated
    params[120:160] = np.nan  # 40 frames: left as a gap
    params[70, 5] = np.inf  # one bad number loses the frame
    seq = MotionSequence.from_poses(params, SHAPE, fs, first_frame=1000)
    kin = compute_kinematics(seq, SEGMENTS, cutoff_hz=6.0, max_gap_frames=5)
    assert [(g.first_frame, g.last_frame, g.filled) for g in kin.gaps] == [
        (1050, 1053, True), (1070, 1070, True), (1120, 1159, False)]
    assert kin.valid[50:54].all() and not kin.valid[120:160].any()
    assert np.isnan(kin.com[120:160]).all() and np.isnan(kin.joint_angles[120:160]).all()
    assert np.isnan(kin.com_velocity[120:160]).all()
    knee = ANGLE_JOINTS.index("l_knee")
    filled = kin.joint_angles[50:54, knee, 0]
    assert np.abs(filled - truth[50:54, PARAM_INDEX["l_knee_flex"]]).max() < np.radians(1.0)
    # Either side of the long gap is analysed on its own.
    assert np.isfinite(kin.com_velocity[:120]).all() and np.isfinite(kin.com_velocity[160:]).all()


def test_too_short_to_filter_says_so() -> None:
    seq = MotionSequence.from_poses(params_over_time(5), SHAPE, 30.0, source="clip")
    with pytest.raises(UserError, match="clip is too short.*5 frame.*needs at least 10"):
        compute_kinematics(seq, SEGMENTS, cutoff_hz=6.0)
    # Unfiltered, 5 frames are enough to differentiate.
    assert np.isfinite(compute_kinematics(seq, SEGMENTS, cutoff_hz=0.0).com_velocity).all()


def test_runs_between_long_gaps_that_are_too_short_are_noted() -> None:
    params = params_over_time(60)
    params[20:40] = np.nan
    params[42:] = np.nan
    seq = MotionSequence.from_poses(params, SHAPE, 30.0)
    kin = compute_kinematics(seq, SEGMENTS, cutoff_hz=6.0, max_gap_frames=1)
    assert any("frames 40-41" in note and "too few" in note for note in kin.notes)
    assert np.isfinite(kin.com[40:42]).all() and np.isnan(kin.com_velocity[40:42]).all()


def test_all_nan_sequence_says_so() -> None:
    seq = MotionSequence.from_poses(np.full((30, N_POSE_PARAMS), np.nan), SHAPE, 30.0,
                                    source="lost.json")  # fmt: skip
    with pytest.raises(UserError, match="lost.json has no frame with data"):
        compute_kinematics(seq, SEGMENTS)


def test_constant_sequence_has_zero_derivatives_and_a_note() -> None:
    seq = MotionSequence.from_poses(params_over_time(40, l_knee_flex=0.5), SHAPE, 30.0)
    kin = compute_kinematics(seq, SEGMENTS)
    assert any("constant" in note for note in kin.notes)
    for values in (kin.com_velocity, kin.segment_acceleration, kin.segment_angular_velocity,
                   kin.joint_angular_velocity):
        np.testing.assert_allclose(values, 0.0, atol=1e-9)


def test_cutoff_above_nyquist_says_so() -> None:
    seq = MotionSequence.from_poses(params_over_time(40), SHAPE, 10.0)
    with pytest.raises(UserError, match="too high for 10 frames/s"):
        compute_kinematics(seq, SEGMENTS, cutoff_hz=6.0)


def test_model_angles_are_the_angles_the_pose_parameters_move() -> None:
    """`MODEL_ANGLES`, read from the layout, against poses: random poses within the joint
    limits move every listed angle by degrees and leave the others at 0 (hinges)."""
    from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS
    from tracking.report.kinematics import ANGLE_JOINTS, ANGLE_NAMES, MODEL_ANGLES, joint_angles

    rng = np.random.default_rng(0)
    lower = np.where(np.isfinite(LOWER_LIMITS), LOWER_LIMITS, -1.0)
    upper = np.where(np.isfinite(UPPER_LIMITS), UPPER_LIMITS, 1.0)
    params = rng.uniform(lower, upper, size=(40, N_POSE_PARAMS))
    world = np.stack([forward_kinematics(Pose(p), SHAPE) for p in params])
    moved_deg = np.abs(np.degrees(joint_angles(world))).max(axis=0)  # (J, 3)
    for j, joint in enumerate(ANGLE_JOINTS):
        for k, name in enumerate(ANGLE_NAMES):
            if name in MODEL_ANGLES[joint]:
                assert moved_deg[j, k] > 5.0, (joint, name)
            else:
                assert moved_deg[j, k] < 1e-6, (joint, name)
    assert {j for j, a in MODEL_ANGLES.items() if a == ("flexion",)} == {
        "neck", "l_elbow", "r_elbow", "l_knee", "r_knee"}
