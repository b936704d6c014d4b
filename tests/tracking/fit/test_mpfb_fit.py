"""Fitting MakeHuman's skinned body (``--body mpfb``) to point clouds of another mpfb subject."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from recon.errors import UserError
from tests.helpers import run_cli
from tracking.body.model import NODE_NAMES, Pose, pose_in_frame
from tracking.body.motion import read_pose_file
from tracking.body.mpfb.model import MacroShape
from tracking.body.mpfb.subject import MpfbModel
from tracking.body.synthetic import body_cloud, walking_poses
from tracking.fit.body_fit import FitConfig, fit_body
from tracking.fit.step import fit_summary
from tracking.track.step import _model_of_pose_file

# benchmarks/body_fit.py's mismatched subject: not the fit's start (MakeHuman's average).
MISMATCHED = MpfbModel(MacroShape(gender=0.2, weight=0.7, height=0.4, age_years=40.0),
                       clothes_cm=2.0, mesh="full")  # fmt: skip


@pytest.fixture(scope="module")
def walking_fit():
    """A mid-stride walking pose (legs apart, arms swinging, elbows bent) at a heading of
    130 degrees, its cloud (5 mm noise, 30% hidden) and the mpfb fit of it."""
    rng = np.random.default_rng(3)
    pose = walking_poses(12, 30.0, MISMATCHED.shape, phase_deg=90.0)[8]
    c, s = np.cos(np.deg2rad(130.0)), np.sin(np.deg2rad(130.0))
    pose = pose_in_frame(pose, np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]))
    points, _ = body_cloud(MISMATCHED, pose, rng)
    return pose, points, fit_body(points, FitConfig(body="mpfb"))


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
def test_mpfb_fit_recovers_the_joints_of_another_mpfb_subject(walking_fit):
    pose, _, result = walking_fit
    truth = MISMATCHED.joints(pose)
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - truth, axis=1)
    assert result.success, result.message
    assert result.model.name == "mpfb"
    # Measured: mean 2.9 mm, max 5.1 mm.
    assert errors.mean() < 0.010
    assert errors.max() < 0.020
    assert result.shape.height == pytest.approx(MISMATCHED.shape.height, abs=0.02)
    # The clothing is found: the trunk is 2 cm out, not MakeHuman's bare average.
    assert result.model.record()["clothes_cm"] == pytest.approx(2.0, abs=1.0)
    assert result.residual_median < 0.005  # 5 mm noise: |N(0, 5 mm)| has median 3.4 mm


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
def test_the_fit_file_starts_mpfb_tracking_with_the_fitted_subject(walking_fit, tmp_path):
    pose, _, result = walking_fit
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit_summary(result)))
    given = read_pose_file(path)
    model = _model_of_pose_file(path, given, "mpfb")  # what `mocap track --init-pose` builds
    assert given.body == result.model.record()
    start = Pose(given.frames[0][1])
    # The tracker's (decimated) subject puts the joints where the fit did.
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    assert np.abs(model.joints(start) - fitted).max() < 1e-6
    assert np.allclose(json.loads(path.read_text())["joints"]["pelvis"], fitted[0])


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
def test_cli_mpfb_fit_of_a_box_fails_and_still_writes_the_body(tmp_path):
    rng = np.random.default_rng(0)
    # A 0.5 x 1.7 x 0.3 m box's surface: body-sized, but no body.
    box = rng.uniform(-1.0, 1.0, size=(4000, 3))
    side = rng.integers(0, 3, size=len(box))
    box[np.arange(len(box)), side] = np.sign(box[np.arange(len(box)), side])
    box *= np.array([0.25, 0.85, 0.15])
    cloud = tmp_path / "box.ply"
    o3d.io.write_point_cloud(str(cloud), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(box)))
    out = tmp_path / "fit"
    # One orientation, judged, no fallback (the search's depth is not what this test is about).
    done = run_cli("fit", "--cloud", cloud, "--out", out, "--body", "mpfb", "--no-isolate",
                   "--orientations", "1", "--max-orientations", "1",
                   "--judged", "1", "--fallback-orientations", "0")  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "does not look like one human body" in done.stderr
    data = json.loads((out / "fit.json").read_text())
    assert data["success"] is False
    assert data["body"]["name"] == "mpfb" and set(data["body"]) >= {"macro", "clothes_cm"}
    mesh = o3d.io.read_triangle_mesh(str(out / "fit.ply"))
    assert len(mesh.vertices) == len(MISMATCHED.node_weights)  # the full mesh, 13,380


def _real_pose(clip: str, frame: int) -> Pose:
    """Frame `frame` of a CMU clip on our skeleton, turned as benchmarks/body_fit.py turns it."""
    from tests.helpers import shared_dataset
    from tracking.body.bvh import read_bvh
    from tracking.body.retarget import retarget

    motion = read_bvh(shared_dataset("mocap_bvh") / clip)
    pose = retarget(motion, None, [frame]).poses[0]  # in the clip naming's unit
    angle = np.random.default_rng(frame).uniform(-np.pi, np.pi)
    c, s = np.cos(angle), np.sin(angle)
    return pose_in_frame(pose, np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]))


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize(("clip", "frame", "seed"), [
    # Fitted with the legs crossed, each in the other's place (knees 300 mm, ankles 550 mm
    # off), and accepted with 90.2% inliers, before the two-leg search and the 95% bar.
    ("cmu_02_01_walk.bvh", 146, 1002),
    # Standing with an arm raised: fitted 29 cm too tall, bent over, and accepted with 91.4%
    # inliers, before the 95% bar sent the search on to the next orientations.
    ("cmu_bend_pickup.bvh", 1915, 1023),
    # Standing with an arm overhead: the 12 best trunk fits were all head down, so the fit
    # was upside down (reported failed, 780 mm off), before both ends of the cloud were tried.
    # With the chest's bend and twist (session 17) it was accepted with a joint 70 mm off
    # until accepted fits had their limbs searched again: 3.2 mm, max 5.
    ("cmu_bend_pickup.bvh", 1277, 1021),
    # A hanging arm fitted raised (refused: left arm 385-628 mm off), before a refused limb
    # was searched again with every candidate refined (`repair_limbs`): 3.5 mm, max 8.
    ("cmu_dance.bvh", 449, 1001),
    # Picking up, the chest bent sideways: the left forearm laid along the thigh and accepted
    # (wrist 86 mm off, every point on the body; the hand's points are explained by the leg),
    # before accepted fits had their limbs searched again on up to 4x the fit's points
    # (session 17; on the fit's 1,500 points that search ended 108 mm off): 5 mm.
    ("cmu_bend_pickup.bvh", 319, 1018),
    # Stopping from a walk: accepted with the left wrist 121 mm off (forearm twisted and
    # straighter than it is) and with the right elbow 100 mm off (the upper arm turned into
    # a mirror configuration), before the second look searched on all the points with more
    # starts and rounds (`search_limbs` with ``dense``; session 18): 6 and 5 mm.
    ("cmu_131_01_start_walk_stop.bvh", 198, 1008),
    ("cmu_131_01_start_walk_stop.bvh", 397, 1009),
])  # fmt: skip
def test_mpfb_fit_of_real_clip_poses_once_fitted_wrong(clip, frame, seed):
    pose = _real_pose(clip, frame)
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(seed))
    result = fit_body(points, FitConfig(body="mpfb"))
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - MISMATCHED.joints(pose), axis=1)
    assert result.success, result.message
    # Measured after the fixes: mean 2-4 mm, max 5-18 mm.
    assert errors.mean() < 0.010 and errors.max() < 0.040


@pytest.mark.slow
def test_mpfb_fit_of_a_cloud_of_unknown_scale_is_in_its_units(walking_fit, tmp_path):
    """A workspace's SfM cloud has no metric scale: the skinned body (in metres) is fitted to
    the cloud brought to 1.75 m, and everything the fit gives is back in the cloud's units."""
    pose, points, metric = walking_fit
    result = fit_body(3.0 * points, FitConfig(body="mpfb", metric=False))
    assert result.success, result.message
    assert result.model_to_cloud == pytest.approx(3.0 * MISMATCHED.shape.height / 1.75, rel=0.02)
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted / 3.0 - MISMATCHED.joints(pose), axis=1)
    assert errors.mean() < 0.010  # metric cloud: 2.9 mm
    assert result.summary()["height"] == pytest.approx(3.0 * MISMATCHED.shape.height, rel=0.02)
    assert np.abs(result.vertices() / 3.0 - metric.vertices()).max() < 0.05
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit_summary(result)))
    with pytest.raises(UserError, match="cloud of unknown scale"):
        read_pose_file(path)


def test_acceptance_refuses_a_limb_fitted_elsewhere():
    """The body right but for one arm: a global inlier share of 95% lets it through (the arm
    is under 5% of the points), the two local checks do not."""
    from tracking.body.model import PARAM_INDEX
    from tracking.fit.body_fit import acceptance

    pose = walking_poses(12, 30.0, MISMATCHED.shape, phase_deg=90.0)[8]
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(5))
    loose = FitConfig(max_unexplained_cluster=1.0, min_limb_support=0.0)
    ok, problems, (_, _, inliers) = acceptance(MISMATCHED, pose, points, FitConfig())
    assert ok, problems
    assert inliers > 0.99
    arm_back = pose.params.copy()
    arm_back[PARAM_INDEX["l_shoulder_rx"]] = np.deg2rad(45.0)  # swung back, not forward
    arm_back = Pose(arm_back)
    ok, problems, (_, _, inliers) = acceptance(MISMATCHED, arm_back, points, loose)
    assert ok and inliers > 0.95, problems  # what the global test alone says (95.3%)
    ok, problems, _ = acceptance(MISMATCHED, arm_back, points, FitConfig())
    assert not ok
    message = "; ".join(problems)
    assert "points on the left forearm segment" in message  # 4.7% of the points in one place
    assert "together in one place" in message


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize(("clip", "frame", "seed"), [
    ("cmu_squat.bvh", 176, 1006),  # a forearm fitted into the trunk: accepted at 96% inliers
    ("cmu_boxing.bvh", 370, 1008),  # a forearm hanging instead of forward: 98% inliers
])  # fmt: skip
def test_mpfb_fit_of_real_clip_poses_is_right_or_refused(clip, frame, seed):
    """Poses the search got wrong while the global inlier share accepted them (max joint
    errors 207-591 mm), before the local checks of `acceptance`: now right or refused (a
    third, a CMU dance frame, is now right: see the test above)."""
    pose = _real_pose(clip, frame)
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(seed))
    result = fit_body(points, FitConfig(body="mpfb"))
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - MISMATCHED.joints(pose), axis=1)
    assert not result.success or errors.max() < 0.050, (result.message, errors.max())


@pytest.mark.slow
@pytest.mark.shared_data
def test_arms_overhead_239_is_right_or_refused_near_the_truth():
    """Arms overhead, frame 239 (the right forearm turned 47 degrees and bent 38): every
    orientation of the standing start is refused, for that forearm. The failed result was
    the superquadrics' lowest-cost fit, upside down (every joint 100-450 mm off, mean 268 mm),
    until a refused fit reported the judged fit of the lowest skinned cost (upright, mean 19
    mm) and the centroid start was tried after the standing one (session 19: accepted, 2.4 mm
    in benchmarks/body_fit.py). Right or refused, never reported far off."""
    pose = _real_pose("cmu_arms_overhead.bvh", 239)
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(1000))
    result = fit_body(points, FitConfig(body="mpfb"))
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - MISMATCHED.joints(pose), axis=1)
    assert not result.success or errors.max() < 0.050, (result.message, errors.max())
    assert errors.mean() < 0.030 and np.median(errors) < 0.015, errors  # right or refused


@pytest.mark.slow
@pytest.mark.shared_data
def test_a_seated_body_is_fitted_from_the_roots_ranked_with_limbs():
    """Sit-stand frame 860, seated on a stool (knees bent 119-143 degrees, thighs abducted,
    the trunk leaning 40 degrees), the cloud of `benchmarks/body_fit.py --clips fresh`: the
    trunk alone ranked its right roots 124th of 320, and every searched orientation was
    refused (reported 314 mm off). Ranked with the limbs (the second fallback start), it is
    accepted (session 20: 2.6 mm)."""
    _assert_fitted_within_30_mm("cmu_sit_stand.bvh", 860, seed=1005)


@pytest.mark.slow
@pytest.mark.shared_data
def test_a_kick_is_fitted_from_the_trunk_twisted_at_the_waist():
    """Kick frame 640, the cloud of `benchmarks/body_fit.py --clips fresh`: the right leg swung
    forward and 30 degrees across, the chest twisted 45 degrees from the hips. Every stage
    before the twisted-trunk fallback was refused (reported 181 mm off, the twist the wrong
    way); from the standing trunk fits twisted at the waist, the legs set as a pair that may
    cross, it is accepted (2.9 mm, max 5)."""
    _assert_fitted_within_30_mm("cmu_kick.bvh", 640, seed=1003)


def _assert_fitted_within_30_mm(clip: str, frame: int, seed: int) -> None:
    """The fit of `benchmarks/body_fit.py`'s cloud of this CMU frame (the mismatched subject,
    its seed) is accepted with every joint within 30 mm."""
    pose = _real_pose(clip, frame)
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(seed))
    result = fit_body(points, FitConfig(body="mpfb"))
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - MISMATCHED.joints(pose), axis=1)
    assert result.success, result.message
    assert errors.max() < 0.030, errors


def test_limbs_set_to_their_best_candidates_rank_a_root():
    """`with_limbs`: a trunk fit whose limbs hang straight is scored with each limb on its
    best grid candidate. On a seated cloud (not the fit's own model), from the true root: the
    cost falls, and both thighs come forward, as seated."""
    from tracking.body.model import PARAM_INDEX
    from tracking.fit.body_fit import _bounds, _Problem, _surface, with_limbs

    pose = walking_poses(1, 30.0, MISMATCHED.shape)[0]
    params = pose.params.copy()
    for side, sign in (("l", 1.0), ("r", -1.0)):
        params[PARAM_INDEX[f"{side}_hip_rx"]] = np.deg2rad(-90.0)
        params[PARAM_INDEX[f"{side}_hip_rz"]] = np.deg2rad(10.0) * sign
        params[PARAM_INDEX[f"{side}_knee_flex"]] = np.deg2rad(90.0)
    seated = Pose(params)
    points, _ = body_cloud(MISMATCHED, seated, np.random.default_rng(3))
    points = points[np.random.default_rng(0).choice(len(points), 400, replace=False)]
    height = MISMATCHED.shape.height
    problem = _Problem(_surface(), _bounds(height), 0.03 * height)
    x = np.concatenate([pose.params, [height, 1.0]])  # the true root, the walking limbs
    for limb_param in ("hip_rx", "hip_rz", "knee_flex", "shoulder_rx", "elbow_flex"):
        for side in "lr":
            x[PARAM_INDEX[f"{side}_{limb_param}"]] = 0.0
    before = problem.cost(x, points, np.arange(0, problem.n_samples, 4))
    cost, ranked = with_limbs(problem, x, points)
    assert cost < 0.8 * before, (cost, before)
    for side in "lr":
        assert np.rad2deg(ranked[PARAM_INDEX[f"{side}_hip_rx"]]) < -55.0, side  # -60 or -90


def test_a_limb_fitted_elsewhere_is_found_again_by_the_repair():
    """`repair_limbs`, the second chance of a fit refused for a limb: from MakeHuman's average
    subject (not the cloud's) with the left arm held out sideways, every candidate of that
    arm is refined and the arm comes back; the body then passes."""
    from tracking.body.model import PARAM_INDEX
    from tracking.fit.body_fit import acceptance
    from tracking.fit.skinned_fit import fitting_model, repair_limbs

    pose = walking_poses(12, 30.0, MISMATCHED.shape, phase_deg=90.0)[8]
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(5))
    start = fitting_model("mpfb", MISMATCHED.shape.height)
    arm_out = pose.params.copy()
    for name, degrees in (("l_shoulder_rz", 90.0), ("l_shoulder_rx", 0.0), ("l_elbow_flex", 0.0)):
        arm_out[PARAM_INDEX[name]] = np.deg2rad(degrees)
    arm_out = Pose(arm_out)
    truth = MISMATCHED.joints(pose)
    wrist = NODE_NAMES.index("l_wrist")
    assert np.linalg.norm(start.joints(arm_out)[wrist] - truth[wrist]) > 0.3
    assert not acceptance(start, arm_out, points, FitConfig())[0]
    model, repaired = repair_limbs(start, arm_out, points, FitConfig(), ("l_arm",))
    errors = np.linalg.norm(model.joints(repaired) - truth, axis=1)
    ok, problems, _ = acceptance(model, repaired, points, FitConfig())
    assert ok, problems
    assert errors[wrist] < 0.025 and errors.mean() < 0.012, errors


@pytest.mark.slow
@pytest.mark.shared_data
def test_the_thorough_repair_finds_a_forearm_between_the_candidates():
    """The second look's search (`repair_limbs` with ``thorough``): from MakeHuman's average
    subject with the left forearm of a start-walk-stop frame twisted 12 degrees too far and
    bent 22 instead of 53 degrees (the fit that was accepted 121 mm off), the ordinary
    search ends elsewhere and passes (measured: wrist 193 mm off); the thorough one, which
    also starts from the current configuration's twist and hinge turned and chooses on all
    the points, brings the wrist back (1 mm)."""
    from tracking.body.model import PARAM_INDEX
    from tracking.fit.skinned_fit import fitting_model, repair_limbs

    pose = _real_pose("cmu_131_01_start_walk_stop.bvh", 198)
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(1008))
    start = fitting_model("mpfb", MISMATCHED.shape.height)
    wrong = pose.params.copy()
    for name, degrees in (("l_shoulder_rz", 4.4), ("l_shoulder_rx", 0.1),
                          ("l_shoulder_ry", -47.2), ("l_elbow_flex", 21.6)):  # fmt: skip
        wrong[PARAM_INDEX[name]] = np.deg2rad(degrees)
    wrong = Pose(wrong)
    truth = MISMATCHED.joints(pose)
    wrist = NODE_NAMES.index("l_wrist")
    assert np.linalg.norm(start.joints(wrong)[wrist] - truth[wrist]) > 0.1
    model, ordinary = repair_limbs(start, wrong, points, FitConfig(), ("l_arm",))
    assert np.linalg.norm(model.joints(ordinary)[wrist] - truth[wrist]) > 0.05
    model, thorough = repair_limbs(start, wrong, points, FitConfig(), ("l_arm",), thorough=True)
    errors = np.linalg.norm(model.joints(thorough) - truth, axis=1)
    assert errors[wrist] < 0.015 and errors.mean() < 0.010, errors


@pytest.mark.slow
def test_the_second_look_refuses_points_off_the_body_that_no_limb_explains():
    """`second_look`: a right body passes it; the same body with 12 points (0.3% of the cloud,
    under the subset test's 1.5%) together 15 cm in front of the chest, which no limb
    search can explain, is refused rather than reported a success."""
    from tracking.fit.body_fit import acceptance, second_look

    pose = walking_poses(12, 30.0, MISMATCHED.shape, phase_deg=90.0)[8]
    points, _ = body_cloud(MISMATCHED, pose, np.random.default_rng(5))
    chest = MISMATCHED.joints(pose)[NODE_NAMES.index("spine")]
    front = MISMATCHED.posed_vertices(pose)[:, 2].max() - chest[2]
    blob = chest + [0.0, 0.1, front + 0.15] + np.random.default_rng(6).normal(0, 0.01, (12, 3))
    _, _, (ok, problems, _) = second_look(MISMATCHED, pose, points, points, FitConfig())
    assert ok, problems
    held = np.vstack([points, blob])
    assert acceptance(MISMATCHED, pose, held, FitConfig())[0]  # the subset's test passes it
    _, _, (ok, problems, _) = second_look(MISMATCHED, pose, held, held, FitConfig())
    assert not ok
    assert "after the limbs were searched again" in "; ".join(problems)


@pytest.mark.slow
@pytest.mark.shared_data
def test_arms_overhead_are_fitted_from_the_wide_arm_grid():
    """Cartwheel frame 115 (held-out), the cloud of `benchmarks/body_fit.py --clips held-out`:
    arms overhead, every fit of the standard arm grid refused (reported 217 mm off). The last
    fallback, the standing start with the wide grid (turned and overhead arms), accepts it
    (session 21: 3.3 mm, 297 s)."""
    _assert_fitted_within_30_mm("cmu_cartwheel.bvh", 115, seed=1016)


def test_the_wide_arm_grid_adds_turned_and_overhead_arms():
    from tracking.fit.body_fit import ArmGrid, _candidates

    standard, wide = _candidates("l_arm"), _candidates("l_arm", ArmGrid.WIDE)
    assert set(standard) < set(wide)
    assert all(c[2] == 0 and c[1] >= -90 for c in standard)
    assert any(c[1] <= -135 for c in wide) and any(c[2] != 0 for c in wide)
    assert _candidates("l_leg", ArmGrid.WIDE) == _candidates("l_leg")
