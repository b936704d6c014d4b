"""Tests of tracking.report.dynamics (Newton-Euler) against hand calculations and analytic
motions."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.body.model import N_POSE_PARAMS, PARAM_INDEX, BodyShape
from tracking.report.anthropometry import DE_LEVA_1996, Sex, body_segments, default_body_mass
from tracking.report.dynamics import STANDARD_GRAVITY, inverse_dynamics
from tracking.report.kinematics import MotionSequence, compute_kinematics

SHAPE = BodyShape.default(1.75)
MASS = 70.0
G = STANDARD_GRAVITY


def still(**values: float) -> MotionSequence:
    """30 frames at 60 Hz of one pose (pelvis 1 m up), given as named parameters."""
    p = np.zeros((30, N_POSE_PARAMS))
    p[:, PARAM_INDEX["root_ty"]] = 1.0
    for name, value in values.items():
        p[:, PARAM_INDEX[name]] = value
    return MotionSequence.from_poses(p, SHAPE, 60.0)


def loads_of(seq: MotionSequence, gravity: np.ndarray | None = None):
    segments = body_segments(SHAPE, MASS)
    kin = compute_kinematics(seq, segments, cutoff_hz=6.0)
    if gravity is None:
        return kin, inverse_dynamics(kin)
    return kin, inverse_dynamics(kin, gravity)


def test_table_masses_add_up_to_the_body_mass() -> None:
    for sex in Sex:
        table = DE_LEVA_1996[sex]
        total = sum(r.mass for k, r in table.items() if k not in ("hand", "upper_arm",
                    "forearm", "thigh", "shank", "foot")) + 2 * sum(
            table[k].mass for k in ("hand", "upper_arm", "forearm", "thigh", "shank", "foot"))
        assert total == pytest.approx(1.0, abs=2e-4), sex
        assert body_segments(SHAPE, MASS, sex).total_mass_kg == pytest.approx(MASS, rel=2e-4)
    # The default mass keeps de Leva's male sample's body-mass index (73 kg at 1.741 m).
    assert default_body_mass(1.741) == pytest.approx(73.0)


def test_static_horizontal_arm_matches_a_hand_calculation() -> None:
    # Left arm held straight forward (shoulder flexed 90 degrees), elbow straight, standing still.
    _, loads = loads_of(still(l_shoulder_rx=-np.pi / 2))
    ua, fa, hand = SHAPE.upper_arm, SHAPE.forearm, SHAPE.hand
    # de Leva (1996) male: mass fraction and centre of mass from the proximal joint.
    m_ua, m_fa, m_h = 0.0271 * MASS, 0.0162 * MASS, 0.0061 * MASS
    lever_ua, lever_fa, lever_h = 0.5772 * ua, ua + 0.4574 * fa, ua + fa + 0.3624 * hand
    weight = (m_ua + m_fa + m_h) * G  # 33.9 N for 70 kg
    moment = (m_ua * lever_ua + m_fa * lever_fa + m_h * lever_h) * G  # 11.1 N m for 1.75 m
    j = loads.joints.index("l_shoulder")
    # The trunk holds the arm up (+Y) ...
    np.testing.assert_allclose(loads.force_in_world[:, j], [[0.0, weight, 0.0]] * 30, atol=1e-6)
    # ... and against gravity's moment, which would extend it: a flexion moment about -X.
    np.testing.assert_allclose(loads.moment_in_world[:, j], [[-moment, 0.0, 0.0]] * 30,
                               atol=1e-6)  # fmt: skip
    np.testing.assert_allclose(loads.moment_anatomical[:, j], [[moment, 0.0, 0.0]] * 30,
                               atol=1e-6)  # fmt: skip
    # Elbow: forearm and hand only, levers from the elbow.
    e = loads.joints.index("l_elbow")
    elbow_moment = (m_fa * 0.4574 * fa + m_h * (fa + 0.3624 * hand)) * G
    assert loads.moment_anatomical[0, e, 0] == pytest.approx(elbow_moment, abs=1e-6)
    assert loads.force_in_world[0, e, 1] == pytest.approx((m_fa + m_h) * G, abs=1e-6)


def test_standing_still_the_ground_carries_the_body_weight() -> None:
    kin, loads = loads_of(still())
    # The external load left at the pelvis is the body weight, straight up.
    np.testing.assert_allclose(loads.force_in_world[:, 0], [[0.0, MASS * G, 0.0]] * 30,
                               atol=1e-6)  # fmt: skip
    # The spine carries the thorax, head and arms; in the symmetric rest pose without moment.
    seg = kin.segments
    above = [seg.names.index(n) for n in ("thorax", "head", "l_upper_arm", "l_forearm",
                                          "l_hand", "r_upper_arm", "r_forearm", "r_hand")]
    s = loads.joints.index("spine")
    assert loads.force_in_world[0, s, 1] == pytest.approx(seg.mass_kg[above].sum() * G)
    np.testing.assert_allclose(loads.moment_in_world[:, s], 0.0, atol=1e-9)


def test_free_fall_needs_no_joint_loads() -> None:
    n, fs = 60, 60.0
    t = np.arange(n) / fs
    p = np.zeros((n, N_POSE_PARAMS))
    p[:, PARAM_INDEX["root_ty"]] = 3.0 + 1.5 * t - 0.5 * G * t**2
    p[:, PARAM_INDEX["l_elbow_flex"]] = 1.0
    p[:, PARAM_INDEX["r_hip_rx"]] = -0.5
    _, loads = loads_of(MotionSequence.from_poses(p, SHAPE, fs))
    np.testing.assert_allclose(loads.force_in_world, 0.0, atol=1e-6)
    np.testing.assert_allclose(loads.moment_in_world, 0.0, atol=1e-6)


def test_shank_spinning_about_the_knee_needs_only_a_centripetal_force() -> None:
    # Without gravity, a shank (and rigid foot) turning at constant speed about the knee axis,
    # a principal axis at the knee, needs no moment and a force m w^2 r towards the knee.
    n, fs, omega = 90, 120.0, 3.0
    t = np.arange(n) / fs
    p = np.zeros((n, N_POSE_PARAMS))
    p[:, PARAM_INDEX["l_knee_flex"]] = 0.2 + omega * t
    kin, loads = loads_of(MotionSequence.from_poses(p, SHAPE, fs), gravity=np.zeros(3))
    seg = kin.segments
    parts = [seg.names.index("l_shank"), seg.names.index("l_foot")]
    knee = kin.world_from_node[:, seg.node[parts[0]], :3, 3]
    centripetal = -omega**2 * sum(
        seg.mass_kg[i] * (kin.segment_com[:, i] - knee) * [0.0, 1.0, 1.0] for i in parts)
    k = loads.joints.index("l_knee")
    # Finite differences of a circular path are not exact: 5 mN on a 9 N force at the ends.
    np.testing.assert_allclose(loads.force_in_world[:, k], centripetal, atol=0.01)
    np.testing.assert_allclose(loads.moment_in_world[:, k], 0.0, atol=1e-3)
