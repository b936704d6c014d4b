"""Silhouette tracking against synthetic sequences with known poses."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time

import numpy as np
import pytest

from recon.cameras import write_cameras_json
from tests.helpers import recording_entities, run_cli, shared_dataset
from tracking.body.bvh import read_bvh
from tracking.body.model import (
    N_POSE_PARAMS,
    NODE_INDEX,
    NODE_NAMES,
    PARAM_INDEX,
    BodyModel,
    BodyShape,
    Pose,
    forward_kinematics,
    node_positions_in_world,
    pose_in_frame,
    root_rotation,
)
from tracking.body.motion import is_body_skeleton, poses_from_motion
from tracking.rig.cameras import read_cameras, ring_cameras
from tracking.silhouettes.hull import hull_diameter
from tracking.track.render import CpuRasterRenderer
from tracking.track.tracker import (
    STATUSES,
    FrameResult,
    SilhouetteTracker,
    TrackConfig,
    crouched_starts,
    start_height,
    start_heights,
    upright_starts,
)

SHAPE = BodyShape.default(1.75)
MODEL = BodyModel(SHAPE)
CAMERAS = ring_cameras(4, 4.0, 1.5, (0.0, 0.9, 0.0), 320, 240, 343.0)
RENDER = CpuRasterRenderer(CpuRasterRenderer.Options())

SUPERQUADRIC = TrackConfig(body="superquadric")
"""The tracker of the superquadric model: these tests render and score that model."""


def _walk(frames: int) -> list[Pose]:
    """A slow synthetic step: arms and legs swing in opposition while the body moves +Z."""
    poses = []
    for k in range(frames):
        phase = 0.25 * k
        poses.append(Pose.from_dict({
            "root_ty": 0.95, "root_tz": 0.04 * k,
            "l_hip_rx": -0.3 * np.sin(phase), "r_hip_rx": 0.3 * np.sin(phase),
            "l_knee_flex": 0.2 + 0.2 * np.sin(phase), "r_knee_flex": 0.2 - 0.2 * np.sin(phase),
            "l_shoulder_rx": 0.25 * np.sin(phase), "r_shoulder_rx": -0.25 * np.sin(phase),
            "l_shoulder_rz": 0.15, "r_shoulder_rz": -0.15,
            "l_elbow_flex": 0.3, "r_elbow_flex": 0.3,
        }))  # fmt: skip
    return poses


def _masks(pose: Pose) -> list[np.ndarray]:
    vertices = MODEL.posed_vertices(pose)
    return [RENDER.render(vertices, MODEL.faces, cam) for cam in CAMERAS]


def _mpjpe_mm(pose: Pose, shape: BodyShape, truth: Pose) -> float:
    a, b = node_positions_in_world(pose, shape), node_positions_in_world(truth, SHAPE)
    return 1000 * float(np.mean([np.linalg.norm(a[n] - b[n]) for n in NODE_NAMES]))


# twist_weight 0 with no temporal prior (the default) once made the prior's centre 0/0 = NaN,
# and every frame was lost.
@pytest.mark.parametrize("twist_weight", [TrackConfig().twist_weight, 0.0])
def test_tracking_follows_a_walk_from_a_given_start(twist_weight):
    truth = _walk(4)
    config = dataclasses.replace(SUPERQUADRIC, twist_weight=twist_weight)
    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    errors = []
    for frame, pose in enumerate(truth):
        result = tracker.track(frame, _masks(pose), init=truth[0] if frame == 0 else None)
        assert result.pose is not None, result.event
        errors.append(_mpjpe_mm(result.pose, SHAPE, pose))
        assert result.xor_fraction < 0.1
    assert max(errors) < 30  # 1 px is ~12 mm at 4 m with f = 343 px


def test_a_subject_turning_through_180_degrees_is_followed_past_the_wrap():
    # A heading stored in -180..180 does not stop the body at 180: the suite's turn_pirouette
    # stuck there (frames 36-39 and 56 at -180.0) and diverged at 57 (session 45). Here the
    # walk turns 15 degrees a frame from 150, through 180, to 225.
    headings = np.radians(150.0 + 15.0 * np.arange(6))
    truth = [Pose.from_dict({**pose.as_dict(), "root_ry": heading})
             for pose, heading in zip(_walk(6), headings, strict=True)]
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE)
    for frame, pose in enumerate(truth):
        result = tracker.track(frame, _masks(pose), init=truth[0] if frame == 0 else None)
        assert result.pose is not None, result.event
        assert result.status == ("init" if frame == 0 else "tracked"), result.event
        assert _mpjpe_mm(result.pose, SHAPE, pose) < 10  # measured: 1.4-3.6 mm
        heading = result.pose.as_dict()["root_ry"]
        assert -np.pi <= heading < np.pi  # stored in its range: the same rotation
        # (the pelvis' heading trades a few degrees against the chest's twist: 4-6 measured)
        assert abs(np.degrees(heading - headings[frame] + np.pi) % 360 - 180) < 10


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
def test_the_chest_side_bend_and_twist_are_tracked_and_can_be_held():
    """A chest turning to 23 and bending to 11 degrees over the pelvis in 5 frames: the tracker
    follows both (issue 19's extra degrees of freedom); held (--hold), they stay 0 and the
    joints fall behind."""
    values = {"root_ty": 0.95, "l_shoulder_rz": 0.3, "r_shoulder_rz": -0.3,
              "l_elbow_flex": 0.4, "r_elbow_flex": 0.4, "spine_flex": 0.1}
    truth = [Pose.from_dict({**values, "spine_twist": 0.08 * k, "spine_bend": 0.04 * k})
             for k in range(6)]  # fmt: skip
    twist, bend = PARAM_INDEX["spine_twist"], PARAM_INDEX["spine_bend"]
    last = {}
    for hold in ((), ("spine_bend", "spine_twist")):
        tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, hold=hold),
                                    shape=SHAPE)  # fmt: skip
        for frame, pose in enumerate(truth):
            result = tracker.track(frame, _masks(pose), init=truth[0] if frame == 0 else None)
            assert result.pose is not None, result.event
        last[hold] = result.pose
    free, held = last[()], last[("spine_bend", "spine_twist")]
    assert abs(free.params[twist] - 0.4) < np.deg2rad(5)
    assert abs(free.params[bend] - 0.2) < np.deg2rad(5)
    assert held.params[twist] == 0.0 and held.params[bend] == 0.0
    assert _mpjpe_mm(free, SHAPE, truth[-1]) < 6 and _mpjpe_mm(held, SHAPE, truth[-1]) > 12


def test_refine_finds_the_pose_of_one_frame_from_a_wrong_start():
    # No time in the loop: an arm swung 35 degrees off and a 6 cm shift are found again (the
    # first pass leaves the elbow 8 cm off, the second finds it); the truth stays put.
    truth = _walk(3)[2]
    masks = _masks(truth)
    start = Pose(truth.params + np.where(
        np.arange(len(truth.params)) == 0, 0.06, 0.0)).as_dict()
    start["r_shoulder_rx"] += np.deg2rad(35)
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE)
    assert _mpjpe_mm(Pose.from_dict(start), SHAPE, truth) > 40
    assert _mpjpe_mm(tracker.refine(masks, Pose.from_dict(start)), SHAPE, truth) < 10
    assert _mpjpe_mm(tracker.refine(masks, truth, passes=1), SHAPE, truth) < 1
    # With the shape fitted to the frame too, from a subject 8% too tall: one frame takes
    # the height more than halfway back (measured: 1.80 m for 1.75 m).
    tall = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=BodyShape.default(1.89))
    refined = tall.refine(masks, truth, passes=1, shape=True)
    assert abs(tall.shape.height - SHAPE.height) < 0.5 * (1.89 - SHAPE.height)
    assert _mpjpe_mm(refined, tall.shape, truth) < 25
    with pytest.raises(ValueError, match="shape"):
        SilhouetteTracker(CAMERAS).refine(masks, truth)


def test_a_floor_shadow_under_feet_off_the_floor_does_not_stretch_the_body():
    """A subject 8 cm above the floor (a jump, or the suite's retargeted clips, whose feet
    float up to 8 cm) with a shadow on the floor that every view keeps: the shape refined with
    the pose from a subject 8% too tall. Counted, the shadow stretches the legs down to it
    (measured 1.834 m for 1.75, 13.5 mm); the hull's lowest band out of the XOR
    (`TrackConfig.floor_band_m`), 1.747 m and 7.4 mm."""
    from tests.tracking.silhouettes.test_hull import disc_masks

    truth = Pose.from_dict({**_walk(1)[0].as_dict(), "root_ty": 0.95 + 0.08})
    vertices = MODEL.posed_vertices(truth)
    sole = vertices[:, 1].min()
    feet = vertices[vertices[:, 1] < sole + 0.05].mean(axis=0)
    shadow = disc_masks(CAMERAS, np.array([feet[0] + 0.05, sole - 0.08, feet[2] + 0.05]),
                        0.2, 0.1)  # fmt: skip
    masks = [m | s for m, s in zip(_masks(truth), shadow, strict=True)]
    heights, errors = {}, {}
    for band in (0.0, TrackConfig().floor_band_m):
        tall = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, floor_band_m=band),
                                 shape=BodyShape.default(1.89))  # fmt: skip
        refined = tall.refine(masks, truth, passes=1, shape=True)
        heights[band], errors[band] = tall.shape.height, _mpjpe_mm(refined, tall.shape, truth)
    band = TrackConfig().floor_band_m
    assert abs(heights[band] - SHAPE.height) < 0.02 and errors[band] < 10
    assert heights[0.0] - SHAPE.height > 0.05 and errors[0.0] > errors[band] + 4


def test_a_start_bent_over_keeps_the_height_of_its_fit():
    """The hull of a body bent forward at the hips (about 70 degrees) is 1.29 m along up for a
    1.75 m subject: its fit, tilted, is capped by the hull's longest extent (1.49 m), and the
    start keeps its fit's height (measured 1.57 m, 47 mm), where the cap along up left 1.35 m
    and an upright start 246 mm off. A stride, upright, is capped along up: its diagonal is
    longer than the subject is tall. (The suite's cartwheel starts bent over: its figures are
    in the README; this is the mechanism, on the model's own renders.)"""
    bent = Pose.from_dict({"root_ty": 0.95, "root_rx": 1.2, "l_hip_rx": -1.2,
                           "r_hip_rx": -1.2})  # fmt: skip
    config = dataclasses.replace(SUPERQUADRIC, init_headings=2, init_extremity_starts=0,
                                 init_shape=False)  # fmt: skip
    tracker = SilhouetteTracker(CAMERAS, config)
    pose, _ = tracker.initialise(_masks(bent))
    assert tracker.shape.height > 1.5, tracker.shape.height
    assert _mpjpe_mm(pose, tracker.shape, bent) < 100

    up, voxel = np.array([0.0, 1.0, 0.0]), config.voxel_m
    stride = Pose.from_dict({"root_ty": 0.92, "l_hip_rx": -0.6, "r_hip_rx": 0.5,
                             "r_knee_flex": 0.4})  # fmt: skip
    points = tracker.visual_hull_points(_masks(stride))
    along_up, longest = float(np.ptp(points @ up)), hull_diameter(points)
    assert longest > along_up + 0.02, (longest, along_up)
    tall = BodyShape.default(2.0)
    assert start_height(stride, tall, points, up, voxel) == 1.05 * (along_up + voxel)
    bent_points = tracker.visual_hull_points(_masks(bent))
    assert start_height(bent, tall, bent_points, up, voxel) == pytest.approx(
        1.05 * (hull_diameter(bent_points) + voxel))
    short = BodyShape.default(1.4)
    assert start_height(bent, short, bent_points, up, voxel) == short.height  # the fit's
    assert start_height(bent, tall, bent_points, None, voxel) == tall.height  # no up known


def test_the_start_searched_at_two_heights_keeps_the_one_of_lower_xor(monkeypatch):
    """The hull fit's height is the fat hull's; upright, the start is searched at the hull's
    extent along up too (`start_heights`), and the lower XOR keeps its height. Here the two
    heights are the subject's (1.75 m) and one 12% taller, in either order: the subject's
    wins, its pose within 20 mm (measured 3 mm, 613 XOR pixels; the taller's alone ends 59
    mm off, 3901 px)."""
    import tracking.track.tracker as tracker_module

    truth = _walk(1)[0]
    config = dataclasses.replace(SUPERQUADRIC, init_headings=2, init_extremity_starts=0,
                                 init_shape=False)  # fmt: skip
    for heights in ([1.96, 1.75], [1.75, 1.96]):
        monkeypatch.setattr(tracker_module, "start_heights", lambda *_, h=heights: h)
        tracker = SilhouetteTracker(CAMERAS, config)
        pose, message = tracker.initialise(_masks(truth))
        assert tracker.shape.height == pytest.approx(1.75), (heights, message)
        assert "at 1.75 m" in message, message
        assert _mpjpe_mm(pose, tracker.shape, truth) < 20

    up, voxel = np.array([0.0, 1.0, 0.0]), config.voxel_m
    points = tracker.visual_hull_points(_masks(truth))
    along_up = float(np.ptp(points @ up)) + voxel
    tall, short = BodyShape.default(2.0), BodyShape.default(along_up + 0.5 * voxel)
    assert start_heights(truth, tall, points, up, voxel) == [
        pytest.approx(1.05 * along_up), pytest.approx(along_up)]
    assert start_heights(truth, short, points, up, voxel) == [short.height]  # within a voxel
    assert start_heights(truth, tall, points, None, voxel) == [tall.height]  # no up known
    bent = Pose.from_dict({"root_ty": 0.95, "root_rx": 1.2})  # the trunk 69 degrees off up
    assert len(start_heights(bent, tall, points, up, voxel)) == 1


def test_the_second_height_refines_the_first_heights_best_starts_alone(monkeypatch):
    # `_start_search` with `only`: those starts are refined as in the full search (the same
    # floats, the same winner among them); the others score infinity, and the fit's swaps
    # and the extremities' poses are not made when none of them is asked for.
    truth = _walk(1)[0]
    masks = _masks(truth)
    config = dataclasses.replace(SUPERQUADRIC, init_headings=4, init_extremity_starts=1,
                                 init_shape=False)  # fmt: skip
    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    points, up = tracker.visual_hull_points(masks), np.array([0.0, 1.0, 0.0])
    fit = Pose.from_dict({"root_ty": 0.95, "root_ry": 0.3})
    with tracker._searching_start():
        x, score, _, ranked, _ = tracker._start_search(masks, fit, points, up, False, False)
        assert sorted(ranked) == list(range(6))  # the fit, 4 upright, 1 from the extremities
        before = tracker.evaluations
        y, best, _, again, _ = tracker._start_search(masks, fit, points, up, False, False,
                                                  only=ranked[:2])  # fmt: skip
        np.testing.assert_array_equal(y, x)
        assert best == score and again[:2] == ranked[:2]
        assert 0 < tracker.evaluations - before < before / 2
        uprights = [i for i in ranked if 1 <= i <= 4][:2]
        for name in ("_best_hypothesis", "_extremity_starts"):
            monkeypatch.setattr(tracker, name, lambda *_: pytest.fail("made, not asked for"))
        y, best, start, again, _ = tracker._start_search(masks, fit, points, up, False, False,
                                                      only=uprights)  # fmt: skip
    # The two upright starts ranked as in the full search, the winner the better of them.
    assert again[:2] == uprights and "upright start" in start and np.isfinite(best), start
    assert best >= score


def test_the_starts_refined_side_by_side_are_those_refined_in_turn():
    # `TrackConfig.workers`: the start's candidates refined in forked processes give the
    # poses, the evaluation count and the priors of the refinement in this process.
    truth = _walk(3)[2]
    masks = _masks(truth)
    starts = [Pose(truth.params + np.where(np.arange(N_POSE_PARAMS) == i, 0.1, 0.0))
              for i in (0, PARAM_INDEX["l_shoulder_rx"], PARAM_INDEX["r_knee_flex"])]
    found = {}
    for workers in (1, 2):
        tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, workers=workers),
                                    shape=SHAPE)  # fmt: skip
        with tracker._searching_start():
            xs = tracker._refine_starts(tracker._energy(masks), starts)
        found[workers] = (np.array(xs), tracker.evaluations, tracker._prior)
    np.testing.assert_array_equal(found[1][0], found[2][0])
    assert found[1][1] == found[2][1] > 100
    for serial, forked in zip(found[1][2], found[2][2], strict=True):
        np.testing.assert_array_equal(serial, forked)
    assert _mpjpe_mm(Pose(found[2][0][1]), SHAPE, truth) < 10


def test_a_bent_arm_turned_on_its_axis_is_found_from_a_folded_start():
    """With the upper arm's axial twist sampled too (`init_twists` 3) and its best few
    samples refined (`init_starts` 3; neither is the default), the start's limb grid finds an
    arm held out with the elbow bent 40 degrees and turned 60 on its axis from the forearm
    folded on the chest (the CMU squat's start, 409 mm off, session 21). Sampled at the start's
    twist alone, with only the grid's best refined, the wrist stays 355 mm off."""
    base = {"root_ty": 0.95, "r_shoulder_rz": -0.2, "r_elbow_flex": 0.3}
    truth = Pose.from_dict({**base, **{name: np.deg2rad(value) for name, value in (
        ("l_shoulder_rz", 20), ("l_shoulder_rx", -30), ("l_shoulder_ry", 60),
        ("l_elbow_flex", 40))}})  # fmt: skip
    start = Pose.from_dict({**base, "l_shoulder_rz": 0.3, "l_elbow_flex": np.deg2rad(140)})
    masks = _masks(truth)

    def wrist_error_mm(config: TrackConfig) -> float:
        pose = SilhouetteTracker(CAMERAS, config, shape=SHAPE).refine(masks, start, passes=1)
        a, b = node_positions_in_world(pose, SHAPE), node_positions_in_world(truth, SHAPE)
        return 1000 * float(np.linalg.norm(a["l_wrist"] - b["l_wrist"]))

    assert wrist_error_mm(dataclasses.replace(SUPERQUADRIC, init_twists=3, init_starts=3)) < 15
    assert wrist_error_mm(dataclasses.replace(SUPERQUADRIC, init_twists=1, init_starts=1)) > 200


def test_upright_starts_stand_on_the_given_up_at_even_headings():
    up = np.array([0.0, 0.0, 1.0])  # a Z-up world
    fit = Pose.from_dict({"root_tx": 1.0, "root_ty": 2.0, "root_tz": 0.9, "root_rx": 1.4,
                          "root_ry": 0.3, "l_knee_flex": 1.0})  # fmt: skip
    starts = upright_starts(fit, up, 4, pelvis=np.array([1.0, 2.0, 0.95]))
    fit_forward = root_rotation(fit)[:, 2]
    headings = []
    for pose in starts:
        rotation = root_rotation(pose)
        assert np.allclose(rotation[:, 1], up)  # the body's Y is up: standing
        assert np.allclose(pose.params[:3], [1.0, 2.0, 0.95])
        assert pose.as_dict()["l_knee_flex"] == 0.0  # a neutral stance
        headings.append(np.arctan2(rotation[1, 2], rotation[0, 2]))
    # Even headings, the first one the fit's own (projected on the ground).
    assert np.isclose(headings[0], np.arctan2(fit_forward[1], fit_forward[0]))
    steps = np.diff(np.unwrap(headings))
    assert np.allclose(steps, np.pi / 2)
    assert upright_starts(fit, up, 0) == []


def test_crouched_starts_are_the_upright_ones_bent_over_on_the_fits_pelvis():
    """`crouched_starts`: the upright starts' headings, on the fit's pelvis, each pitched
    forward, its chest bent and its hips and knees flexed deep (`_CROUCH_DEG`); a squat: the
    knees in front of the pelvis and below it, the neck ahead of the pelvis."""
    up = np.array([0.0, 1.0, 0.0])
    fit = Pose.from_dict({"root_tx": 0.2, "root_ty": 0.6, "root_tz": -0.1, "root_ry": 0.7,
                          "spine_flex": 1.2})  # fmt: skip
    uprights, crouched = upright_starts(fit, up, 4), crouched_starts(fit, up, 4)
    assert len(crouched) == 4
    for standing, pose in zip(uprights, crouched, strict=True):
        assert np.allclose(pose.params[:3], fit.params[:3])
        ahead = root_rotation(standing)[:, 2]  # the heading of the upright start
        world = forward_kinematics(pose, SHAPE)[:, :3, 3]
        pelvis = world[NODE_INDEX["pelvis"]]
        for knee in ("l_knee", "r_knee"):
            assert (world[NODE_INDEX[knee]] - pelvis) @ ahead > 0.2
            assert (world[NODE_INDEX[knee]] - pelvis) @ up < 0.1
        assert (world[NODE_INDEX["neck"]] - pelvis) @ ahead > 0.2
        assert pose.as_dict()["l_knee_flex"] == pytest.approx(np.deg2rad(115.0))
    assert crouched_starts(fit, up, 0) == []


def test_crouched_bodies_compete_where_the_fit_is_bent_over_when_asked(monkeypatch):
    """``--init-crouched``: a fit that is not upright (`bent`) gets crouched starts at the
    upright starts' headings among the candidates, and one that wins is named so; without
    the option, or for an upright fit, none. (The refinements are skipped: the candidates
    are counted, and the one made to score lowest is named.)"""
    masks = _masks(_walk(1)[0])
    points, up = None, np.array([0.0, 1.0, 0.0])
    fit = Pose.from_dict({"root_ty": 0.95, "root_ry": 0.3})
    for crouched, bent, count in ((True, True, 1 + 4 + 4), (True, False, 1 + 4),
                                  (False, True, 1 + 4)):  # fmt: skip
        config = dataclasses.replace(SUPERQUADRIC, init_headings=4, init_extremity_starts=0,
                                     init_crouched=crouched)  # fmt: skip
        tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
        points = tracker.visual_hull_points(masks) if points is None else points
        made = []

        def unrefined(energy, starts, made=made):
            made.extend(starts)
            return [p.params.copy() for p in starts]

        monkeypatch.setattr(tracker, "_refine_starts", unrefined)
        monkeypatch.setattr(tracker, "_best_hypothesis", lambda energy, x: Pose(x))
        # The last candidate scores lowest: the crouched start at 270 degrees, if made.
        monkeypatch.setattr(tracker, "_objective", lambda energy, y, level, made=made: (
            0.0 if any(np.array_equal(y, p.params) for p in made[-1:]) else 1.0))
        with tracker._searching_start():
            _, _, start, ranked, _ = tracker._start_search(masks, fit, points, up, bent, False)
        assert len(ranked) == count, (crouched, bent, ranked)
        assert start == ("a crouched start at 270 deg from its fit" if count == 9
                         else "an upright start at 270 deg from its fit"), start


def test_visual_hull_contains_the_body():
    pose = _walk(1)[0]
    tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, voxel_m=0.03),
                                shape=SHAPE)
    hull = tracker.visual_hull_points(_masks(pose))
    body = MODEL.posed_vertices(pose)
    # The hull encloses the body: its box covers the body's box to within a voxel or two.
    assert np.all(hull.min(axis=0) <= body.min(axis=0) + 0.06)
    assert np.all(hull.max(axis=0) >= body.max(axis=0) - 0.06)
    assert np.ptp(hull[:, 1]) < np.ptp(body[:, 1]) + 0.15


@pytest.mark.parametrize(("view", "fill", "event"), [
    (2, np.zeros_like, "empty silhouette in cam02"),
    # A failed background model: every pixel foreground, so no outline to fit (issue 23).
    (1, np.ones_like, "every pixel foreground in cam01"),
])
def test_an_empty_or_full_silhouette_loses_the_frame_without_nan(view, fill, event):
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE)
    masks = _masks(_walk(1)[0])
    masks[view] = fill(masks[view])
    result = tracker.track(7, masks)
    assert result.pose is None and event in result.event


def test_silhouettes_that_are_all_unknown_lose_the_frame():
    """Every silhouette pixel lies where the background is unknown (a median that holds the
    subject in every camera): nothing to fit, and the frame is lost, not divided by zero."""
    masks = _masks(_walk(1)[0])
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE,
                                unknown=[m.copy() for m in masks])
    result = tracker.track(7, masks)
    assert result.pose is None and "every silhouette pixel is unknown" in result.event


# The rig as Qualisys and Pose2Sim calibrate it: a Z-up world. The tracker works in the rig's
# upright frame (Y up) and writes the joints back in the world frame.
WORLD_FROM_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _z_up_walk(tmp_path, frames: int):
    """A synthetic walk workspace (320x240) whose cameras are moved into a Z-up world."""
    clip = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    ws = tmp_path / "walk"
    made = run_cli("synth", ws, "--bvh", clip, "--frames", str(frames), "--size", "320x240",
                   "--clean")  # fmt: skip
    assert made.returncode == 0, made.stderr
    write_cameras_json(ws / "cameras.json", [c.in_frame(WORLD_FROM_YUP.T)
                                             for c in read_cameras(ws / "cameras.json")])
    return ws


def _joint_errors(ws, world_from_truth=WORLD_FROM_YUP) -> tuple[list[dict], list[float]]:
    """tracks/joints.csv's rows and their distances (m) to the truth (gt/joints.csv, turned
    by `world_from_truth`: by default into the Z-up world)."""
    with (ws / "tracks" / "joints.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    with (ws / "gt" / "joints.csv").open() as handle:
        truth = {(r["frame"], r["joint"]): world_from_truth @ [float(r[k]) for k in "xyz"]
                 for r in csv.DictReader(handle)}  # fmt: skip
    return rows, [float(np.linalg.norm(np.array([float(r[k]) for k in "xyz"])
                                       - truth[r["frame"], r["joint"]])) for r in rows]


@pytest.mark.slow  # its path is covered faster elsewhere (make test's 10-minute budget)
@pytest.mark.shared_data
def test_cli_synth_then_track_writes_every_output(tmp_path):
    ws = _z_up_walk(tmp_path, 3)
    result = run_cli("track", ws)
    assert result.returncode == 0, result.stderr
    rows, errors = _joint_errors(ws)
    assert list(rows[0]) == ["frame", "joint", "x", "y", "z"] and len(rows) == 3 * 16
    # Automatic start (visual hull, limb hypotheses, shape from the outlines of the 3 frames)
    # at 320x240: measured 18 mm; swapped legs are ~100 mm, a flipped or lost body 300 mm.
    assert np.mean(errors) < 0.04
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert [f["frame"] for f in pose["frames"]] == [0, 1, 2]
    assert all(len(f["params"]) == N_POSE_PARAMS for f in pose["frames"])
    # The first frame says how it was started: from the silhouettes, not from a given pose.
    assert pose["frames"][0]["event"].startswith("init from visual hull")
    assert "segment lengths from the first frames" in pose["frames"][0]["event"]
    assert np.allclose(pose["world_from_upright"], WORLD_FROM_YUP, atol=1e-9)
    motion = read_bvh(ws / "tracks" / "motion.bvh")
    assert is_body_skeleton(motion) and motion.num_frames == 3
    poses, _ = poses_from_motion(motion)
    np.testing.assert_allclose(poses[2].params, pose["frames"][2]["params"], atol=1e-6)
    entities = recording_entities(ws / "logs" / "track.rrd")
    assert any("/xor@SegmentationImage" in e for e in entities)
    assert any(e.startswith("/world/body/skeleton@Points3D:keypoint_ids") for e in entities)
    assert any(e.startswith("/world/body/mesh@Mesh3D") for e in entities)
    again = run_cli("track", ws)
    assert again.returncode == 0 and "up to date" in again.stdout
    # The tracked sequence is what the motion report reads; 3 frames are too few to filter,
    # which it says in one line (the full report is tested in test_report.py).
    report = run_cli("report", ws)
    assert report.returncode == 2 and "too short" in report.stderr
    assert report.stderr.strip().count("\n") == 0


def _frame_errors_mm(ws) -> dict[int, float]:
    """Per frame, the mean distance (mm) of tracks/joints.csv's joints to gt/joints.csv's
    (`_joint_errors` in the workspace's own world)."""
    rows, errors = _joint_errors(ws, np.eye(3))
    frames = [int(r["frame"]) for r in rows]
    return {f: 1000 * float(np.mean([e for g, e in zip(frames, errors, strict=True) if g == f]))
            for f in sorted(set(frames))}  # fmt: skip


def _suite_clip_from_150(root, clip: str):
    """The motion suite's `clip` from clip frame 150 (`tracking_suite.py --start 150`): its 60
    frames synthesised by `mocap synth` into root/clip (they set the ring of cameras)."""
    return _suite_clip(root, clip, "--first-frame", "150")


def _suite_clip(root, clip: str, *flags):
    """The motion suite's `clip` (`tracking_suite.py`, seed 0): its 60 frames synthesised by
    `mocap synth` into root/clip with `flags`."""
    ws = root / clip
    made = run_cli("synth", ws, "--bvh", shared_dataset("mocap_bvh") / f"cmu_{clip}.bvh",
                   "--frames", "60", *flags)  # fmt: skip
    assert made.returncode == 0, made.stderr
    return ws

@pytest.mark.slow  # a start search at 640x480: about 40 s
@pytest.mark.shared_data
def test_an_extremity_start_lower_without_the_lead_wins_by_it_with_the_proportions(tmp_path):
    """The motion suite's cartwheel at 24 fps (`tracking_suite.py --fps 25`: 50 frames, which
    set the ring of cameras): at frame 0 an upright start won at 13125 XOR px against an
    extremity start's 11510, without its lead (0.8), and ended 73 mm off at 23.6% XOR with its
    proportions, the extremity start 15 mm at 14.5% (session 47). With both given their
    proportions, the extremity start wins by the lead."""
    ws = _suite_clip(tmp_path, "cartwheel", "--fps", "25", "--frames", "50")
    result = run_cli("track", ws, "--last", "0")
    assert result.returncode == 0, result.stderr
    event = json.loads((ws / "tracks" / "pose.json").read_text())["frames"][0]["event"]
    assert "from its extremities" in event and "with its proportions under 0.8 times" in event, (
        event)
    assert _frame_errors_mm(ws)[0] < 30


@pytest.mark.slow  # two tracks of 24 frames at 640x480: 100 s
@pytest.mark.shared_data
def test_a_start_gone_wrong_is_tracked_back_from_the_frames_after_it(tmp_path):
    """The motion suite's boxing from clip frame 150 (`tracking_suite.py --start 150`): the
    automatic start holds both arms in a guard in front of the chest, 220-390 mm off, and the
    track finds them a few frames later. Tracked back from there, the first frames are right;
    with --back-xor-factor 0 they are not."""
    ws = _suite_clip_from_150(tmp_path, "boxing")
    # The suite's 60 frames (they set the ring of cameras), the first 24 tracked.
    off = run_cli("track", ws, "--last", "23", "--back-xor-factor", "0")
    assert off.returncode == 0, off.stderr
    assert np.mean([_frame_errors_mm(ws)[f] for f in range(4)]) > 60
    result = run_cli("track", ws, "--last", "23", "--overwrite")
    assert result.returncode == 0, result.stderr
    errors = _frame_errors_mm(ws)
    assert max(errors[f] for f in range(4)) < 30, errors
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert "tracked back" in pose["frames"][0]["event"]


@pytest.mark.slow  # three starts, a shape pass and a track of 30 frames at 640x480: ~100 s
@pytest.mark.shared_data
def test_a_shape_pass_moves_past_starts_over_the_bar_and_tracks_back_to_frame_0(tmp_path):
    """The motion suite's cartwheel from clip frame 150: at frame 0 the subject is bent
    sideways and the start search finds a 1.8 m body at 44% XOR, 236 mm off; a shape pass from
    there made the subject 1.73-1.77 m for 1.56 (session 45). The search at frame 3 is over
    the absolute bar too, the one at 6 under it: the pass runs from 6, and its pose there is
    tracked back to frame 0 with the shape it found. Frame 0 is then "init", under 30 mm
    (measured 5.0; before, "diverged" at 236), and so is every frame of the 30 (measured
    at most 11)."""
    ws = _suite_clip_from_150(tmp_path, "cartwheel")
    result = run_cli("track", ws, "--last", "29")
    assert result.returncode == 0, result.stderr
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    event = pose["frames"][0]["event"]
    assert pose["frames"][0]["status"] == "init" and pose["diverged"] == [], event
    assert ("at frame 6; segment lengths from the frames from there: the start search at "
            "frame(s) 0 (XOR" in event and "tracked back to frame 0" in event), event
    errors = _frame_errors_mm(ws)
    assert errors[0] < 30 and max(errors.values()) < 30, errors
    assert abs(pose["shape"]["height"] - 1.56) < 0.04, pose["shape"]["height"]


@pytest.mark.slow  # four starts, two shape passes and a track of 48 frames at 640x480: ~150 s
@pytest.mark.shared_data
def test_a_shape_pass_gone_wrong_under_the_bar_runs_again_from_a_start_at_its_end(tmp_path):
    """The motion suite's bend_pickup from clip frame 150: the start at frame 0 is under the
    absolute bar (27% XOR) but 103 mm off, 1.40 m tall for the 1.56 m subject, and the shape
    pass tracked on from it at 26-35% XOR, 100-130 mm (the clip 44.3 mm, its subject 1.45 m;
    session 46). A start searched afresh at the pass's last frame (20) reaches 12%: the pass
    runs again from there, and frame 0 is tracked back to. Every frame then under 30 mm
    (measured at most 16 over 60 frames)."""
    ws = _suite_clip_from_150(tmp_path, "bend_pickup")
    result = run_cli("track", ws, "--last", "47")
    assert result.returncode == 0, result.stderr
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    event = pose["frames"][0]["event"]
    assert ("at frame 20 (XOR" in event and "the shape pass from frame 0 had reached XOR"
            in event and "tracked back to frame 0" in event), event
    errors = _frame_errors_mm(ws)
    assert max(errors.values()) < 30, errors
    assert abs(pose["shape"]["height"] - 1.56) < 0.04, pose["shape"]["height"]


@pytest.mark.slow  # a track of 39 frames at 640x480: about 90 s
@pytest.mark.shared_data
def test_the_cartwheels_divergence_is_tracked_back_from_its_recovery(tmp_path):
    """The motion suite's cartwheel (`tracking_suite.py`, seed 0): forwards, the track
    diverges at frame 37 and is back under the bar of before it at 38, its visual hull
    explained ("recovered"). Tracked back from 38, the frames from 28 on replace it: each
    under 30 mm (measured 10.7-15.5), none diverged. With two workers (`make test` sets one),
    the track backs run beside the track (`recon.parallel.Beside`), and the frames they may
    replace wait for them: the recording holds each frame once, in order, with its final
    status. (Until session 45 this was the cartwheel from clip frame 150, whose start was
    right by luck: `tracking_suite.py`'s session-45 paragraph.)"""
    from tests.helpers import read_recording

    ws = _suite_clip(tmp_path, "cartwheel")
    result = run_cli("track", ws, "--last", "38", "--workers", "2")
    assert result.returncode == 0, result.stderr
    errors = _frame_errors_mm(ws)
    assert max(errors[f] for f in range(28, 39)) < 30, errors
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert pose["diverged"] == [] and pose["recovered"] == [38], pose["recovered"]
    assert "the track back from frame 38 over the diverged frames from 37 starts here" in [
        f["event"] for f in pose["frames"]]
    summary = json.loads((ws / "run.json").read_text())["steps"]["track"]["summary"]
    assert summary["track_back_seconds"] > 0  # apart from the frames' own, forward
    read = read_recording(ws / "logs" / "track.rrd")
    assert read.rows("track/status_index", "frame") == list(range(39))
    assert read.rows("track/status_index", "Scalars:scalars")[37] == [STATUSES.index("tracked")]


@pytest.mark.shared_data
def test_cli_track_from_a_given_pose_in_another_frame(tmp_path):
    """--init-pose FILE: a pose file in the world frame of a Z-up rig (world_from_upright the
    identity) is re-expressed in the tracker's upright frame; tracked from the true start, the
    joints stay on the truth. Read as if it were upright, it would start lying on its side."""
    ws = _z_up_walk(tmp_path, 2)
    truth = json.loads((ws / "gt" / "pose.json").read_text())
    for entry in truth["frames"]:
        entry["params"] = pose_in_frame(Pose(entry["params"]), WORLD_FROM_YUP).params.tolist()
    given = tmp_path / "start.json"
    given.write_text(json.dumps(truth))  # no world_from_upright: the world frame
    result = run_cli("track", ws, "--init-pose", given, "--meshes")
    assert result.returncode == 0, result.stderr
    tracked = json.loads((ws / "tracks" / "pose.json").read_text())
    assert np.allclose(tracked["world_from_upright"], WORLD_FROM_YUP, atol=1e-9)
    rows, errors = _joint_errors(ws)
    assert len(rows) == 2 * 16 and np.mean(errors) < 0.03
    # --meshes: the full mesh of each frame in the rig's Z-up world, around its joints.
    import open3d as o3d

    assert sorted(p.name for p in (ws / "tracks" / "meshes").iterdir()) == [
        "000000.ply", "000001.ply"]
    mesh = o3d.io.read_triangle_mesh(str(ws / "tracks" / "meshes" / "000001.ply"))
    vertices = np.asarray(mesh.vertices)
    assert len(vertices) == 13380 and mesh.has_vertex_normals()
    assert np.ptp(vertices[:, 2]) > 1.3 > np.ptp(vertices[:, 1])  # standing along Z
    joints = np.array([[float(r[a]) for a in "xyz"] for r in rows if r["frame"] == "1"])
    assert np.linalg.norm(vertices.mean(axis=0) - joints.mean(axis=0)) < 0.15


def _pass_stand_ins(monkeypatch, tracker, track, refined, masks=False):
    """`calibrate_shape`'s stand-ins: `track` for the tracker's, a shape refinement that notes
    in `refined` the first parameter of each pose it refines (its masks with `masks`) and
    leaves them, no energy and no refinement."""
    def refine_shape(sequence, poses):
        refined.extend(sequence if masks else [int(p.params[0]) for p in poses])
        return poses

    monkeypatch.setattr(tracker, "track", track)
    monkeypatch.setattr(tracker, "_refine_shape", refine_shape)
    monkeypatch.setattr(tracker, "_energy", lambda masks: None)
    monkeypatch.setattr(tracker, "_refine_all", lambda energy, x, init=False: x)


def test_the_shape_pass_tracks_no_frame_after_its_last_refined_one(monkeypatch):
    """`calibrate_shape` over 10 frames with a stride of 4 refines the shape with frames 0, 4
    and 8: it tracks frames 0-8 and not 9, which tell the shape nothing, and its progress
    still counts all 10. (Its tracking, refinements and energy are stand-ins here: what is
    checked is which frames it tracks and refines.)"""
    tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, shape_stride=4))
    tracked, refined, progress = [], [], []

    def track(frame, masks, init=None):
        tracked.append(frame)
        return FrameResult(frame, Pose(np.full(N_POSE_PARAMS, float(frame))), 0.0, 1.0, 0, 0.0,
                           "init" if frame == 0 else "", "init" if frame == 0 else "tracked")

    _pass_stand_ins(monkeypatch, tracker, track, refined, masks=True)
    first = tracker.calibrate_shape([[i] for i in range(10)], progress=lambda: progress.append(1))
    assert tracked == list(range(9)) and len(progress) == 10
    assert refined == [[0], [4], [8]] and tracker.shape_frames_used == [0, 4, 8]
    assert (first.params == 0).all()



def _shape_pass(monkeypatch, tracker, statuses, frames):
    """`calibrate_shape` over `frames` with stand-ins (`test_the_shape_pass_tracks_no_frame_
    after_its_last_refined_one`'s) whose frame i has status statuses[i] and a pose whose
    parameters are all 10 + i; "unexplained" is "tracked", flagged."""
    def track(index, masks, init=None):
        status = statuses[index]
        return FrameResult(index, Pose(np.full(N_POSE_PARAMS, 10.0 + index)), 0.0, 1.0, 0, 0.0,
                           "", "tracked" if status == "unexplained" else status,
                           unexplained=status == "unexplained")  # fmt: skip

    _pass_stand_ins(monkeypatch, tracker, track, [])
    monkeypatch.setattr(tracker, "track_back", lambda results, masks_of: {})
    tracker.calibrate_shape([[i] for i in range(len(statuses))], frames=frames)


def test_a_recovery_in_the_shape_pass_frames_starts_from_the_pose_it_gave_them(monkeypatch):
    """The shape pass over frames 100-105 (by number) gives frames 100, 101, 103 and 105
    poses it trusts; 102 diverged and 104 is flagged unexplained. A recovery at 103 tries
    the pass's pose (refined like the last good pose) after the last good pose: enough
    there (no divergence), the hull's search does not run. At 102 and 104, and at 103 when
    that pose is no better, the hull's search runs; the lowest XOR wins. (The energy here is
    a pose's first parameter.)"""
    tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, shape_stride=1))
    _shape_pass(monkeypatch, tracker, ["init", "tracked", "diverged", "recovered",
                                       "unexplained", "tracked"], frames=range(100, 106))
    hull = []

    def initialise(masks, init=None, enough=None):
        hull.append(masks)
        return Pose(np.full(N_POSE_PARAMS, 8.0)), "init from visual hull"

    monkeypatch.setattr(tracker, "_best_hypothesis", lambda energy, x: Pose(x))
    monkeypatch.setattr(tracker, "initialise", initialise)
    tracker._last_good = (99, np.full(N_POSE_PARAMS, 20.0))
    energy = lambda pose, level=0: float(pose.params[0])  # noqa: E731

    def recover(frame, bar):
        hull.clear()
        x, e, found = tracker._recover(frame, [frame], energy, np.full(N_POSE_PARAMS, 30.0),
                                       30.0, enough=lambda value: value <= bar)  # fmt: skip
        return e, found, len(hull)

    assert recover(103, bar=15) == (13, "the shape pass's pose", 0)
    assert recover(103, bar=5) == (8, "the visual hull", 1)
    assert recover(102, bar=15) == (8, "the visual hull", 1)
    assert recover(104, bar=15) == (8, "the visual hull", 1)
    assert recover(105, bar=25) == (20, "the last good pose (frame 99)", 0)

def _opening(energies, tracker, backwards, seen):
    """Stand-ins for `track_back`'s test: the forward results of `energies` (XOR pixels of
    a silhouette of 100; each pose's parameters all its frame's number), and `tracker.track`
    tracking frame f backwards at energy backwards[f] (pose parameters 100 + f), noting in
    `seen` the frame, the prediction's history and whether the divergence watch was off."""
    results = [FrameResult(f, Pose(np.full(N_POSE_PARAMS, float(f))), e, 100.0, 0, 0.0,
                           "init from its fit" if f == 0 else "",
                           "init" if f == 0 else "tracked")
               for f, e in enumerate(energies)]  # fmt: skip

    def track(frame, masks, init=None):
        seen.append((frame, [int(x[0]) for x in tracker.history], tracker._backwards))
        tracker.history = [*tracker.history[-1:], np.full(N_POSE_PARAMS, 100.0 + frame)]
        return FrameResult(frame, Pose(np.full(N_POSE_PARAMS, 100.0 + frame)),
                           backwards[frame], 100.0, 0, 0.0, "", "tracked")  # fmt: skip

    tracker.track = track
    return results


def test_a_wrong_opening_is_tracked_back_from_its_frame_of_lowest_xor():
    """The first frame at 30% XOR, the lowest 10% at frame 5: frames 4 to 0 are tracked again
    backwards from frame 5 (the prediction from frames 6 and 5), and each of them replaces the
    forward one, whose summed energies are higher. The first keeps its status "init" and
    says so; the watch is off while tracking back, and on again after."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _opening([30, 28, 26, 20, 12, 10, 11, 12, 12, 12], tracker,
                       {4: 12, 3: 11, 2: 11, 1: 10, 0: 11}, seen)
    back = tracker.track_back(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [4, 3, 2, 1, 0]
    assert seen[0][1] == [6, 5] and all(s[2] for s in seen) and not tracker._backwards
    assert sorted(back) == [0, 1, 2, 3, 4]
    assert all(back[f].pose.params[0] == 100 + f for f in back)
    assert back[0].status == "init" and back[1].status == "tracked"
    assert back[0].event == "init from its fit; tracked back from frame 5"


def test_a_track_back_worse_before_some_frame_joins_the_forward_one_there():
    """Backwards, frames 4 and 3 are lower than forwards but 2 to 0 far higher: the forward
    track holds frames 0-2 and the backward one 3-4 (the lowest summed energy), and frame 3
    says the two meet there."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _opening([30, 28, 26, 20, 12, 10, 11], tracker,
                       {4: 11, 3: 10, 2: 40, 1: 40, 0: 40}, seen)
    back = tracker.track_back(results, lambda frame: [frame])
    assert sorted(back) == [3, 4]
    assert back[3].event == "the track back from frame 5 starts here" and back[4].event == ""


def test_a_track_back_higher_everywhere_replaces_nothing():
    """Backwards, every frame is higher than forwards: nothing is replaced (the forward track
    from the first frame to the anchor is the lowest sum)."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _opening([30, 28, 26, 20, 12, 10, 11], tracker,
                       {4: 13, 3: 21, 2: 27, 1: 29, 0: 31}, seen)
    assert tracker.track_back(results, lambda frame: [frame]) == {} and len(seen) == 5


def test_a_track_back_hardly_lower_replaces_nothing():
    """Backwards, the frames are lower, but by 3.4% summed (112 XOR pixels against 116), under
    `_BACK_GAIN`: two tracks of a right start differ that much by the silhouettes' noise, and
    the forward one stays."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _opening([30, 28, 26, 20, 12, 10, 11], tracker,
                       {4: 12, 3: 19, 2: 25, 1: 27, 0: 29}, seen)
    assert tracker.track_back(results, lambda frame: [frame]) == {} and len(seen) == 5


@pytest.mark.parametrize("factor", [0.0, 3.5])
def test_no_track_back_when_off_or_the_first_frame_is_near_the_lowest(factor):
    """--back-xor-factor 0 is off; 3.5: the first frame's 30% is under 3.5 times the lowest
    10%, and the opening is kept as it is, nothing tracked again."""
    config = dataclasses.replace(SUPERQUADRIC, back_xor_factor=factor)
    tracker, seen = SilhouetteTracker(CAMERAS, config), []
    results = _opening([30, 28, 26, 20, 12, 10, 11], tracker, {}, seen)
    assert tracker.track_back(results, lambda frame: [frame]) == {} and seen == []


def _gap(statuses, energies, tracker, backwards, seen):
    """`_opening`'s stand-ins for `track_back_gap`: the forward results of `statuses` and
    `energies` (a frame of energy None has no pose), the last one recovered."""
    results = _opening([e if e is not None else 50 for e in energies], tracker, backwards, seen)
    return [dataclasses.replace(r, status=s, **({} if e is not None else
                                                {"pose": None, "energy": float("nan")}))
            for r, s, e in zip(results, statuses, energies, strict=True)]  # fmt: skip


GAP = ["init", "tracked", "tracked", "tracked", "tracked", "diverged", "tracked", "tracked",
       "recovered", "tracked"]
"""A divergence at frame 5, recovered at frame 8 (the results end with frame 8 but for the
last test: a frame 9 after the recovery)."""


def test_a_divergence_is_tracked_back_from_the_frame_that_recovers_from_it():
    """Diverged at frame 5 (30% XOR), 6 and 7 high, recovered at 8: frames 7 to 5 are tracked
    again backwards from 8 (the prediction from 8 alone: no frame after it yet), lower, and
    replace the forward ones; frame 4's backward track is no lower than its forward one (the
    two tracks have met) and ends the track back. Frame 5 is then "recovered", by the track
    back; frame 8 keeps its status."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _gap(GAP[:9], [10, 10, 11, 12, 13, 30, 31, 29, 12], tracker,
                   {7: 12, 6: 12, 5: 12, 4: 13}, seen)
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [7, 6, 5, 4] and seen[0][1] == [8]
    assert all(s[2] for s in seen) and not tracker._backwards
    assert sorted(back) == [5, 6, 7] and all(back[f].pose.params[0] == 100 + f for f in back)
    assert back[5].status == "recovered" and back[6].status == "tracked"
    assert back[5].event == ("recovered by the track back from frame 8 over the diverged "
                             "frames from 5")


def test_a_track_back_from_a_recovery_goes_on_before_the_divergence_while_lower():
    """The forward track slid before its divergence at frame 5 (frames 2-4 high but under the
    bars): backwards, they are lower too, and the track back replaces them, from frame 2
    (frame 1: no lower, the two tracks met). No frame of the divergence is left: frame 2 is
    "tracked", and says where the track back starts."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _gap(GAP[:9], [10, 10, 20, 22, 25, 30, 31, 29, 12], tracker,
                   {7: 12, 6: 12, 5: 12, 4: 12, 3: 11, 2: 11, 1: 10}, seen)
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [7, 6, 5, 4, 3, 2, 1] and sorted(back) == [2, 3, 4, 5, 6, 7]
    assert back[2].status == "tracked" and back[5].status == "tracked"
    assert back[2].event == ("the track back from frame 8 over the diverged frames from 5 "
                             "starts here")


def test_a_track_back_from_a_recovery_gives_lost_frames_a_pose():
    """Frames 5 and 6 lost (no pose), 7 recovered after them, as the start search found
    nothing under the bar there: tracked back from 7 under the bar, they get poses, and 5 is
    "recovered"."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    statuses = ["init", "tracked", "tracked", "tracked", "tracked", "lost", "lost", "recovered"]
    results = _gap(statuses, [10, 10, 11, 12, 13, None, None, 12], tracker,
                   {6: 14, 5: 14, 4: 14}, seen)
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert sorted(back) == [5, 6] and back[5].status == "recovered"
    assert back[5].event.endswith("over the lost frames from 5")


@pytest.mark.parametrize("wrong", [{"status": "diverged"}, {"unexplained": True}])
def test_a_track_back_from_a_recovery_ends_where_it_goes_wrong_itself(wrong):
    """Backwards, frame 6 is over the bars (a divergence: no search while tracking back), or
    leaves a part of the visual hull out where the forward frame did not, and the track back
    ends there: frame 7 alone is replaced, and says the recovery starts there."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    results = _gap(GAP[:9], [10, 10, 11, 12, 13, 30, 31, 29, 12], tracker,
                   {7: 12, 6: 12, 5: 12}, seen)
    track = tracker.track

    def diverging(frame, masks, init=None):
        result = track(frame, masks, init)
        return dataclasses.replace(result, **wrong) if frame == 6 else result

    tracker.track = diverging
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [7, 6] and sorted(back) == [7]
    assert back[7].status == "recovered"


def test_a_track_back_from_a_recovery_reaches_back_frames_only():
    """A divergence further back than `back_frames` (3 here): the track back from frame 8
    replaces frames 7 and 6 alone (the divergence's later frames: a divergence stays open
    while no frame recovers from it), and 6 is "recovered", naming frame 5."""
    tracker, seen = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC,
                                                                   shape_frames=3)), []
    results = _gap(GAP[:9], [10, 10, 11, 12, 13, 30, 31, 29, 12], tracker,
                   {7: 12, 6: 12, 5: 12}, seen)
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [7, 6] and sorted(back) == [6, 7]
    assert back[6].status == "recovered" and back[6].event.endswith("diverged frames from 5")


def test_a_recovery_without_diverged_frames_before_it_tracks_back_while_lower():
    """A divergence the start search recovered from at once (frame 8 "recovered", no diverged
    frame before it) after a slide (frames 5-7 high): tracked back from 8 while lower, frames
    7 to 5 are replaced, and frame 4 (no lower) ends the track back. Frame 5 is "tracked", and
    says where the track back starts; a divergence behind a recovery (frame 3's) is not
    reached."""
    tracker, seen = SilhouetteTracker(CAMERAS, SUPERQUADRIC), []
    statuses = ["init", "tracked", "diverged", "recovered", "tracked", "tracked", "tracked",
                "tracked", "recovered"]
    results = _gap(statuses, [10, 10, 30, 11, 13, 20, 22, 25, 12], tracker,
                   {7: 12, 6: 12, 5: 12, 4: 14}, seen)
    back = tracker.track_back_gap(results, lambda frame: [frame])
    assert [s[0] for s in seen] == [7, 6, 5, 4] and sorted(back) == [5, 6, 7]
    assert back[5].status == "tracked"
    assert back[5].event == "the track back from frame 8 starts here"


@pytest.mark.parametrize("case", ["off", "not recovered", "unexplained"])
def test_no_track_back_from_a_recovery_when_off_after_it_or_not_trusted(case):
    """Nothing is tracked back: off (--back-xor-factor 0); the last frame not a recovery (a
    frame after it); a recovered pose that leaves a part of the visual hull out."""
    config = (dataclasses.replace(SUPERQUADRIC, back_xor_factor=0.0) if case == "off"
              else SUPERQUADRIC)  # fmt: skip
    tracker, seen = SilhouetteTracker(CAMERAS, config), []
    statuses = GAP if case == "not recovered" else GAP[:9]
    energies = [10, 10, 11, 12, 13, 30, 31, 29, 12, 12][:len(statuses)]
    results = _gap(statuses, energies, tracker, {}, seen)
    if case == "unexplained":
        results[8] = dataclasses.replace(results[8], unexplained=True)
    assert tracker.track_back_gap(results, lambda frame: [frame]) == {} and seen == []


def test_the_shape_pass_refines_the_shape_on_the_poses_tracked_back(monkeypatch):
    """A shape pass whose first frame is far above its lowest XOR: the segment lengths are
    refined on the poses of the frames tracked back (0 and 4 of frames 0-8, stride 4), and
    its start says how many were."""
    tracker = SilhouetteTracker(CAMERAS, dataclasses.replace(SUPERQUADRIC, shape_stride=4))
    forward = [34, 30, 20, 15, 12, 11, 10, 11, 12]  # (the first under the absolute bar)
    refined = []

    def track(frame, masks, init=None):
        if tracker._backwards:
            return FrameResult(frame, Pose(np.full(N_POSE_PARAMS, 100.0 + frame)), 10.0, 100.0,
                               0, 0.0, "", "tracked")  # fmt: skip
        return FrameResult(frame, Pose(np.full(N_POSE_PARAMS, float(frame))), forward[frame],
                           100.0, 0, 0.0, "init" if frame == 0 else "",
                           "init" if frame == 0 else "tracked")  # fmt: skip

    _pass_stand_ins(monkeypatch, tracker, track, refined)
    first = tracker.calibrate_shape([[i] for i in range(9)])
    assert refined == [100, 104, 8] and first.params[0] == 100
    assert tracker._start_event.endswith("the first 6 tracked back")


def _pass_over_the_bar(monkeypatch, start_xor, back_statuses=None, tracked_xor=10.0,
                       pause_s=0.0, lost_from=None, **settings):
    """`calibrate_shape` over 30 frames (`shape_frames` 12, stride 2) with stand-ins: a start
    (the tracker's history empty) at frame f has XOR start_xor.get(f, 50%) (of a silhouette of
    100, a pose whose parameters are all f), a tracked frame f `tracked_xor` (parameters f),
    and a frame
    tracked backwards status back_statuses.get(f, "tracked") (parameters 100 + f). Returns
    the tracker, its pose, the frames it tracked ((frame, "start"/"track"/"back")), the
    poses the shape was refined on (their first parameter) and the progress counted. A start
    searched in another process (the second opinion beside the pass, `workers` 2) takes
    `pause_s` (so that the pass ends first), and is not in the frames tracked. A frame tracked
    from `lost_from` on is lost."""
    parent = os.getpid()
    config = dataclasses.replace(SUPERQUADRIC, shape_frames=12, shape_stride=2, **settings)
    tracker, tracked, refined, progress = SilhouetteTracker(CAMERAS, config), [], [], []
    back_statuses = back_statuses or {}

    def track(frame, masks, init=None):
        x = np.full(N_POSE_PARAMS, float(frame))
        if tracker._backwards:
            tracked.append((frame, "back"))
            status = back_statuses.get(frame, "tracked")
            return FrameResult(frame, Pose(x + 100.0), 10.0, 100.0, 0, 0.0,
                               "diverged: stand-in" if status == "diverged" else "", status)
        kind = "track" if tracker.history else "start"
        if os.getpid() != parent:
            time.sleep(pause_s)
        tracked.append((frame, kind))
        if kind == "track" and lost_from is not None and frame >= lost_from:
            return FrameResult(frame, None, 100.0, 100.0, 0, 0.0, "lost: stand-in", "lost")
        tracker.history = [*tracker.history[-1:], x]
        if kind == "start":
            return FrameResult(frame, Pose(x), start_xor.get(frame, 50.0), 100.0, 0, 0.0,
                               "init from stand-in", "init")  # fmt: skip
        return FrameResult(frame, Pose(x), tracked_xor, 100.0, 0, 0.0, "", "tracked")

    _pass_stand_ins(monkeypatch, tracker, track, refined)
    monkeypatch.setattr(tracker, "track_back", lambda results, masks_of: {})
    first = tracker.calibrate_shape([[i] for i in range(30)], frames=range(100, 130),
                                    progress=lambda: progress.append(1))
    return tracker, first, tracked, refined, len(progress)


def test_a_shape_pass_whose_start_is_over_the_bar_starts_where_one_is_under_it(monkeypatch):
    """The start at frame 0 at 45% XOR and at 3 at 40%, over the absolute bar (35%): a
    shape from those poses would be wrong (the frame-150 cartwheel's 1.84 m model for a
    1.56 m subject). The search runs again every 3 frames; at frame 6 it is under the bar
    (20%), and the pass runs from there: frames 7-16 tracked (12 frames from 6, the last
    refined one 16), the shape refined on 6, 8, ..., 16, and the pose of frame 6 tracked
    back to frame 0 with that shape, which is the pose returned. The frames tracked back
    are the pass's poses of those frames (a recovery's candidates)."""
    tracker, first, tracked, refined, progress = _pass_over_the_bar(
        monkeypatch, {0: 45.0, 3: 40.0, 6: 20.0})
    assert tracked == [(0, "start"), (3, "start"), (6, "start"),
                       # the second opinion (`_second_opinion`), here at once with one worker
                       # (`_opinion_beside`): 50%, the pass stands
                       (16, "start"),
                       *[(f, "track") for f in range(7, 17)],
                       *[(f, "back") for f in range(5, -1, -1)]]
    assert refined == [6, 8, 10, 12, 14, 16] and tracker.shape_frames_used == refined
    assert first.params[0] == 100.0 and progress == 12
    assert sorted(tracker._shape_pass_poses) == list(range(100, 117))
    assert tracker._shape_pass_poses[100][0] == 100.0  # frame 0: tracked back
    assert tracker._shape_pass_poses[106][0] == 6.0
    assert ("at frame 106" in tracker._start_event and "100 (XOR 45.0%), 103 (XOR 40.0%)"
            in tracker._start_event and tracker._start_event.endswith("to frame 100"))
    assert tracker.history == [] and tracker._last_good is None and not tracker._backwards


def test_a_shape_pass_start_not_tracked_back_to_the_first_frame_leaves_it_a_search(
        monkeypatch):
    """As above, but the track back from frame 6 diverges at frame 3: no pose is returned
    (`mocap track` searches the first frame's start with the pass's shape), and the start's
    event says why; the frames it reached (5, 4) are the pass's poses. When no start is
    under the bar, the lowest wins (frame 9 of 0-9: the first `shape_frames`)."""
    tracker, first, tracked, _, _ = _pass_over_the_bar(
        monkeypatch, {0: 45.0, 3: 40.0, 6: 20.0}, back_statuses={3: "diverged"})
    assert first is None and tracked[-3:] == [(5, "back"), (4, "back"), (3, "back")]
    assert "not tracked back to frame 100 (frame 103: diverged" in tracker._start_event
    assert {105, 104} <= set(tracker._shape_pass_poses) and 103 not in tracker._shape_pass_poses
    tracker, first, tracked, refined, _ = _pass_over_the_bar(
        monkeypatch, {0: 45.0, 3: 40.0, 6: 50.0, 9: 38.0})
    # (No second opinion at 19: 11 frames from there, fewer than the pass's 12.)
    assert [t for t in tracked if t[1] == "start"] == [(f, "start") for f in (0, 3, 6, 9)]
    assert refined[0] == 9 and first.params[0] == 100.0


def test_a_shape_pass_tracked_far_above_a_start_searched_at_its_end_runs_again_from_there(
        monkeypatch):
    """The pass's start at frame 0 under the bar (27%), its frames tracked at 30% XOR; a start
    searched afresh at its last frame (10) reaches 12%, clearly lower (1.2 times 12 is under
    30): the pass started wrong (the suite's bend_pickup from clip frame 150, session 46), and
    runs again from frame 10, whose pose is tracked back to frame 0 with the shape from frames
    10-20. With --back-xor-factor 0, or at 26% there (1.2 times that is over 30), the pass
    stands."""
    tracker, first, tracked, refined, progress = _pass_over_the_bar(
        monkeypatch, {0: 27.0, 10: 12.0}, tracked_xor=30.0)
    assert tracked == [(0, "start"), (10, "start"), *[(f, "track") for f in range(1, 11)],
                       *[(f, "track") for f in range(11, 21)],
                       *[(f, "back") for f in range(9, -1, -1)]]
    assert refined == [10, 12, 14, 16, 18, 20] and first.params[0] == 100.0 and progress == 12
    assert ("at frame 110 (XOR 12.0%); segment lengths from the frames from there: the shape "
            "pass from frame 100 had reached XOR 30.0% there (its start: init from stand-in"
            in tracker._start_event), tracker._start_event
    _, _, tracked, refined, _ = _pass_over_the_bar(monkeypatch, {0: 27.0, 10: 26.0},
                                                   tracked_xor=30.0)
    assert tracked[1] == (10, "start") and tracked[-1] == (10, "track")
    assert refined == [0, 2, 4, 6, 8, 10]
    _, _, tracked, refined, _ = _pass_over_the_bar(monkeypatch, {0: 27.0, 10: 12.0},
                                                   tracked_xor=30.0, back_xor_factor=0.0)
    assert (10, "start") not in tracked and refined == [0, 2, 4, 6, 8, 10]


def test_the_second_opinion_searches_beside_the_pass_and_the_shape_is_made_meanwhile(
        monkeypatch):
    """As above, with 2 workers: the second opinion's search runs in a process beside the pass
    (`_opinion_beside`: its start at frame 10 is not among this process's frames), and the
    shape is made from the pass while it runs (refined on 0-10). Where the opinion moves the
    pass, it runs again from frame 10 and the shape is made again, from 10-20: the same
    pose, shape and event as in turn (the test above). Where the pass stands, the shape made
    meanwhile is the one kept."""
    tracker, first, tracked, refined, progress = _pass_over_the_bar(
        monkeypatch, {0: 27.0, 10: 12.0}, tracked_xor=30.0, pause_s=1.0, workers=2)
    assert tracked == [(0, "start"), *[(f, "track") for f in range(1, 21)],
                       *[(f, "back") for f in range(9, -1, -1)]]
    assert refined == [0, 2, 4, 6, 8, 10, 10, 12, 14, 16, 18, 20]
    assert first.params[0] == 100.0 and progress == 12
    assert ("at frame 110 (XOR 12.0%); segment lengths from the frames from there: the shape "
            "pass from frame 100 had reached XOR 30.0% there (its start: init from stand-in"
            in tracker._start_event), tracker._start_event
    assert tracker.history == [] and sorted(tracker._shape_pass_poses) == list(range(100, 121))
    tracker, first, tracked, refined, _ = _pass_over_the_bar(
        monkeypatch, {0: 27.0, 10: 26.0}, tracked_xor=30.0, pause_s=1.0, workers=2)
    assert tracked == [(0, "start"), *[(f, "track") for f in range(1, 11)]]
    assert refined == [0, 2, 4, 6, 8, 10] and first.params[0] == 0.0
    assert tracker._start_event == "init from stand-in; segment lengths from the first frames"


def test_a_pass_that_loses_the_subject_before_the_opinions_frame_gets_one_at_its_own_end(
        monkeypatch):
    """The pass from frame 0 loses the subject at frame 6, before the frame its second opinion
    searches beside it (10): that search is given up unwaited (it would take 30 s), and the
    opinion is searched here at the pass's own last frame (5), as the pass ended there; at
    12% against the pass's 30% it moves the pass, which runs again from 5."""
    started = time.perf_counter()
    tracker, first, tracked, refined, _ = _pass_over_the_bar(
        monkeypatch, {0: 27.0, 5: 12.0}, tracked_xor=30.0, pause_s=30.0, lost_from=6,
        workers=2)
    assert time.perf_counter() - started < 15
    assert tracked[:8] == [(0, "start"), *[(f, "track") for f in range(1, 7)], (5, "start")]
    # (no shape made from the pass meanwhile: it ended before the opinion's frame; the pass
    # again from 5 loses the subject at 6 too, and the shape comes from 5 alone)
    assert refined == [5] and "at frame 105 (XOR 12.0%)" in tracker._start_event


def test_cli_track_needs_a_video_workspace(tmp_path):
    result = run_cli("track", tmp_path)
    assert result.returncode == 2 and "not a video workspace" in result.stderr


@pytest.mark.parametrize("flag", [["--contour-level", "3"], ["--shape-stride", "0"],
                                  ["--levels", "0"], ["--max-xor-fraction", "0"],
                                  ["--init-headings", "-1"], ["--hold", "l_knee_flex"],
                                  ["--init-starts", "0"], ["--init-twists", "0"],
                                  ["--back-xor-factor", "-1"]])
def test_cli_track_rejects_bad_settings_in_one_line(tmp_path, flag):
    result = run_cli("track", tmp_path, *flag)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip().count("\n") == 0 and flag[0] in result.stderr


def test_pixels_of_unknown_background_are_left_out():
    """cam01's background is unknown over a band across the torso (its photo showed a person
    there, say): its silhouette there is wrong, the torso lost and a blob beside it. Told
    which pixels are unknown, the tracker leaves them out of the energy (whose XOR is then
    that of clean silhouettes) and of the visual hull."""
    truth = _walk(3)
    band = np.zeros((CAMERAS[1].height, CAMERAS[1].width), bool)
    band[60:150, :] = True

    def corrupted(pose: Pose) -> list[np.ndarray]:
        masks = _masks(pose)
        masks[1] = masks[1] & ~band  # the torso and arms lost ...
        masks[1][70:140, 60:110] = True  # ... and a blob that is not there
        return masks

    errors, xor = {}, {}
    # Without the floor band, whose pixels (here the soles', 3-5 points of the silhouette at
    # 320x240) count as missed whatever the pose: the XOR told is then that of clean
    # silhouettes alone (0.043-0.061 with the band).
    config = dataclasses.replace(SUPERQUADRIC, floor_band_m=0.0)
    for told in (True, False):
        tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE,
                                    unknown=[None, band, None, None] if told else None)
        errors[told], xor[told] = [], []
        for frame, pose in enumerate(truth):
            result = tracker.track(frame, corrupted(pose),
                                   init=truth[0] if frame == 0 else None)
            assert result.pose is not None, result.event
            errors[told].append(_mpjpe_mm(result.pose, SHAPE, pose))
            xor[told].append(result.xor_fraction)
    assert max(errors[True]) < 15, errors
    assert max(xor[True]) < 0.06 < min(xor[False][1:]), xor  # measured 0.000-0.014
    # The visual hull is carved by what the views can tell: the torso is in it.
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE,
                                unknown=[None, band, None, None])
    hull = tracker.visual_hull_points(corrupted(truth[0]))
    body = MODEL.posed_vertices(truth[0])
    assert np.ptp(hull[:, 1]) > np.ptp(body[:, 1]) - 0.1


def test_limb_samples_must_end_inside_every_silhouette_and_off_the_trunk():
    """Thesis 6.2.5's sample test (`_valid`), many samples at once: a sample whose hand ends
    inside every (dilated) silhouette and off the torso axis passes; one whose hand leaves a
    silhouette, or ends on the torso axis, does not."""
    truth = _walk(1)[0]
    tracker = SilhouetteTracker(CAMERAS, SUPERQUADRIC, shape=SHAPE)
    energy = tracker._energy(_masks(truth))
    tracker._refine_all(energy, truth.params.copy())  # sets the dilated silhouettes
    out = truth.params.copy()  # the arm raised sideways, out of the silhouettes
    out[PARAM_INDEX["l_shoulder_rz"]] = 1.5
    across = truth.params.copy()  # the hand drawn onto the torso axis
    across[PARAM_INDEX["l_shoulder_rz"]] = -0.8
    across[PARAM_INDEX["l_elbow_flex"]] = 2.4
    ends = ("l_elbow", "l_wrist")
    valid = tracker._valid(np.array([truth.params, out, across]), ends, "arm", energy, 1)
    assert valid.tolist() == [True, False, False]
