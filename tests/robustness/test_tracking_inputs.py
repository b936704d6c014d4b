"""Robustness rows for the tracking inputs (issue 23): impossible tracks given to `mocap report`
(a workspace's ``tracks/pose.json`` or a BVH clip) and silhouettes that are all foreground or
all background given to `mocap track`.

Inputs are made here, without ../shared/data: a 2 s walk of the body model (60 frames at
30 Hz, `tracking.body.synthetic.walking_poses`) written as a pose file or a body-skeleton BVH,
and a 4-frame, 2-camera, 200x150 video workspace of that walk from `mocap synth --clean`
(about a second), built once per session and copied per row.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.helpers import run_cli
from tests.robustness.harness import Case, assert_one_line_error, check_case, rows
from tests.robustness.scenes import cache_folder
from tracking.body.model import PARAM_INDEX, BodyShape
from tracking.body.synthetic import walking_poses

SHAPE = BodyShape.default(1.75)
FPS = 30.0
FRAMES = 60
VIDEO_FRAMES = 4
POSE = "ws/tracks/pose.json"


@functools.cache
def _walk_params() -> np.ndarray:
    """(FRAMES, N_POSE_PARAMS) the walk's pose parameters."""
    return np.stack([p.params for p in walking_poses(FRAMES, FPS, SHAPE)])


@functools.cache
def _walk_bvh() -> Path:
    from tracking.body.bvh import write_bvh
    from tracking.body.motion import motion_from_poses

    path = cache_folder() / "walk.bvh"
    write_bvh(motion_from_poses(walking_poses(FRAMES, FPS, SHAPE), SHAPE, 1 / FPS), path)
    return path


@functools.cache
def _video_ws() -> Path:
    """A `mocap synth` workspace: cam00 and cam01, frames 0-3, exact silhouettes."""
    from tracking.rig.synth import SynthConfig, synthesize

    root = cache_folder() / "video"
    synthesize(root, SynthConfig(bvh=_walk_bvh(), cameras=2, size="200x150",
                                 frames=VIDEO_FRAMES, clean=True))
    return root


# ---------------------------------------------------------------------------------------------
# Report inputs


def _track_data(frames: list[dict] | None = None, **changes) -> dict:
    frames = frames if frames is not None else [
        {"frame": k, "params": row.tolist()} for k, row in enumerate(_walk_params())]
    return {"frame_rate": FPS, "shape": dataclasses.asdict(SHAPE), "frames": frames, **changes}


def _write_track(folder: Path, data: dict) -> None:
    path = folder / POSE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))  # NaN and Infinity as Python's json writes them


def _track_with(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    """Setup: the walk's pose.json with `edit` applied to its data."""

    def setup(folder: Path) -> None:
        data = _track_data()
        edit(data)
        _write_track(folder, data)

    return setup


def _frame(index: int, **entry) -> Callable[[dict], None]:
    def edit(data: dict) -> None:
        data["frames"][index].update(entry)

    return edit


def _param(index: int, name: str, value: float) -> Callable[[dict], None]:
    def edit(data: dict) -> None:
        data["frames"][index]["params"][PARAM_INDEX[name]] = value

    return edit


def _steps(ws: Path) -> dict:
    run = ws / "run.json"
    return json.loads(run.read_text()).get("steps", {}) if run.is_file() else {}


def _refused_again(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    """The same command refuses again with the same line: nothing was left to reuse."""
    again = run_cli(*result.args[3:], cwd=folder)
    assert again.returncode == 2, again.stderr
    assert assert_one_line_error(again) == assert_one_line_error(result)


def _no_report(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    assert not (ws / "report").exists() and not (ws / "report.partial").exists()
    assert not (ws / "logs" / "report.rrd").exists() and "report" not in _steps(ws)


def _fixed_then_reported(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    """The same command refuses again; after the file is put right, the report runs (a fresh
    computation, not a reuse)."""
    _no_report(folder, result)
    _refused_again(folder, result)
    _write_track(folder, _track_data())
    fixed = run_cli("report", "ws", cwd=folder)
    assert fixed.returncode == 0, fixed.stderr
    assert "up to date" not in fixed.stdout and "1.20 m/s" in fixed.stdout
    assert _steps(folder / "ws")["report"]["summary"]["frames"] == FRAMES


def _reported_then_corrupted(folder: Path) -> None:
    """A good report exists; then the track is damaged (a frame number turns negative)."""
    from tracking.report.step import ReportConfig, report_from_workspace

    _write_track(folder, _track_data())
    report_from_workspace(folder / "ws", ReportConfig())
    data = _track_data()
    data["frames"][0]["frame"] = -3
    _write_track(folder, data)


def _old_report_not_trusted(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    # The refusal was not masked by the earlier report (its fingerprint is of the old file),
    # and running again still refuses rather than calling the old report up to date.
    assert "up to date" not in result.stdout
    _refused_again(folder, result)


def _edge_values_reported(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    summary = json.loads((folder / "ws" / "report" / "summary.json").read_text())
    assert summary["frames"] == FRAMES and summary["frames_with_data"] == FRAMES
    assert [(g["first_frame"], g["last_frame"]) for g in summary["gaps"]] == [(30, 30)]
    assert "report" in _steps(folder / "ws")


def _edge_values(data: dict) -> None:
    """What writers legitimately produce: a knee exactly at its limit (the tracker clips to
    the limits), an elbow past it by half the tolerance (text rounding), a lost frame written
    as NaN, and the entries in reverse order."""
    frames = data["frames"]
    frames[5]["params"][PARAM_INDEX["l_knee_flex"]] = 0.0
    frames[6]["params"][PARAM_INDEX["r_elbow_flex"]] = -0.5 * np.deg2rad(1e-3)
    frames[30]["params"] = [float("nan")] * 24
    frames.reverse()


REPORT_ROWS = [
    Case("report-frame-negative", lambda f: ("report", "ws"), _track_with(_frame(0, frame=-3)),
         message=r"pose\.json: frame -3 is not a frame number", inputs=[POSE],
         then=_fixed_then_reported),
    Case("report-frame-duplicated", lambda f: ("report", "ws"),
         _track_with(_frame(11, frame=10)),
         message=r"pose\.json: frame 10 appears more than once", inputs=[POSE], then=_no_report),
    Case("report-frame-huge", lambda f: ("report", "ws"), _track_with(_frame(59, frame=10**9)),
         message=r"pose\.json: frames 0 to 1000000000 span 1000000001 frames.*--max-frames",
         inputs=[POSE], then=_no_report),
    Case("report-joint-1e300", lambda f: ("report", "ws"),
         _track_with(_param(10, "l_knee_flex", 1e300)),
         message=r"pose\.json: frame 10: l_knee_flex = 5\.72958e\+301 deg is outside its joint "
                 r"limits 0\.\.150 deg", inputs=[POSE], then=_no_report),
    Case("report-root-1e300", lambda f: ("report", "ws"),
         _track_with(_param(10, "root_tx", 1e300)),
         message=r"pose\.json: frame 10: root_tx = 1e\+300 m is beyond the \+-1000 m",
         inputs=[POSE], then=_no_report),
    Case("report-param-nan", lambda f: ("report", "ws"),
         _track_with(_param(4, "spine_flex", float("nan"))),
         message=r"pose\.json: frame 4: spine_flex is nan", inputs=[POSE], then=_no_report),
    Case("report-corrupted-after-a-good-report", lambda f: ("report", "ws"),
         _reported_then_corrupted, message=r"pose\.json: frame -3 is not a frame number",
         inputs=[POSE, "ws/report"], then=_old_report_not_trusted, marks=[pytest.mark.slow]),
    Case("report-legitimate-edge-values", lambda f: ("report", "ws"), _track_with(_edge_values),
         rc=0, inputs=[POSE], then=_edge_values_reported),
]


# ---------------------------------------------------------------------------------------------
# BVH inputs (frames have no numbers in a BVH: only the values can be wrong)


def _bvh_with(frame: int, column: int, value: str) -> Callable[[Path], None]:
    """Setup: ``clip.bvh``, the walk with one channel value of one frame replaced."""

    def setup(folder: Path) -> None:
        lines = _walk_bvh().read_text().splitlines()
        first = lines.index("MOTION") + 3
        row = lines[first + frame].split()
        row[column] = value
        lines[first + frame] = " ".join(row)
        (folder / "clip.bvh").write_text("\n".join(lines) + "\n")

    return setup


def _no_bvh_report(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    assert not (folder / "out" / "report").exists()


def _no_bvh_report_refused_again(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    _no_bvh_report(folder, result)
    _refused_again(folder, result)


def _bvh_args(folder: Path) -> tuple[str, ...]:
    return ("report", "--bvh", "clip.bvh", "--out", "out")


# Columns of the body BVH: 0-2 the root position (metres), 3-5 its ZXY rotation, 6-8 the spine.
BVH_ROWS = [
    Case("bvh-root-position-1e300", _bvh_args, _bvh_with(10, 0, "1e300"),
         message=r"clip\.bvh: frame 10: root_tx = 1e\+300 m is beyond the \+-1000 m",
         inputs=["clip.bvh"], then=_no_bvh_report_refused_again),
    Case("bvh-rotation-1e300", _bvh_args, _bvh_with(10, 8, "1e300"),
         message=r"clip\.bvh: frame 10: Yrotation of spine is 1e\+300 degrees",
         inputs=["clip.bvh"], then=_no_bvh_report),
    Case("bvh-rotation-nan", _bvh_args, _bvh_with(10, 4, "nan"),
         message=r"clip\.bvh:\d+: non-finite number", inputs=["clip.bvh"],
         then=_no_bvh_report),
]


# ---------------------------------------------------------------------------------------------
# Track inputs


def _video_with(value: int, cameras: tuple[str, ...], frames: tuple[int, ...] = ()
                ) -> Callable[[Path], None]:  # fmt: skip
    """Setup: the video workspace with the silhouettes of `cameras` (in `frames`, default
    all) set to `value` (255: every pixel foreground; 0: empty)."""

    def setup(folder: Path) -> None:
        ws = folder / "ws"
        shutil.copytree(_video_ws(), ws)
        for camera in cameras:
            for path in sorted((ws / "silhouettes" / camera).glob("0*.png")):
                if not frames or int(path.stem) in frames:
                    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
                    cv2.imwrite(str(path), np.full_like(mask, value))

    return setup


def _nothing_tracked(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    assert not (ws / "tracks").exists() and not (ws / "logs" / "track.rrd").exists()
    assert "track" not in _steps(ws)


def _nothing_tracked_nor_reported(folder: Path, result: subprocess.CompletedProcess[str]
                                  ) -> None:  # fmt: skip
    """Nothing tracked; the same command refuses again, and the report finds no track."""
    _nothing_tracked(folder, result)
    _refused_again(folder, result)
    report = run_cli("report", "ws", cwd=folder)  # nothing tracked: nothing to report
    assert report.returncode == 2 and "track the sequence first" in assert_one_line_error(report)


def _lost_everywhere(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    # Every frame lost: no outputs and no step, though the recording shows what was tried.
    ws = folder / "ws"
    assert not (ws / "tracks").exists() and "track" not in _steps(ws)


def _video_and_impossible_init_pose(folder: Path) -> None:
    _video_with(0, ())(folder)
    bad = _track_data([{"frame": 0, "params": [0.0, 1e300] + [0.0] * 22}])
    (folder / "bad.json").write_text(json.dumps(bad))


TRACK = ("track", "ws")
INIT = ("--init-pose", "ws/gt/pose.json")
TRACK_ROWS = [
    Case("track-one-camera-all-foreground", lambda f: TRACK, _video_with(255, ("cam01",)),
         message=r"every pixel is foreground in cam01 in frame\(s\) 0-3 \(all 4\): the "
                 r"background model failed", inputs=["ws/silhouettes"],
         then=_nothing_tracked_nor_reported),
    Case("track-all-cameras-all-foreground", lambda f: TRACK,
         _video_with(255, ("cam00", "cam01")),
         message=r"every pixel is foreground in cam00 in frame\(s\) 0-3 \(all 4\); cam01 in "
                 r"frame\(s\) 0-3 \(all 4\)", inputs=["ws/silhouettes"], then=_nothing_tracked),
    Case("track-some-frames-all-foreground", lambda f: TRACK,
         _video_with(255, ("cam00",), (1, 3)),
         message=r"every pixel is foreground in cam00 in frame\(s\) 1, 3: ",
         inputs=["ws/silhouettes"], then=_nothing_tracked),
    Case("track-one-camera-empty", lambda f: TRACK, _video_with(0, ("cam01",)),
         message=r"cannot start tracking at frame 0: empty silhouette in cam01$",
         inputs=["ws/silhouettes"], then=_nothing_tracked),
    Case("track-all-cameras-empty", lambda f: TRACK, _video_with(0, ("cam00", "cam01")),
         message=r"no silhouette in any camera in any of frames 0-3: nobody to track$",
         inputs=["ws/silhouettes"], then=_nothing_tracked),
    Case("track-one-camera-empty-with-init-pose", lambda f: (*TRACK, *INIT),
         _video_with(0, ("cam01",)),
         message=r"the subject was lost in every frame \(empty silhouette in cam01\)",
         inputs=["ws/silhouettes", "ws/gt"], then=_lost_everywhere),
    Case("track-init-pose-impossible", lambda f: (*TRACK, "--init-pose", "bad.json"),
         _video_and_impossible_init_pose,
         message=r"bad\.json: frame 0: root_ty = 1e\+300 m is beyond", inputs=["bad.json"],
         then=_nothing_tracked),
]


# ---------------------------------------------------------------------------------------------
# Slow rows: the tracker runs (about 2 s a frame from a given pose at 200x150)


def _last_frame_lost(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    """The lost frame is said (stderr warning, stdout, pose.json null, run.json), and the
    tracker's own pose.json (limits reached or not) is what the report then reads."""
    ws = folder / "ws"
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert [f["params"] is None for f in pose["frames"]] == [False, False, False, True]
    assert "lost: empty silhouette in cam00" in pose["frames"][3]["event"]
    assert _steps(ws)["track"]["summary"]["lost"] == [3]
    assert "lost       frames [3]" in result.stdout
    report = run_cli("report", "ws", "--cutoff-hz", "0", cwd=folder)
    assert report.returncode == 0, report.stderr
    summary = json.loads((ws / "report" / "summary.json").read_text())
    assert summary["frames"] == 4 and summary["frames_with_data"] == 3


SLOW_ROWS = [
    Case("track-last-frame-empty-is-lost-and-said", lambda f: (*TRACK, *INIT),
         _video_with(0, ("cam00",), (VIDEO_FRAMES - 1,)), rc=0,
         message=r"(?m)^warning: the subject was lost in 1 of 4 frames",
         inputs=["ws/silhouettes", "ws/gt"], then=_last_frame_lost,
         marks=[pytest.mark.slow]),
]


ROWS = [*REPORT_ROWS, *BVH_ROWS, *TRACK_ROWS, *SLOW_ROWS]


@pytest.mark.parametrize("case", rows(ROWS))
def test_tracking_input(case: Case, tmp_path: Path) -> None:
    check_case(case, tmp_path)
