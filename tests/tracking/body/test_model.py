"""Body model: pose layout, limits, forward kinematics against hand-computed poses, the mesh."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from tracking.body.bvh import rotations_to_channels
from tracking.body.model import (
    JOINT_NAMES,
    LEGACY_POSE_PARAMS,
    LOWER_LIMITS,
    N_POSE_PARAMS,
    NODE_INDEX,
    NODE_NAMES,
    NODE_PARENTS,
    PARAM_INDEX,
    PARAM_MOVES_NODE,
    POSE_LAYOUT,
    SEARCH_LOWER_LIMITS,
    SEARCH_UPPER_LIMITS,
    UPPER_LIMITS,
    WHOLE_TURN,
    BodyModel,
    BodyShape,
    Pose,
    forward_kinematics,
    in_limits,
    node_positions_in_world,
    pose_derivative_axes,
    pose_in_frame,
    rest_offsets,
    root_rotation,
    superquadric,
    turn_difference,
)

SHAPE = BodyShape.default(1.75)
MODEL = BodyModel(SHAPE)
HALF_PI = np.pi / 2


def _joints(**values: float) -> dict[str, np.ndarray]:
    return node_positions_in_world(Pose.from_dict(values), SHAPE)


# ------------------------------------------------------------------------- layout and limits


def test_layout_has_the_thesis_24_parameters_then_the_spine_bend_and_twist() -> None:
    assert len(POSE_LAYOUT) == 26
    assert len({p.name for p in POSE_LAYOUT}) == 26
    assert {p.joint for p in POSE_LAYOUT} == set(JOINT_NAMES)
    assert len(JOINT_NAMES) == 11
    thesis = POSE_LAYOUT[:LEGACY_POSE_PARAMS]
    dof = {j: sum(p.joint == j for p in thesis) for j in JOINT_NAMES}
    assert dof["pelvis"] == 6 and dof["spine"] == 1 and dof["neck"] == 1
    assert [(p.name, p.joint, p.axis) for p in POSE_LAYOUT[LEGACY_POSE_PARAMS:]] == [
        ("spine_bend", "spine", (0.0, 0.0, 1.0)), ("spine_twist", "spine", (0.0, 1.0, 0.0))]
    for side in "lr":
        # Each complete limb has four degrees of freedom (3 at the root, 1 at the hinge).
        assert dof[f"{side}_shoulder"] + dof[f"{side}_elbow"] == 4
        assert dof[f"{side}_hip"] + dof[f"{side}_knee"] == 4
    for p in POSE_LAYOUT:
        assert p.unit == ("m" if p.kind == "translation" else "rad")
        assert p.lower < p.upper
        assert np.isclose(np.linalg.norm(p.axis), 1.0)


def test_hinge_limits_are_0_to_150_degrees() -> None:
    for name in ("l_elbow_flex", "r_elbow_flex", "l_knee_flex", "r_knee_flex"):
        (p,) = [p for p in POSE_LAYOUT if p.name == name]
        assert (p.lower, p.upper) == pytest.approx((0.0, np.radians(150.0)))


def test_pose_dict_round_trip_and_unknown_name() -> None:
    pose = Pose.from_dict({"l_knee_flex": 0.5, "root_ty": 1.0})
    d = pose.as_dict()
    assert d["l_knee_flex"] == 0.5 and d["root_ty"] == 1.0
    assert sum(v != 0 for v in d.values()) == 2
    assert np.array_equal(Pose.from_dict(d).params, pose.params)
    with pytest.raises(KeyError):
        Pose.from_dict({"l_wrist_flex": 0.1})
    with pytest.raises(ValueError):
        Pose(np.zeros(23))
    with pytest.raises(ValueError):
        pose.params[0] = 1.0  # read-only


def test_whole_turns_wrap_and_joint_angles_clip_into_their_ranges() -> None:
    # The root's roll, pitch and heading are the whole turns: a search moves them past 180
    # degrees (a subject spins), and a stored pose has them in -180..180.
    assert [p.name for p, whole in zip(POSE_LAYOUT, WHOLE_TURN, strict=True) if whole] == [
        "root_rz", "root_rx", "root_ry"]
    assert np.all(np.isinf(SEARCH_LOWER_LIMITS[WHOLE_TURN]))
    assert np.array_equal(SEARCH_LOWER_LIMITS[~WHOLE_TURN], LOWER_LIMITS[~WHOLE_TURN])
    assert np.array_equal(SEARCH_UPPER_LIMITS[~WHOLE_TURN], UPPER_LIMITS[~WHOLE_TURN])
    x = Pose.from_dict({"root_ry": np.radians(200.0), "root_rz": np.radians(-530.0),
                        "root_rx": np.radians(90.0), "l_elbow_flex": 3.0,
                        "root_tx": 100.0}).params.copy()
    y = Pose(in_limits(x))
    assert np.degrees(y.as_dict()["root_ry"]) == pytest.approx(-160.0)
    assert np.degrees(y.as_dict()["root_rz"]) == pytest.approx(-170.0)
    assert np.degrees(y.as_dict()["root_rx"]) == pytest.approx(90.0)
    assert y.as_dict()["l_elbow_flex"] == pytest.approx(np.radians(150.0))
    assert y.as_dict()["root_tx"] == 100.0
    assert y.violations() == ()
    assert np.array_equal(Pose(x).clamped().params, y.params)
    # The same rotation: the body does not move.
    x[PARAM_INDEX["l_elbow_flex"]] = 1.0
    assert np.allclose(forward_kinematics(Pose(x), SHAPE),
                       forward_kinematics(Pose(in_limits(x)), SHAPE))
    assert np.degrees(turn_difference(np.radians(-170.0), np.radians(170.0))) == pytest.approx(
        20.0)
    assert np.degrees(turn_difference(np.radians(170.0), np.radians(-170.0))) == pytest.approx(
        -20.0)


def test_clamp_and_violations() -> None:
    pose = Pose.from_dict({"l_knee_flex": -0.2, "r_elbow_flex": 3.0, "root_tx": 100.0})
    bad = {v.name: v for v in pose.violations()}
    assert set(bad) == {"l_knee_flex", "r_elbow_flex"}
    assert bad["l_knee_flex"].excess == pytest.approx(0.2)
    assert bad["r_elbow_flex"].excess == pytest.approx(3.0 - np.radians(150.0))
    clamped = pose.clamped().as_dict()
    assert clamped["l_knee_flex"] == 0.0
    assert clamped["r_elbow_flex"] == pytest.approx(np.radians(150.0))
    assert clamped["root_tx"] == 100.0  # the root is free
    assert pose.clamped().violations() == ()
    assert Pose.neutral().violations() == ()


def test_right_shoulder_abduction_limits_mirror_the_left() -> None:
    limits = {p.name: (p.lower, p.upper) for p in POSE_LAYOUT}
    lo, hi = limits["l_shoulder_rz"]
    assert limits["r_shoulder_rz"] == pytest.approx((-hi, -lo))


# ------------------------------------------------------------------------- forward kinematics


def test_neutral_joints_are_summed_rest_offsets() -> None:
    offsets = rest_offsets(SHAPE)
    joints = _joints()
    for i, name in enumerate(NODE_NAMES):
        expected, node = np.zeros(3), i
        while node >= 0:
            expected += offsets[node]
            node = NODE_PARENTS[node]
        assert np.allclose(joints[name], expected), name
    # Hand-computed for H = 1.75 m: shoulder 0.1295H left and 0.288H above the hip level.
    assert np.allclose(joints["l_shoulder"], [0.1295 * 1.75, 0.288 * 1.75, 0.0])
    assert np.allclose(joints["l_ankle"], [0.05 * 1.75, -(0.245 + 0.246) * 1.75, 0.0])


def test_neutral_frames_are_world_aligned() -> None:
    world = forward_kinematics(Pose.neutral(), SHAPE)
    assert world.shape == (len(NODE_NAMES), 4, 4)
    assert np.allclose(world[:, :3, :3], np.eye(3))


def test_elbow_flexion_90_degrees_points_forearm_forward() -> None:
    j = _joints(l_elbow_flex=HALF_PI)
    shoulder_y = SHAPE.pelvis_to_spine + SHAPE.spine_to_neck
    elbow = np.array([SHAPE.shoulder_half_width, shoulder_y - SHAPE.upper_arm, 0.0])
    assert np.allclose(j["l_elbow"], elbow)
    assert np.allclose(j["l_wrist"], elbow + [0.0, 0.0, SHAPE.forearm])
    assert np.allclose(j["r_wrist"], _joints()["r_wrist"])  # the other arm is untouched


def test_knee_flexion_90_degrees_points_shank_backward() -> None:
    j = _joints(r_knee_flex=HALF_PI)
    knee = np.array([-SHAPE.hip_half_width, -SHAPE.thigh, 0.0])
    assert np.allclose(j["r_knee"], knee)
    assert np.allclose(j["r_ankle"], knee + [0.0, 0.0, -SHAPE.shank])


def test_shoulder_abduction_then_twist_then_elbow_follows_zxy_order() -> None:
    # Rz(90) lifts the left arm sideways to +X; the twist Ry(90) about the (now horizontal) bone
    # turns the elbow's forward flexion direction (+Z) into +Y: the forearm points up.
    j = _joints(l_shoulder_rz=HALF_PI, l_shoulder_ry=HALF_PI, l_elbow_flex=HALF_PI)
    shoulder = _joints()["l_shoulder"]
    elbow = shoulder + [SHAPE.upper_arm, 0.0, 0.0]
    assert np.allclose(j["l_elbow"], elbow)
    assert np.allclose(j["l_wrist"], elbow + [0.0, SHAPE.forearm, 0.0])


def test_hip_flexion_lifts_the_thigh_forward() -> None:
    j = _joints(l_hip_rx=-HALF_PI)
    assert np.allclose(j["l_knee"], [SHAPE.hip_half_width, 0.0, SHAPE.thigh])


def test_spine_flexion_bends_chest_forward() -> None:
    j = _joints(spine_flex=HALF_PI)
    spine = np.array([0.0, SHAPE.pelvis_to_spine, 0.0])
    assert np.allclose(j["neck"], spine + [0.0, 0.0, SHAPE.spine_to_neck])
    assert np.allclose(j["l_hip"], _joints()["l_hip"])


def test_root_moves_everything_rigidly() -> None:
    t = np.array([1.0, 0.9, -2.0])
    pose = Pose.from_dict({"root_tx": t[0], "root_ty": t[1], "root_tz": t[2],
                           "root_ry": HALF_PI, "l_elbow_flex": 0.7})  # fmt: skip
    rest = Pose.from_dict({"l_elbow_flex": 0.7})
    yaw_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    moved = node_positions_in_world(pose, SHAPE)
    still = node_positions_in_world(rest, SHAPE)
    for name in NODE_NAMES:
        assert np.allclose(moved[name], yaw_90 @ still[name] + t), name
    # Yaw +90 about Y turns the left side (+X) to -Z.
    sx, sy = SHAPE.shoulder_half_width, SHAPE.pelvis_to_spine + SHAPE.spine_to_neck
    assert np.allclose(moved["l_shoulder"], t + [0.0, sy, -sx])
    assert np.allclose(MODEL.posed_vertices(pose), MODEL.posed_vertices(rest) @ yaw_90.T + t)


def test_root_euler_order_is_z_then_x_then_y() -> None:
    a, b = 0.3, -0.4
    world = forward_kinematics(Pose.from_dict({"root_rz": a, "root_rx": b}), SHAPE)
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cb, -sb], [0, sb, cb]])
    assert np.allclose(world[NODE_INDEX["pelvis"], :3, :3], rz @ rx)


def test_pose_in_a_rotated_frame_is_the_same_body_rotated() -> None:
    """A pose re-expressed in a frame rotated about the origin moves every node and vertex by
    that rotation; only the root's six parameters change. Pitch 90 degrees (an upright body
    in a Z-up world) is the root angles' gimbal lock, where the angles are still exact."""
    rng = np.random.default_rng(3)
    for pitch in (0.4, HALF_PI):
        pose = Pose(rng.uniform(-0.5, 0.5, N_POSE_PARAMS)).clamped()
        pose = Pose.from_dict({**pose.as_dict(), "root_rx": pitch})
        q = _rotation(rng)
        moved = pose_in_frame(pose, q)
        a, b = forward_kinematics(pose, SHAPE), forward_kinematics(moved, SHAPE)
        assert np.allclose(q @ a[:, :3, :3], b[:, :3, :3], atol=1e-9)
        assert np.allclose(a[:, :3, 3] @ q.T, b[:, :3, 3], atol=1e-9)
        assert np.allclose(MODEL.posed_vertices(pose) @ q.T, MODEL.posed_vertices(moved))
        assert np.array_equal(moved.params[6:], pose.params[6:])
        assert np.allclose(root_rotation(moved), b[NODE_INDEX["pelvis"], :3, :3])
    # The root's ZXY angles back from its rotation; at the lock, one of the equivalent sets.
    for angles in ([0.3, -0.4, 1.1], [0.3, HALF_PI, 1.1], [-2.0, -HALF_PI, 0.5]):
        pose = Pose.from_dict(dict(zip(("root_rz", "root_rx", "root_ry"), angles, strict=True)))
        back = np.deg2rad(rotations_to_channels(root_rotation(pose), "ZXY"))
        again = Pose.from_dict(dict(zip(("root_rz", "root_rx", "root_ry"), back, strict=True)))
        assert np.allclose(root_rotation(again), root_rotation(pose), atol=1e-9), angles
        if abs(angles[1]) < 1.0:
            assert np.allclose(again.params[3:6], angles)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# ------------------------------------------------------------------------- mesh


def test_counts_match_the_thesis_model_roughly() -> None:
    assert len(MODEL.segments) == 29
    assert 2500 <= len(MODEL.rest_vertices) <= 3300  # thesis: 2,894
    assert 5000 <= len(MODEL.faces) <= 6200  # thesis: 5,600
    assert MODEL.segment_of_vertex.shape == (len(MODEL.rest_vertices),)
    assert set(np.unique(MODEL.segment_of_vertex)) == set(range(29))


def _segment_mesh(k: int, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keep = np.flatnonzero(MODEL.segment_of_vertex == k)
    faces = MODEL.faces[MODEL.segment_of_face == k] - keep[0]
    return vertices[keep], faces


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


@pytest.mark.parametrize("k", range(29))
def test_every_segment_is_closed_watertight_and_outward(k: int) -> None:
    verts, faces = _segment_mesh(k, MODEL.rest_vertices)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(verts), o3d.utility.Vector3iVector(faces)
    )
    assert mesh.is_watertight(), MODEL.segments[k].name
    assert mesh.is_orientable()
    edges = {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert len(verts) - len(edges) + len(faces) == 2  # Euler characteristic of a sphere
    semi = np.array(MODEL.segments[k].semi_axes)
    ellipsoid = 4.0 / 3.0 * np.pi * np.prod(semi)
    # Outward normals give a positive volume, near the ellipsoid's (a superquadric with eps < 1
    # is fuller; faceting makes it a little smaller).
    assert 0.7 * ellipsoid < _signed_volume(verts, faces) < 1.9 * ellipsoid


def test_superquadric_orientation_is_outward_for_a_unit_sphere() -> None:
    verts, faces = superquadric(np.ones(3))
    a, b, c = (verts[faces[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    assert np.all(np.einsum("ij,ij->i", normals, verts[faces].mean(axis=1)) > 0)


def test_neutral_model_height_matches_shape_height() -> None:
    for height in (1.6, 1.75, 1.9):
        model = BodyModel(BodyShape.default(height))
        extent = np.ptp(model.rest_vertices[:, 1])
        assert extent == pytest.approx(height, rel=0.03)
        # Standing on the floor: the soles are at the hip height below the pelvis.
        assert model.rest_vertices[:, 1].min() == pytest.approx(-model.shape.hip_height, abs=1e-9)


def test_posed_segments_move_rigidly_with_their_bone() -> None:
    rng = np.random.default_rng(0)
    lo = np.array([max(p.lower, -1.0) for p in POSE_LAYOUT])
    hi = np.array([min(p.upper, 1.0) for p in POSE_LAYOUT])
    pose = Pose(rng.uniform(lo, hi))
    posed = MODEL.posed_vertices(pose)
    world = forward_kinematics(pose, SHAPE)
    for k, spec in enumerate(MODEL.segments):
        before, _ = _segment_mesh(k, MODEL.rest_vertices)
        after, _ = _segment_mesh(k, posed)
        d0 = np.linalg.norm(before[:, None] - before[None], axis=-1)
        d1 = np.linalg.norm(after[:, None] - after[None], axis=-1)
        assert np.allclose(d0, d1), spec.name
        # And it is the bone's transform that moves it: centre follows world_from_node.
        node = world[NODE_INDEX[spec.node]]
        centre = node[:3, :3] @ np.array(spec.centre_in_node) + node[:3, 3]
        assert np.allclose(after.mean(axis=0), centre, atol=1e-9)
    # The lower arm moved differently from the upper arm, so skinning is per segment.
    assert not np.allclose(posed, MODEL.rest_vertices)


def test_forearm_mesh_follows_elbow_flexion() -> None:
    names = MODEL.segment_names
    k = names.index("l_forearm")
    posed, _ = _segment_mesh(k, MODEL.posed_vertices(Pose.from_dict({"l_elbow_flex": HALF_PI})))
    elbow = _joints()["l_elbow"]
    # Flexed 90 degrees, the forearm lies in front of the elbow at elbow height.
    assert posed[:, 2].max() == pytest.approx(elbow[2] + SHAPE.forearm)
    assert np.allclose(posed.mean(axis=0), elbow + [0.0, 0.0, SHAPE.forearm / 2])
    upper, _ = _segment_mesh(names.index("l_upper_arm"), MODEL.posed_vertices(Pose.neutral()))
    assert np.array_equal(upper, _segment_mesh(names.index("l_upper_arm"), MODEL.rest_vertices)[0])


def test_body_shape_rejects_inconsistent_lengths() -> None:
    from dataclasses import replace

    with pytest.raises(ValueError):
        replace(SHAPE, thigh=2.0)
    with pytest.raises(ValueError):
        replace(SHAPE, forearm=-0.1)


def test_pose_derivatives_match_finite_differences():
    rng = np.random.default_rng(1)
    shape = BodyShape.default(1.7)
    pose = Pose(rng.uniform(-0.5, 0.5, N_POSE_PARAMS))
    world, axes, pivots = pose_derivative_axes(pose, shape)
    eps = 1e-6
    for k, param in enumerate(POSE_LAYOUT):
        bumped = pose.params.copy()
        bumped[k] += eps
        moved = forward_kinematics(Pose(bumped), shape)
        numeric = (moved[:, :3, 3] - world[:, :3, 3]) / eps
        if param.kind == "translation":
            analytic = np.broadcast_to(axes[k], (len(NODE_NAMES), 3))
        else:
            analytic = np.cross(axes[k], world[:, :3, 3] - pivots[k])
        analytic = np.where(PARAM_MOVES_NODE[k][:, None], analytic, 0.0)
        np.testing.assert_allclose(numeric, analytic, atol=1e-5, err_msg=param.name)
