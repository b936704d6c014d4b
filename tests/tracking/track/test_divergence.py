"""Knowing when the tracker is lost, recovering, reporting it, and the frame interval in the
search ranges (issue 20); the relative XOR test alone: test_xor_watch.py."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import tracking.track.tracker as tracker_module
from recon.errors import UserError
from tracking.body.model import Pose
from tracking.body.motion import read_pose_file
from tracking.track.step import _write_outputs, status_lists
from tracking.track.tracker import (
    FrameResult,
    SilhouetteTracker,
    TrackConfig,
    limb_half_range,
)


def test_grid_ranges_scale_with_the_frame_interval():
    """Defaults reproduce the former 8 and 40 degree half-ranges at 30 fps (the rate they were
    tuned at); at 60 fps the same angular speeds give half of them, at 25 fps 1.2 times."""
    config = TrackConfig()
    change = np.deg2rad([0.0, 2.0, 10.0, 100.0])  # change over the two preceding frames
    at_30 = np.rad2deg(limb_half_range(change, 1 / 30, config))
    np.testing.assert_allclose(at_30, [8.0, 8.0, 20.0, 40.0])
    np.testing.assert_allclose(np.rad2deg(limb_half_range(change, 1 / 60, config)),
                               [4.0, 4.0, 20.0, 20.0])  # fmt: skip
    np.testing.assert_allclose(np.rad2deg(limb_half_range(change, 1 / 25, config)),
                               [9.6, 9.6, 20.0, 48.0])  # fmt: skip
    # With no time in the loop (starts), the grids span the same whatever the frame rate.
    np.testing.assert_allclose(limb_half_range(change, 1 / 60, config, wide=True),
                               limb_half_range(change, 1 / 30, config, wide=True))
    with pytest.raises(ValueError, match="frame interval"):
        SilhouetteTracker([], TrackConfig(body="superquadric"), frame_interval_s=0.0)


def _result(frame: int, status: str, pose: bool = True) -> FrameResult:
    return FrameResult(frame, Pose(np.zeros(26)) if pose else None, 1000.0 if pose else np.nan,
                       10000.0, 1, 0.1, "" if status == "tracked" else f"{status}: why",
                       status)  # fmt: skip


def test_pose_json_carries_each_frame_status_and_the_lost_and_recovered_frames(tmp_path):
    from tracking.body.model import BodyModel, BodyShape

    results = [_result(0, "init"), _result(1, "tracked"), _result(2, "lost", pose=False),
               _result(3, "recovered"), _result(4, "diverged"), _result(5, "tracked")]
    model = BodyModel(BodyShape.default(1.75))
    names = ("joints", "pose", "bvh", "glb")
    outputs = {n: tmp_path / f"out.{n}" for n in names}
    _write_outputs(outputs, results, model, 30.0, np.eye(3))
    written = json.loads(outputs["pose"].read_text())
    assert [f["status"] for f in written["frames"]] == ["init", "tracked", "lost", "recovered",
                                                         "diverged", "tracked"]
    assert (written["lost"], written["diverged"], written["recovered"]) == ([2], [4], [3])
    assert status_lists(results) == {"lost": [2], "diverged": [4], "recovered": [3],
                                     "absent": [], "two_subjects": []}
    # The readers of pose.json (mocap report, --init-pose) read it as before: frame 2 lost.
    given = read_pose_file(outputs["pose"])
    assert [f for f, p in given.frames if p is None] == [2] and len(given.frames) == 6


def _arms_out(pose: Pose) -> Pose:
    """`pose` with both arms raised sideways to horizontal and the elbows straight: what a
    tracker at 30 fps cannot follow in one frame."""
    values = pose.as_dict()
    values.update({"l_shoulder_rz": 1.4, "r_shoulder_rz": -1.4, "l_shoulder_rx": 0.0,
                   "r_shoulder_rx": 0.0, "l_elbow_flex": 0.0, "r_elbow_flex": 0.0})
    return Pose.from_dict(values)


def _track_shown(config: TrackConfig, shown: list[Pose], recover=None, masks_of=None):
    """A small synthetic scene (the superquadric body, 4 views at 320x240) showing the poses
    `shown` (their silhouettes, or ``masks_of(frame, pose)``), tracked from the true start, with
    `recover` in place of the start search when given: the frames' results and MPJPE (mm)
    against what they show."""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE, _masks, _mpjpe_mm

    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    if recover is not None:
        tracker._recover = lambda frame, masks, energy, x, e, enough=None: recover(
            tracker, energy, x, e)
    results, errors = [], []
    for frame, pose in enumerate(shown):
        tracker.shown = pose
        masks = _masks(pose) if masks_of is None else masks_of(frame, pose)
        result = tracker.track(frame, masks, init=shown[0] if frame == 0 else None)
        assert result.pose is not None, result.event
        results.append(result)
        errors.append(_mpjpe_mm(result.pose, SHAPE, pose))
    return results, errors


def _track_jumps(config: TrackConfig, recover=None):
    """`_track_shown` of a walk whose frames 6-7 show the subject with the arms suddenly out
    (silhouettes of another pose, as when a track jumps), frame 8 the walk again."""
    from tests.tracking.track.test_tracker import _walk

    return _track_shown(config, [_arms_out(p) if k in (6, 7) else p
                                 for k, p in enumerate(_walk(9))], recover)  # fmt: skip


@pytest.mark.parametrize("relative", [True, False])
def test_a_track_that_jumps_is_flagged_under_the_absolute_bar(relative):
    """The jump to the arms out and back is far above the 1-3% XOR of the frames before: the
    relative test flags both frames, and what the start search returns (here a stand-in that
    finds the pose shown) makes them "recovered". With the relative tests off, the same jump
    passes under the absolute bar (35%): tracked, and 60+ mm off."""
    config = TrackConfig(body="superquadric")
    if not relative:
        config = dataclasses.replace(config, spike_xor_factor=0.0, high_xor_frames=0)
    calls = []

    def recover(tracker, energy, x, e):
        calls.append(tracker.shown)
        y = tracker.shown.params
        return y, energy(Pose(y)), "the pose shown"

    results, errors = _track_jumps(config, recover)
    statuses = [r.status for r in results]
    xor = [round(r.xor_fraction, 3) for r in results]
    if relative:
        assert statuses == ["init"] + ["tracked"] * 5 + ["recovered", "tracked", "recovered"], (
            statuses, xor)
        assert "recent median" in results[6].event and "the pose shown" in results[6].event
        # The stand-in's poses exactly; frame 7 tracked on from there (measured 11 mm).
        assert len(calls) == 2 and errors[6] < 1 and errors[8] < 1 and errors[7] < 25, errors
    else:
        assert statuses == ["init"] + ["tracked"] * 8 and not calls, (statuses, xor)
        assert xor[6] < TrackConfig().max_xor_fraction and errors[6] > 60, (errors, xor)


def test_a_track_back_under_the_bar_after_a_divergence_is_found_again():
    """Frame 4 of a walk has a ghost in one view (a block of foreground beside the subject,
    as a passing shadow makes): the XOR jumps, and a start search that finds nothing better
    (a stand-in returning the tracked pose) leaves the frame "diverged", its XOR the
    reference. Frame 5 is clean: the track, back under the bar of before the divergence, its
    visual hull explained, is "recovered" by the tracking itself, and so said once. Without
    the hull check (``max_unexplained_share`` 0) nothing confirms it: tracked."""
    from tests.tracking.track.test_tracker import _masks, _walk

    def ghost(frame: int, pose: Pose) -> list[np.ndarray]:
        masks = _masks(pose)
        if frame == 4:
            masks[0][100:130, 20:40] = True  # the ghost, left of the subject
        return masks

    def track(config: TrackConfig, found: str | None = None
              ) -> tuple[list[FrameResult], list[float]]:  # fmt: skip
        return _track_shown(config, _walk(7), lambda t, energy, x, e: (x, e, found), ghost)

    results, errors = track(TrackConfig(body="superquadric"))
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "tracked", "diverged", "recovered",
                        "tracked"], (statuses, [round(r.xor_fraction, 3) for r in results])
    assert "before the divergence at frame 4" in results[5].event, results[5].event
    assert "the start search found nothing better" in results[4].event, results[4].event
    # A pose the search found that is still a divergence is named, not "nothing better".
    named, _ = track(TrackConfig(body="superquadric"), found="the stand-in")
    assert named[4].status == "diverged" and "found the stand-in, still a divergence" in \
        named[4].event, named[4].event
    assert max(errors) < 25, errors  # the pose was right all along: the ghost is not a limb
    unchecked, _ = track(TrackConfig(body="superquadric", max_unexplained_share=0.0))
    assert [r.status for r in unchecked][4:] == ["diverged", "tracked", "tracked"]


def test_a_track_stuck_over_the_bar_after_a_divergence_is_searched_again():
    """Frames 4-7 of a walk have a ghost in one view: frame 4's XOR jumps, and a start search
    that finds nothing better leaves it "diverged", its XOR the reference. Frames 5 and 6 are
    as high, so still over the bar of before the divergence: "diverged" too (the XOR cannot
    tell a ghost from a wrong pose; tracked, a wrong pose there was trusted). Still over that
    bar `_SEARCH_AGAIN_FRAMES` (3) frames on, the search runs again (here a stand-in that then
    finds a pose under it): frame 7 is "recovered", not frame 8 when the ghost has gone."""
    from tests.tracking.track.test_tracker import _masks, _walk
    from tracking.track.tracker import _SEARCH_AGAIN_FRAMES

    assert _SEARCH_AGAIN_FRAMES == 3
    calls = []

    def ghost(frame: int, pose: Pose) -> list[np.ndarray]:
        masks = _masks(pose)
        if 4 <= frame <= 7:
            masks[0][100:140, 10:40] = True  # the ghost, left of the subject
        return masks

    def recover(tracker, energy, x, e):
        calls.append(len(calls))
        return (x, e, None) if len(calls) == 1 else (x, 0.0, "the stand-in")

    results, _ = _track_shown(TrackConfig(body="superquadric"), _walk(10), recover, ghost)
    statuses = [r.status for r in results]
    assert statuses == ["init", "tracked", "tracked", "tracked", "diverged", "diverged",
                        "diverged", "recovered", "tracked", "tracked"], (
        statuses, [round(r.xor_fraction, 3) for r in results])
    assert len(calls) == 2
    assert "searched again 3 frames after the divergence at frame 4" in results[7].event
    assert all("still over" in r.event and "the divergence at frame 4" in r.event
               for r in results[5:7]), [r.event for r in results[5:7]]


def test_a_start_over_the_absolute_bar_is_not_trusted_and_is_searched_again():
    """Frames 0-3 of a walk have a ghost in one view as large as the subject's silhouettes in
    all four: the start, given the true pose, is at 40% XOR, over the absolute bar (35%). It
    is "diverged", not "init", and does not set this subject's reference: frames 1-2 are
    still over the bar, "diverged" too, and at frame 3 the start search runs again (here a
    stand-in that finds a pose under the bar), "recovered". Tracked as before, a start at
    35-47% set the bar at 1.5 times its own XOR, and the suite's frame-150 cartwheels were
    tracked 200-300 mm off for 60 frames, unflagged."""
    from tests.tracking.track.test_tracker import _masks, _walk

    calls = []

    def ghost(frame: int, pose: Pose) -> list[np.ndarray]:
        masks = _masks(pose)
        if frame <= 3:
            masks[0][60:150, 10:110] = True  # the ghost, left of the subject
        return masks

    def recover(tracker, energy, x, e):
        calls.append(len(calls))
        return x, 0.0, "the stand-in"

    config = TrackConfig(body="superquadric")
    results, errors = _track_shown(config, _walk(6), recover, ghost)
    statuses = [r.status for r in results]
    xor = [round(r.xor_fraction, 3) for r in results]
    assert statuses == ["diverged", "diverged", "diverged", "recovered", "tracked",
                        "tracked"], (statuses, xor)
    assert xor[0] > config.max_xor_fraction and len(calls) == 1, (xor, calls)
    assert "over the absolute bar 35%" in results[0].event, results[0].event
    assert all("which the start at frame 0 was over" in r.event for r in results[1:3]), [
        r.event for r in results[1:3]]
    assert "searched again 3 frames after the divergence at frame 0" in results[3].event
    assert max(errors) < 25, errors  # the pose was right all along: the ghost is not a limb
    # Without the ghost, the same start is trusted.
    clean, _ = _track_shown(config, _walk(3), recover)
    assert [r.status for r in clean] == ["init", "tracked", "tracked"] and len(calls) == 1


def test_a_recovery_searches_the_hull_only_when_the_last_good_pose_is_not_enough():
    """The start search of a recovery tries the last good pose first (its limbs over their
    whole range), and the visual hull's search (a stand-in here that finds the pose shown,
    counted) only when that candidate is not `enough` (a stand-in verdict here): the walk's
    arms jump out at frame 6, and the search runs from frame 5's pose."""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE, _masks, _mpjpe_mm, _walk

    walk = _walk(7)
    shown = _arms_out(walk[6])
    tracker = SilhouetteTracker(CAMERAS, TrackConfig(body="superquadric"), shape=SHAPE)
    for frame, pose in enumerate(walk[:6]):
        assert tracker.track(frame, _masks(pose), init=walk[0] if frame == 0 else None).pose
    searched = []

    def hull_search(masks, init=None, enough=None):
        searched.append(init)
        return shown, "the stand-in"

    tracker.initialise = hull_search
    masks = _masks(shown)
    energy = tracker._energy(masks)
    tracked = tracker.history[-1]
    before = energy(Pose(tracked))
    for enough, searches in ((lambda e: True, 0), (lambda e: False, 1), (None, 1)):
        searched.clear()
        x, e, found = tracker._recover(6, masks, energy, tracked, before, enough=enough)
        assert len(searched) == searches, (enough, found)
        if searches:  # the stand-in's pose, exactly
            assert found == "the visual hull" and _mpjpe_mm(Pose(x), SHAPE, shown) < 1
        else:  # better than the tracked pose, so it is the candidate
            assert found == "the last good pose (frame 5)" and e < before, (found, e, before)


@pytest.mark.parametrize(("passes", "enough_under", "again"), [
    (1, None, []), (2, None, [[1.0, 2.0]]), (3, None, [[1.0, 2.0], [0.5]]),
    (4, None, [[1.0, 2.0], [0.5], [0.0]]), (3, 0.6, [[1.0, 2.0]]), (4, 0.2, [[1.0, 2.0], [0.5]]),
])
def test_a_recovery_gives_its_two_best_starts_more_passes(passes, enough_under, again):
    """`_pass_again`: of a recovery's refined starts, the two of lowest score (x[0]) get a
    second pass of the hierarchy, and up to ``recovery_passes - 2`` more while the best is not
    enough (its energy, here x[0] too, not under `enough_under`; None: never enough), these
    only for the starts the pass before lowered. A stand-in refinement lowers the best start
    by 0.5 a pass and raises the second (not kept); the other starts are left as they are."""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE

    config = TrackConfig(body="superquadric", recovery_passes=passes)
    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    refined_again = []

    def refine_starts(energy, starts):
        refined_again.append([float(p.params[0]) for p in starts])
        return [p.params + np.r_[-0.5 if p.params[0] < 2 else 1.0, np.zeros(25)]
                for p in starts]

    tracker._refine_starts = refine_starts
    tracker._objective = lambda energy, x, level: float(x[0])
    enough = None if enough_under is None else (lambda e: e < enough_under)
    starts = [np.r_[v, np.zeros(25)] for v in (3.0, 1.0, 5.0, 2.0)]
    refined, scores = tracker._pass_again(lambda pose: float(pose.params[0]), starts,
                                          [3.0, 1.0, 5.0, 2.0], enough)
    assert refined_again == again
    assert scores == [3.0, 1.0 - 0.5 * len(again), 5.0, 2.0]
    assert [x[0] for x in refined] == scores
    with pytest.raises(UserError, match="--recovery-passes must be >= 1"):
        TrackConfig(recovery_passes=0)


@pytest.mark.parametrize(("enough_under", "known_shape", "batches", "winner"), [
    # The extremities' best (11) is enough: the upright start 3, lower, is not refined.
    (2.5, True, [[0, 9, 10, 11]], 11),
    (0.05, True, [[0, 9, 10, 11], list(range(1, 9))], 3),  # none is enough: all refined
    (None, True, [list(range(12))], 3),  # a start without `enough`: all at once, as before
    (None, False, [list(range(12))], 3),  # the start that sets the shape
])
def test_a_recovery_refines_the_stances_only_when_the_hulls_own_starts_are_not_enough(
        monkeypatch, enough_under, known_shape, batches, winner):
    """`_start_search` with `enough` (a recovery) refines the visual hull's own starts first
    (its fit 0 and its extremities' 9-11, together), and the stances (the upright starts 1-8)
    only when none of those is enough. Without `enough` every start is refined in one call.
    Stand-ins: start i refines to the score ``values[i]``, which is also its energy; no more
    passes (`recovery_passes` 1)."""
    values = [5.0, 4.0, 3.0, 0.1, 6.0, 7.0, 8.0, 9.0, 9.5, 2.0, 1.0, 0.2]
    tracker, refined_batches = _stand_in_start_search(monkeypatch, values)
    enough = None if enough_under is None else (lambda e: e < enough_under)
    x, score, start, *_ = tracker._start_search(
        [], Pose(np.zeros(26)), np.zeros((10, 3)), np.array([0.0, 1.0, 0.0]), False,
        known_shape, enough)  # fmt: skip
    assert refined_batches == batches
    assert int(x[1]) == winner and score == values[winner], start


def _stand_in_start_search(monkeypatch, values: list[float]
                           ) -> tuple[SilhouetteTracker, list[list[int]]]:  # fmt: skip
    """A tracker whose start search (`_start_search`) has 12 stand-in starts: the fit 0, the
    upright starts 1-8 and the extremities' 9-11, start i refined to the score ``values[i]``
    (its parameter 0; parameter 1 is i), which is also its energy; and the starts refined, in
    the batches `_refine_starts` was given."""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE

    def tagged(index: int) -> Pose:
        return Pose(np.r_[0.0, float(index), np.zeros(24)])

    tracker = SilhouetteTracker(CAMERAS, TrackConfig(body="superquadric", recovery_passes=1,
                                                     workers=1), shape=SHAPE)  # fmt: skip
    monkeypatch.setattr(tracker_module, "upright_starts",
                        lambda fit, up, headings, pelvis: [tagged(i) for i in range(1, 9)])
    tracker._best_hypothesis = lambda energy, x: tagged(0)
    tracker._extremity_starts = lambda energy, points: [tagged(i) for i in (9, 10, 11)]
    tracker._energy = lambda masks: (lambda pose, level=0: float(pose.params[0]))
    tracker._objective = lambda energy, x, level: float(x[0])
    batches = []

    def refine_starts(energy, starts):
        indices = [int(p.params[1]) for p in starts]
        batches.append(indices)
        return [np.r_[values[i], float(i), np.zeros(24)] for i in indices]

    tracker._refine_starts = refine_starts
    return tracker, batches


@pytest.mark.parametrize(("extremity", "known_shape", "winner", "contender"), [
    (0.9, False, 3, 11),  # lower than the upright start 3's 1.0, without the lead: contends
    (0.7, False, 11, None),  # under 0.8 times it: wins outright
    (1.1, False, 3, None),  # higher: nothing to contend
    (0.9, True, 11, None),  # a recovery (the shape known): the lowest wins
])
def test_an_extremity_start_lower_without_the_lead_contends_with_the_winner(
        monkeypatch, extremity, known_shape, winner, contender):
    """`_start_search` of a start that sets the shape: an extremity start that scores lower
    than the fit's and the stances' best but not under `_EXTREMITY_LEAD` times it is the
    contender, which the proportions decide (`_shaped_winner`)."""
    values = [5.0, 4.0, 3.0, 1.0, 6.0, 7.0, 8.0, 9.0, 9.5, 2.0, 1.5, extremity]
    tracker, _ = _stand_in_start_search(monkeypatch, values)
    x, score, start, _, other = tracker._start_search(
        [], Pose(np.zeros(26)), np.zeros((10, 3)), np.array([0.0, 1.0, 0.0]), False,
        known_shape)  # fmt: skip
    assert int(x[1]) == winner and score == values[winner], start
    if contender is None:
        assert other is None
    else:
        assert int(other[0][1]) == contender
        assert other[1] == "start 3 of 3 from its extremities"
        assert start == "an upright start at 90 deg from its fit"


@pytest.mark.parametrize(("shaped", "wins", "note"), [
    # The winner 3's swaps 1-3 and the contender 11's (4-6) each given their proportions:
    # the contender's legs swap at 700 is under 0.8 times the winner's best, 1000.
    ({0: 1000, 1: 1200, 5: 700, 4: 900}, (11, 1), "start 3 of 3 from its extremities, its "
     "legs swapped, with its proportions under 0.8 times the winner's (700 against 1000 XOR "
     "px)"),
    ({0: 1000, 1: 1200, 5: 850, 4: 900}, (3, 0), "the winner"),  # lower, not by the lead
    ({0: 2000, 2: 1000, 4: 900}, (3, 2), "the winner"),  # the winner's arms swap
])
def test_the_proportions_decide_between_the_winner_and_its_contender(monkeypatch, shaped, wins,
                                                                      note):
    """`_shaped_winner` with a contender: both starts and their left/right swaps (legs, arms,
    both) are given their proportions side by side, and the contender wins when its best is
    under `_EXTREMITY_LEAD` times the winner's best; what the start's message says of it.
    Stand-ins: a pose's parameter 1 tags its start, parameter 2 its swap (0 itself); pose k
    of the 8 (the winner's four, then the contender's) scores ``shaped[k]`` (else 9000)."""
    tracker, _ = _stand_in_start_search(monkeypatch, [5.0] * 12)
    tracker._refine_starts = lambda energy, starts: [p.params.copy() for p in starts]
    order = []

    def refine_shape(sequence, poses):
        order.append((int(poses[0].params[1]), int(round(poses[0].params[2]))))
        return [Pose(poses[0].params)]

    monkeypatch.setattr(tracker_module, "left_right_swaps",
                        lambda x: [np.r_[x[:2], float(k), x[3:]] for k in (1, 2, 3)])
    tracker._refine_shape = refine_shape
    tracker._refine_all = lambda energy, y, init=False: y
    tracker._prepare = lambda energy, x=None, init=False: None
    tracker._objective = lambda energy, y, level: shaped.get(
        (0 if int(y[1]) == 3 else 4) + int(round(y[2])), 9000.0)
    winner, contender = (np.r_[0.0, float(i), np.zeros(24)] for i in (3, 11))
    y, swapped, start = tracker._shaped_winner([], None, winner, "the winner",
                                               (contender, "start 3 of 3 from its extremities"))
    assert (int(y[1]), int(round(y[2]))) == wins
    assert order == [(3, k) for k in range(4)] + [(11, k) for k in range(4)]
    assert start == note
    assert swapped == ("" if wins[0] == 11 or wins[1] == 0 else ", its arms swapped")


@pytest.mark.slow  # two start searches each: about a minute on 2 shared cores
@pytest.mark.parametrize("floor_band_m", [0.0, TrackConfig().floor_band_m])
def test_the_start_search_recovers_a_track_that_jumped(floor_band_m):
    """The same jumps with the real start search (from the last good pose and the visual hull,
    two upright starts). Nothing over 100 mm is trusted, and frame 8 (the walk again) is
    found again within 25 mm, where the tracker alone stays 60+ mm off (above).

    Without the floor band (this scene has no shadow) the pose shown is found again at once,
    at frame 6. With it (the default) the search fails there (measured, session 43): its
    best pose faces backwards, 504 mm off at 11.9% XOR against the truth's 3.4%, so frame 6
    is "diverged", and frame 7, still over the bar of before, is too (it was "tracked" at
    502 mm before session 43). Why it fails: the feet are in the band, so the legs' grid
    does not tell a knee folded back; and at this scene's 160x120 search level the limbs'
    grids (6 samples an angle over its whole range) keep 5-8 of 216 samples whose ends lie
    inside every silhouette, none near the arm held out."""
    config = TrackConfig(body="superquadric", init_headings=2, floor_band_m=floor_band_m)
    results, errors = _track_jumps(config)
    statuses = [r.status for r in results]
    trusted = [k for k, r in enumerate(results) if errors[k] > 100
               and r.status in ("init", "tracked", "recovered")]
    assert not trusted, (statuses, [round(e) for e in errors])
    assert statuses[8] == "recovered" and errors[8] < 25, (statuses, errors)
    if floor_band_m == 0:
        assert statuses[6] == "recovered", statuses
        assert max(errors[6:9]) < 25, errors


def _one_forearm_out(pose: Pose) -> Pose:
    """`pose` with the left elbow bent 90 degrees and the forearm held out in front."""
    values = pose.as_dict()
    values.update({"l_shoulder_rx": -0.3, "l_elbow_flex": 1.6})
    return Pose.from_dict(values)


def test_a_part_of_the_hull_the_body_leaves_out_is_flagged(tmp_path):
    """The silhouettes show the left forearm held out; the body posed with the arm hanging
    leaves that part of the visual hull out, on pixels it does not cover in several views:
    over `max_unexplained_share`. Posed as shown, nothing is left out. (The superquadric model
    on its own renders: the mechanism; the figures are the suite's, see the README.)"""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE, _masks, _walk
    from tracking.body.model import BodyModel

    hanging = _walk(1)[0]
    shown = _one_forearm_out(hanging)
    masks = _masks(shown)
    config = TrackConfig(body="superquadric")
    tracker = SilhouetteTracker(CAMERAS, config, shape=SHAPE)
    left_out = tracker.unexplained_share(masks, hanging)
    right = tracker.unexplained_share(masks, shown)
    assert left_out > 2 * config.max_unexplained_share and right == 0.0, (left_out, right)

    # A flagged frame: pose.json names it and keeps its share, the others' too.
    results = [dataclasses.replace(_result(0, "init"), unexplained_share=right),
               dataclasses.replace(_result(1, "tracked"), unexplained_share=left_out,
                                   unexplained=True),
               _result(2, "lost", pose=False)]
    outputs = {n: tmp_path / f"out.{n}" for n in ("joints", "pose", "bvh", "glb")}
    _write_outputs(outputs, results, BodyModel(SHAPE), 30.0, np.eye(3))
    written = json.loads(outputs["pose"].read_text())
    assert written["unexplained"] == [1]
    assert [f["unexplained_hull"] for f in written["frames"]] == [right, left_out, None]


def test_a_limb_the_hull_shows_elsewhere_is_searched_again():
    """From the arm hanging, the hull's part the body leaves out (the forearm held out) is
    next to the left shoulder: that arm is searched over its whole range, and the pose found
    leaves nothing out, at a lower XOR, the wrist within 50 mm of the truth (measured 31; 430
    hanging). A pose that leaves nothing out is returned as it is, and so is any pose with
    ``mend_unexplained`` off."""
    from tests.tracking.track.test_tracker import CAMERAS, SHAPE, _masks, _walk
    from tracking.body.model import node_positions_in_world

    def wrist_mm(pose: Pose) -> float:
        a, b = (node_positions_in_world(p, SHAPE)["l_wrist"] for p in (pose, shown))
        return 1000 * float(np.linalg.norm(a - b))

    hanging = _walk(1)[0]
    shown = _one_forearm_out(hanging)
    masks = _masks(shown)
    tracker = SilhouetteTracker(CAMERAS, TrackConfig(body="superquadric"), shape=SHAPE)
    energy = tracker._energy(masks)
    tracker._refine_all(energy, shown.params.copy(), init=True)  # the frame's priors and masks
    assert wrist_mm(hanging) > 300
    mended, note = tracker._mend_unexplained(energy, masks, hanging.params.copy())
    assert note.startswith("l arm searched again"), note
    assert energy(Pose(mended)) < energy(hanging)
    assert tracker.unexplained_share(masks, Pose(mended)) == 0.0
    assert wrist_mm(Pose(mended)) < 50, wrist_mm(Pose(mended))
    same = shown.params.copy()
    returned, note = tracker._mend_unexplained(energy, masks, same)
    assert returned is same and note == ""
    off = dataclasses.replace(TrackConfig(body="superquadric"), mend_unexplained=False)
    unmended = SilhouetteTracker(CAMERAS, off, shape=SHAPE)
    unmended._refine_all(energy, shown.params.copy(), init=True)
    kept = hanging.params.copy()
    returned, note = unmended._mend_unexplained(energy, masks, kept)
    assert returned is kept and note == ""
