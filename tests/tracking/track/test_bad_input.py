"""Bad input for `mocap track` (issue 20): a subject who leaves the view, two subjects in
view, a subject partly outside an image, a sequence too short for the shape pass. Synthetic
scenes of the superquadric body (4 views at 320x240, `test_tracker`'s) or a small `mocap
synth` workspace (2 views at 200x150)."""

from __future__ import annotations

import dataclasses
import functools
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.errors import UserError
from recon.workspace import Workspace
from tests.helpers import run_cli
from tests.tracking.track.test_tracker import CAMERAS, SHAPE, _masks, _mpjpe_mm, _walk
from tracking.body.model import BodyShape
from tracking.track.step import TrackStepConfig, track_workspace
from tracking.track.tracker import SilhouetteTracker, TrackConfig

FAST = TrackConfig(body="superquadric", init_headings=2)
"""The superquadric tracker with two upright starts besides the hull's fit (the fit alone
starts 131 mm off in the scene of the absent frames below): a re-acquisition in ~15 s."""


def _track(frames_masks, truth, config=FAST, given: bool = True):
    """Track masks per frame from the true start (`given`); results and MPJPE (mm, NaN when
    the frame has no pose) against `truth`."""
    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    results, errors = [], []
    for frame, (masks, pose) in enumerate(zip(frames_masks, truth, strict=True)):
        result = tracker.track(frame, masks, init=truth[0] if given and frame == 0 else None)
        results.append(result)
        errors.append(np.nan if result.pose is None else _mpjpe_mm(result.pose, SHAPE, pose))
    return results, errors


# session 26, make test over 10 minutes: 67 s (2 shared cores); re-acquisition stays in
# test_a_subject_who_enters_late_is_tracked_from_its_first_frame
@pytest.mark.slow
def test_a_subject_who_leaves_the_view_is_absent_then_found_again():
    """Frames 3-4 show nobody in any camera: they are "absent" (no pose, no search), and
    frame 5, the subject back, is found again by the start search from the visual hull."""
    truth = _walk(6)
    masks = [[np.zeros_like(m) for m in _masks(p)] if k in (3, 4) else _masks(p)
             for k, p in enumerate(truth)]  # fmt: skip
    results, errors = _track(masks, truth)
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "absent", "absent", "recovered"], statuses
    assert all(r.pose is None and "out of view" in r.event for r in results[3:5])
    assert "after frames 3-4 were absent" in results[5].event
    # Measured 3 mm: the hull's start refined against the outlines (1 px is ~12 mm here).
    assert errors[5] < 15, errors


@functools.cache
def _synth_ws() -> Path:
    """A `mocap synth` workspace: 2 cameras at 200x150, 4 frames of a walk, exact silhouettes
    (about a second), built once and copied per test."""
    import tempfile

    from tracking.body.bvh import write_bvh
    from tracking.body.motion import motion_from_poses
    from tracking.body.synthetic import walking_poses
    from tracking.rig.synth import SynthConfig, synthesize

    root = Path(tempfile.mkdtemp(prefix="mocap-bad-input-"))
    shape = BodyShape.default(1.75)
    write_bvh(motion_from_poses(walking_poses(8, 30.0, shape), shape, 1 / 30), root / "w.bvh")
    synthesize(root / "ws", SynthConfig(bvh=root / "w.bvh", cameras=2, size="200x150",
                                        frames=4, clean=True))  # fmt: skip
    return root / "ws"


def _ws_with_empty(tmp_path: Path, frames: tuple[int, ...]) -> Path:
    ws = tmp_path / "ws"
    shutil.copytree(_synth_ws(), ws)
    for path in sorted((ws / "silhouettes").glob("cam*/0*.png")):
        if int(path.stem) in frames:
            cv2.imwrite(str(path), np.zeros((150, 200), np.uint8))
    return ws


def test_a_subject_who_enters_late_is_tracked_from_its_first_frame(tmp_path):
    """Frames 0-1 are empty in both cameras (the recording began before the subject walked
    in): tracking starts at frame 2, from the given pose (it was refused, or given to no
    frame, before), and pose.json, run.json and the command say which frames were absent."""
    ws = _ws_with_empty(tmp_path, (0, 1))
    result = run_cli("track", ws, "--init-pose", ws / "gt" / "pose.json")
    assert result.returncode == 0, result.stderr
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert [f["status"] for f in pose["frames"]] == ["absent", "absent", "init", "tracked"]
    # (Tracked back from frame 3 where that is clearly lower: `track_back`.)
    assert pose["frames"][2]["event"].startswith("init from the given pose")
    assert pose["absent"] == [0, 1] and pose["lost"] == []
    assert [f["params"] is None for f in pose["frames"]] == [True, True, False, False]
    assert "absent     frames [0, 1]" in result.stdout
    assert "no subject in view in 2 of 4 frames" in result.stderr


def test_silhouettes_with_nobody_in_any_frame_are_refused_in_one_line(tmp_path):
    ws = _ws_with_empty(tmp_path, (0, 1, 2, 3))
    with pytest.raises(UserError, match=r"no silhouette in any camera in any of frames 0-3"):
        track_workspace(Workspace.open_video(ws), TrackStepConfig(), FAST, progress=False)
    assert not (ws / "tracks").exists() and not (ws / "logs" / "track.rrd").exists()


def _beside(pose, dx_m: float = 1.3):
    from tracking.body.model import Pose

    params = pose.params.copy()
    params[0] += dx_m
    return Pose(params)


def test_the_visual_hull_tells_one_subject_from_two():
    """One walking body makes one hull part of human size; a second 0.7-1.3 m beside it (0.2
    m between them at 0.7) makes two or more (each, and their ghosts), in 0.1 s."""
    from tracking.track.tracker import subjects_in_view

    pose = _walk(3)[2]
    one = subjects_in_view(CAMERAS, _masks(pose), FAST)
    assert len(one) == 1 and 1.6 < one[0].height_m < 1.95, one  # the body is 1.75 m
    for dx in (0.7, 1.3):
        two = [a | b for a, b in zip(_masks(pose), _masks(_beside(pose, dx)), strict=True)]
        parts = subjects_in_view(CAMERAS, two, FAST)
        assert len(parts) >= 2, (dx, parts)
        assert abs(np.linalg.norm(parts[0].centre - parts[1].centre) - dx) < 0.1, parts


# session 26, make test over 10 minutes: 80 s (2 shared cores); two subjects stay in
# test_a_start_with_two_subjects_in_view_waits_for_one
@pytest.mark.slow
def test_two_subjects_in_view_are_said_and_not_tracked_as_one():
    """A second subject stands 1.3 m beside the tracked one in frames 3-4: those frames are
    "two-subjects" (no pose, the event says why) instead of a fit to both (the former code
    lost frame 3 without saying why and "recovered" frame 4 on the merged blob at 51% XOR,
    55 mm off, after two start searches of ~25 s); frame 5, alone again, is found again."""
    truth = _walk(6)
    masks = [[a | b for a, b in zip(_masks(p), _masks(_beside(p)), strict=True)]
             if k in (3, 4) else _masks(p) for k, p in enumerate(truth)]  # fmt: skip
    results, errors = _track(masks, truth)
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "two-subjects", "two-subjects",
                        "recovered"], [r.event for r in results]
    assert all(r.pose is None and "2 subjects in view" in r.event for r in results[3:5])
    assert "after frames 3-4 were refused (two subjects)" in results[5].event
    assert errors[5] < 15, errors


def _ws_with_second_subject(tmp_path: Path, frames: tuple[int, ...]) -> Path:
    """The synth workspace with a second body (the superquadric model, in the subject's pose)
    1 m beside the subject in `frames`, in both cameras."""
    from tracking.body.model import BodyModel, Pose
    from tracking.body.motion import read_pose_file
    from tracking.rig.cameras import read_cameras
    from tracking.track.render import CpuRasterRenderer

    ws = _ws_with_empty(tmp_path, ())
    cameras = read_cameras(ws / "cameras.json")
    truth = dict(read_pose_file(ws / "gt" / "pose.json").frames)
    model, render = BodyModel(SHAPE), CpuRasterRenderer(CpuRasterRenderer.Options())
    for frame in frames:
        vertices = model.posed_vertices(_beside(Pose(truth[frame]), 1.0))
        for camera in cameras:
            path = ws / "silhouettes" / camera.name / f"{frame:06d}.png"
            mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127
            other = render.render(vertices, model.faces, camera)
            cv2.imwrite(str(path), 255 * (mask | other).astype(np.uint8))
    return ws


def test_a_start_with_two_subjects_in_view_waits_for_one(tmp_path):
    """A second subject beside the first in frames 0-1: tracking starts at frame 2, when the
    subject is alone, from the given pose, and frames 0-1 are said (the former code tracked
    them at 57% XOR without a word: the absolute bar starts from the first frame's XOR); with
    two subjects in every frame, nothing is tracked, in one line."""
    ws = _ws_with_second_subject(tmp_path, (0, 1))
    result = run_cli("track", ws, "--init-pose", ws / "gt" / "pose.json")
    assert result.returncode == 0, result.stderr
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert [f["status"] for f in pose["frames"]] == ["two-subjects", "two-subjects", "init",
                                                      "tracked"], pose["frames"]
    assert pose["two_subjects"] == [0, 1] and "subjects in view" in pose["frames"][0]["event"]
    assert "two or more subjects in view in 2 of 4 frames" in result.stderr
    crowded = _ws_with_second_subject(tmp_path / "all", (0, 1, 2, 3))
    with pytest.raises(UserError, match=r"no frame shows one subject: two or more subjects "
                                        r"are in view in frame\(s\) 0-3"):
        track_workspace(Workspace.open_video(crowded), TrackStepConfig(), FAST, progress=False)
    assert not (crowded / "tracks").exists()


@pytest.mark.slow  # an automatic start and a shape pass: about a minute on 2 shared cores
def test_a_sequence_too_short_for_the_shape_pass_is_warned_about(tmp_path):
    """2 frames for a shape pass of 24 (every 4th: 6 poses): the shape comes from frame 0
    alone, and the summary (printed by `mocap track`) says so; before, nothing did."""
    ws = _ws_with_empty(tmp_path, ())
    summary = track_workspace(Workspace.open_video(ws), TrackStepConfig(last=1), FAST,
                              progress=False)  # fmt: skip
    assert summary["tracked"] == 2
    assert summary["warnings"] == [
        "the sequence has 2 frames for --shape-frames 24: the body's shape comes from 1 "
        "pose(s) (frame(s) 0) instead of 6, and is less certain; track a longer sequence, or "
        "give a known shape with --init-pose"]


def test_the_shape_pass_warning_says_why_it_had_fewer_poses():
    from tracking.track.step import _short_shape_pass

    config = TrackConfig(body="superquadric")  # 24 frames, every 4th: 6 poses
    frames = list(range(10, 34))
    assert _short_shape_pass(config, frames, [0, 4, 8, 12, 16, 20]) == []
    lost = _short_shape_pass(config, frames, [0, 4])  # lost between frames 14 and 18
    assert lost == ["the shape pass lost the subject after frame 14: the body's shape comes "
                    "from 2 pose(s) (frame(s) 10, 14) instead of 6, and is less certain; "
                    "track a longer sequence, or give a known shape with --init-pose"]
    short = _short_shape_pass(config, frames[:9], [0, 4, 8])
    assert short[0].startswith("the sequence has 9 frames for --shape-frames 24: the body's "
                               "shape comes from 3 pose(s) (frame(s) 10, 14, 18) instead of 6")
    # A start over the bar at frames 10-16 moved the pass to frame 19 (`calibrate_shape`),
    # and the 30 frames end 21 frames after it: 6 poses would have fitted from frame 10.
    late = _short_shape_pass(config, list(range(10, 40)), [9, 13, 17, 21, 25])
    assert late[0].startswith("the sequence has 21 frames from frame 19, where the shape pass "
                              "started (the start search before it was over the bar), for "
                              "--shape-frames 24: the body's shape comes from 5 pose(s)")


def _head_out_of_cam00() -> list:
    """`CAMERAS` with cam00's principal point 90 px lower: the subject's head and shoulders
    are above its image (the others see the whole body)."""
    import dataclasses

    K = CAMERAS[0].K.copy()
    K[1, 2] -= 90.0
    return [dataclasses.replace(CAMERAS[0], K=K), *CAMERAS[1:]]


def test_a_subject_partly_out_of_a_view_keeps_its_visual_hull_and_is_flagged():
    """The head is out of cam00's image: the start's visual hull keeps it (the others see it;
    the former hull, which every view had to see, was 0.55 m short, and the start from it 1.55 m
    tall for 1.75, 223 mm off), and the frame names cam00 as partly out of view."""
    from tests.tracking.track.test_tracker import MODEL, RENDER
    from tracking.rig.cameras import rig_up

    cameras = _head_out_of_cam00()
    pose = _walk(1)[0]
    vertices = MODEL.posed_vertices(pose)
    masks = [RENDER.render(vertices, MODEL.faces, c) for c in cameras]
    assert masks[0][0].any() and not any(m[0].any() for m in masks[1:])
    tracker = SilhouetteTracker(cameras, FAST, shape=SHAPE)
    hull = tracker.visual_hull_points(masks)
    up = rig_up(cameras, hull.mean(axis=0))
    body = vertices @ up
    assert np.ptp(hull @ up) > np.ptp(body) - 0.1, (np.ptp(hull @ up), np.ptp(body))
    assert (hull @ up).max() > body.max() - 0.06  # the top of the head, within two voxels
    result = tracker.track(0, masks, init=pose)
    assert result.cut_by == ("cam00",) and result.pose is not None
    assert _mpjpe_mm(result.pose, SHAPE, pose) < 10


# session 26, make test over 10 minutes: 57 s (2 shared cores); partly out of view stays in
# test_a_subject_partly_out_of_a_view_keeps_its_visual_hull_and_is_flagged
@pytest.mark.slow
def test_an_automatic_start_with_the_head_out_of_a_view_finds_the_subject():
    """The same frame started from the silhouettes alone, the shape unknown: 1.75 m tall and 3
    mm off (measured; the former hull's start: 1.55 m, 30% XOR, 223 mm off, status "init")."""
    from tests.tracking.track.test_tracker import MODEL, RENDER

    cameras = _head_out_of_cam00()
    pose = _walk(1)[0]
    vertices = MODEL.posed_vertices(pose)
    tracker = SilhouetteTracker(cameras, FAST)
    result = tracker.track(0, [RENDER.render(vertices, MODEL.faces, c) for c in cameras])
    assert result.status == "init" and result.cut_by == ("cam00",)
    assert abs(tracker.shape.height - SHAPE.height) < 0.05, tracker.shape.height
    assert _mpjpe_mm(result.pose, tracker.shape, pose) < 15


def test_pose_json_names_the_frames_and_cameras_partly_out_of_view(tmp_path):
    from tracking.body.model import BodyModel, Pose
    from tracking.track.step import _write_outputs
    from tracking.track.tracker import FrameResult

    def result(frame, cut_by=()):
        return FrameResult(frame, Pose(np.zeros(26)), 100.0, 1000.0, 1, 0.1,
                           "init" if frame == 0 else "", "init" if frame == 0 else "tracked",
                           cut_by)  # fmt: skip

    outputs = {n: tmp_path / f"out.{n}" for n in ("joints", "pose", "bvh", "glb")}
    _write_outputs(outputs, [result(0), result(1, ("cam00", "cam02")), result(2)],
                   BodyModel(SHAPE), 30.0, np.eye(3))  # fmt: skip
    written = json.loads(outputs["pose"].read_text())
    assert written["partly_out_of_view"] == [1]
    assert [f["partly_out_of_view"] for f in written["frames"]] == [[], ["cam00", "cam02"], []]


@pytest.mark.slow  # two starts from the visual hull: about 40 s on 2 shared cores
def test_a_start_after_a_gap_over_the_absolute_bar_is_not_recovered():
    """After absent frame 3, frame 4 shows the subject with a blob twice its size beside it in
    cam01 (another person outside the others' view, say): the start search's best pose leaves
    the blob unexplained, over the 35% bar. Lost, not "recovered" as the former code called
    it; frame 5, clean, is found again."""
    truth = _walk(6)
    masks = [_masks(p) for p in truth]
    masks[3] = [np.zeros_like(m) for m in masks[3]]
    masks[4][1] = masks[4][1].copy()
    masks[4][1][20:220, 0:90] = True  # beside the subject, at the image's left edge
    results, errors = _track(masks, truth)
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "absent", "lost", "recovered"], (
        statuses, [r.event for r in results])
    assert "found nothing under the absolute bar 35%" in results[4].event
    assert results[4].xor_fraction > 0.35 and errors[5] < 15, (results[4].xor_fraction, errors)


def _handstand(frames: int) -> list:
    """Upside down on the hands (arms raised overhead, so below), legs apart and swinging."""
    from tracking.body.model import Pose

    return [Pose.from_dict({
        "root_ty": 1.05, "root_rz": 3.0, "root_ry": 0.4,
        "l_shoulder_rz": 2.8, "r_shoulder_rz": -0.5 + 0.0 * k,
        "r_shoulder_rx": -2.6, "l_hip_rz": 0.35 + 0.03 * k, "r_hip_rz": -0.35,
        "l_hip_rx": -0.2 * k, "r_knee_flex": 0.4,
    }) for k in range(frames)]  # fmt: skip


def test_after_lost_frames_the_start_search_starts_from_the_last_good_pose_too():
    """A subject upside down is absent for frames 3-4: at frame 5 the start search runs from
    the last good pose as well as from the visual hull, whose upright starts and fit (within
    60 degrees of up) cannot reach a handstand: the hull's extremity starts are off here,
    since with them, and the second pass of a recovery's best starts, the hull's search
    finds the handstand too (1.5 mm, session 32). Found again, on its pose."""
    truth = _handstand(6)
    masks = [[np.zeros_like(m) for m in _masks(p)] if k in (3, 4) else _masks(p)
             for k, p in enumerate(truth)]  # fmt: skip
    results, errors = _track(masks, truth, dataclasses.replace(FAST, init_extremity_starts=0))
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "absent", "absent", "recovered"], (
        statuses, [r.event for r in results])
    assert "init from the last good pose (frame 2)" in results[5].event, results[5].event
    assert max(errors[:3]) < 15 and errors[5] < 15, errors
