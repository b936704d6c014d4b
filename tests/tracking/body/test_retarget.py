"""Tests of tracking.body.retarget: synthetic round trips through our own model, and a real CMU
walk."""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import shared_dataset
from tracking.body.bvh import CMU_METRES_PER_UNIT, read_bvh
from tracking.body.model import (
    LOWER_LIMITS,
    NODE_INDEX,
    NODE_NAMES,
    PARAM_INDEX,
    UPPER_LIMITS,
    BodyShape,
    Pose,
    forward_kinematics,
    node_positions_in_world,
)
from tracking.body.retarget import CMU_TO_BODY, fit_pose, retarget, shape_from_motion

SHAPE = BodyShape.default(1.75)
LIMBS = (("l_shoulder", "l_elbow_flex"), ("r_shoulder", "r_elbow_flex"),
         ("l_hip", "l_knee_flex"), ("r_hip", "r_knee_flex"))  # fmt: skip


def random_pose(rng: np.random.Generator, margin: float = 0.05) -> Pose:
    """Uniform in the limits (shrunk by `margin` of each range), root anywhere near the origin."""
    lo = np.where(np.isfinite(LOWER_LIMITS), LOWER_LIMITS, -1.0)
    hi = np.where(np.isfinite(UPPER_LIMITS), UPPER_LIMITS, 1.0)
    span = hi - lo
    return Pose(rng.uniform(lo + margin * span, hi - margin * span))


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_round_trip_recovers_positions_and_determined_angles(seed: int) -> None:
    rng = np.random.default_rng(seed)
    truth = random_pose(rng)
    targets = node_positions_in_world(truth, SHAPE)
    fitted, rms = fit_pose(targets, SHAPE, init=None)
    got = node_positions_in_world(fitted, SHAPE)
    err = max(np.linalg.norm(got[n] - targets[n]) for n in NODE_NAMES)
    assert err < 1e-3, f"max node error {err * 1000:.3f} mm"
    assert rms < 1e-3
    assert not fitted.violations()

    w_true, w_fit = forward_kinematics(truth, SHAPE), forward_kinematics(fitted, SHAPE)
    # Root rotation is determined by pelvis, hips and spine (compare matrices: Euler angles
    # have the (rz + pi, pi - rx, ry + pi) twin).
    assert rotation_angle_deg(w_true[0, :3, :3], w_fit[0, :3, :3]) < 0.5
    np.testing.assert_allclose(w_fit[0, :3, 3], w_true[0, :3, 3], atol=1e-4)
    # Spine flex and neck nod are determined by the neck/shoulder and head-top positions.
    for name in ("spine_flex", "neck_flex"):
        i = PARAM_INDEX[name]
        assert abs(np.degrees(fitted.params[i] - truth.params[i])) < 0.5, name
    for ball, hinge in LIMBS:
        i = PARAM_INDEX[hinge]
        # The hinge angle is determined by the root-to-end distance of the limb.
        assert abs(np.degrees(fitted.params[i] - truth.params[i])) < 0.5, hinge
        # The ball joint's whole frame (twist included) is determined only for a bent limb.
        if np.degrees(truth.params[i]) > 10.0:
            k = NODE_INDEX[ball]
            assert rotation_angle_deg(w_true[k, :3, :3], w_fit[k, :3, :3]) < 1.0, ball


def test_round_trip_of_a_straight_limb_reports_positions_not_twist() -> None:
    # A straight arm's twist is free: the fit need not recover it, but positions must match.
    truth = Pose.from_dict({"l_shoulder_ry": 0.8, "l_shoulder_rz": 0.4, "root_ty": 1.0})
    targets = node_positions_in_world(truth, SHAPE)
    fitted, rms = fit_pose(targets, SHAPE)
    assert rms < 1e-4
    got = node_positions_in_world(fitted, SHAPE)
    assert np.linalg.norm(got["l_wrist"] - targets["l_wrist"]) < 1e-4


def test_unreachable_targets_stay_within_limits() -> None:
    # Knees hyperextended by 40 degrees and an elbow bent backwards: outside the limits, so the
    # fit must clamp (nonzero residual) rather than leave the bounds.
    params = Pose.neutral().params.copy()
    for name in ("l_knee_flex", "r_knee_flex", "l_elbow_flex"):
        params[PARAM_INDEX[name]] = -np.radians(40.0)
    params[PARAM_INDEX["root_ty"]] = 0.9
    targets = node_positions_in_world(Pose(params), SHAPE)
    fitted, rms = fit_pose(targets, SHAPE)
    assert not fitted.violations()
    assert np.all(fitted.params >= LOWER_LIMITS) and np.all(fitted.params <= UPPER_LIMITS)
    assert rms > 5e-3


def test_warm_start_tracks_a_smooth_motion() -> None:
    rng = np.random.default_rng(7)
    a, b = random_pose(rng, 0.2), random_pose(rng, 0.2)
    prev = None
    for t in np.linspace(0.0, 1.0, 6):
        truth = Pose((1 - t) * a.params + t * b.params)
        targets = node_positions_in_world(truth, SHAPE)
        prev, rms = fit_pose(targets, SHAPE, init=prev)
        assert rms < 1e-3, t
        assert not prev.violations()


def test_fit_pose_rejects_unknown_nodes() -> None:
    with pytest.raises(KeyError):
        fit_pose({"nose": np.zeros(3)}, SHAPE)


def test_correspondence_covers_every_node() -> None:
    assert set(CMU_TO_BODY) == set(NODE_NAMES)


@pytest.fixture(scope="module")
def walk():
    return read_bvh(shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh")


@pytest.fixture(scope="module")
def walk_result(walk):
    return retarget(walk, CMU_METRES_PER_UNIT, frames=range(0, 41, 10))


@pytest.mark.shared_data
def test_shape_from_cmu_walk(walk) -> None:
    shape = shape_from_motion(walk, CMU_METRES_PER_UNIT)  # BodyShape checks its own height
    assert 1.5 < shape.height < 1.9
    mpu = CMU_METRES_PER_UNIT
    # Truth: bone lengths are the norms of the child joints' rest offsets.
    off = {j.name: np.linalg.norm(j.offset) * mpu for j in walk.joints}
    np.testing.assert_allclose(shape.thigh, (off["LeftLeg"] + off["RightLeg"]) / 2, rtol=1e-6)
    np.testing.assert_allclose(shape.shank, (off["LeftFoot"] + off["RightFoot"]) / 2, rtol=1e-6)
    np.testing.assert_allclose(
        shape.upper_arm, (off["LeftForeArm"] + off["RightForeArm"]) / 2, rtol=1e-6
    )
    np.testing.assert_allclose(shape.forearm, (off["LeftHand"] + off["RightHand"]) / 2, rtol=1e-6)
    assert np.isclose(shape.chain_height, shape.height)


@pytest.mark.shared_data
def test_retarget_cmu_walk(walk_result) -> None:
    r = walk_result
    assert len(r.poses) == 5 and r.residual_rms_m.shape == (5,)
    s = r.summary
    print(f"CMU 02_01 walk frames 0..40/10: residual RMS mm {np.round(r.residual_rms_m * 1e3, 1)}"
          f" mean {s['mean_residual_mm']:.1f} max {s['max_residual_mm']:.1f};"
          f" height {r.shape.height:.3f} m")  # fmt: skip
    assert s["mean_residual_mm"] < 50.0  # the brief's bound
    assert s["mean_residual_mm"] < 30.0  # regression guard: measured 20.3 mm
    assert s["max_residual_mm"] < 80.0
    for pose in r.poses:
        assert not pose.violations()
    knees = np.degrees([[p.params[PARAM_INDEX[k]] for k in ("l_knee_flex", "r_knee_flex")]
                        for p in r.poses])  # fmt: skip
    assert knees.max() > 20.0


@pytest.mark.shared_data
def test_the_asf_named_cmu_clip_retargets_too():
    from tracking.body.retarget import CMU_ASF_TO_BODY, cmu_naming

    clip_path = shared_dataset("mocap_bvh") / "cmu_131_01_start_walk_stop.bvh"
    clip = read_bvh(clip_path)
    assert cmu_naming(clip).nodes is CMU_ASF_TO_BODY
    result = retarget(clip, CMU_METRES_PER_UNIT, frames=range(0, clip.num_frames, 50))
    assert 1.4 < result.shape.height < 1.9
    assert result.summary["mean_residual_mm"] < 25


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["cmu_kick", "cmu_sit_stand"])
def test_the_daz_named_clips_retarget_in_their_own_unit(name):
    from tracking.body.retarget import DAZ_TO_BODY, bvh_metres_per_unit, cmu_naming

    clip = read_bvh(shared_dataset("mocap_bvh") / f"{name}.bvh")
    assert cmu_naming(clip).nodes is DAZ_TO_BODY
    assert bvh_metres_per_unit(clip) == 0.01
    result = retarget(clip, frames=range(1, clip.num_frames, 100))  # the naming's unit
    assert 1.4 < result.shape.height < 1.9
    assert result.summary["mean_residual_mm"] < 30
    # The head top is extrapolated above the neck, along the head.
    assert 0.15 < result.shape.neck_to_head_top < 0.3
