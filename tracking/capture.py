"""`mocap capture`: synchronised videos and their calibration to a motion report, in one call.

The steps, each the library function of its own command and with its defaults::

    init-video   tracking.rig.video.init_video          WS/cameras.json, WS/videos/
    silhouettes  tracking.silhouettes.step.make_silhouettes   WS/silhouettes/
    track        tracking.track.step.track_workspace     WS/tracks/
    report       tracking.report.step.report_from_workspace   WS/report/

A re-run resumes: each step keeps its own rule for reuse (init-video: the same videos, by path,
size and time, and the same calibration, by content; the others: their fingerprint in
``WS/run.json``, which chains the settings of the steps they read, and their outputs on disk;
the report: its settings and the content of ``tracks/pose.json``), so only what changed and
what follows it runs again; ``overwrite`` recomputes everything. A step that fails raises one
`UserError` line, ``"<step>: <why>"``; the steps before it stay finished (a re-run reuses them)
and the failed step leaves no output, each step writing atomically.

`CaptureCommand` is the ``mocap capture`` subcommand (plugin kind ``command``). `mocap --help`
imports this module to list it, so the pipeline is imported inside the functions only.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from recon.errors import UserError

if TYPE_CHECKING:
    from recon.workspace import StepRecord, Workspace
    from tracking.report.step import ReportConfig, ReportSummary
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig

STEPS = ("init-video", "silhouettes", "track", "report")
_T = TypeVar("_T")


class VideoMatch(enum.StrEnum):
    """How `init_video` pairs cameras and videos (`tracking.rig.video`)."""

    NAME = "name"
    ORDER = "order"


@dataclass(frozen=True, kw_only=True)
class CaptureConfig:
    """Settings of `mocap capture` itself; each step has its own config. Field help is the
    CLI's help."""

    match: VideoMatch = field(
        default=VideoMatch.NAME,
        metadata={"help": "pair cameras and videos by name (video file name = camera name, any "
                  "case, '_' and '-' ignored) or by order (Pose2Sim's rule)"})
    copy: bool = field(
        default=False, metadata={"help": "copy the videos into the workspace instead of "
                                 "hard-linking them"})


@dataclass(frozen=True)
class StepOutcome:
    """One step of a capture: what it did, in one line, and where its outputs are."""

    step: str
    text: str
    """The outcome without the step name, e.g. ``12/12 frames tracked, ...``."""
    outputs: str
    reused: bool
    seconds: float
    notes: tuple[str, ...] = ()
    """Warnings and notes of the step, one line each."""

    def line(self) -> str:
        took = "(reused)" if self.reused else f"({self.seconds:.1f} s)"
        return f"{self.step:<12}{self.text} {took}  {self.outputs}"


@dataclass(frozen=True)
class CaptureResult:
    """What `capture` made (or found finished) in ``root``."""

    root: Path
    steps: tuple[StepOutcome, ...]
    track: dict[str, Any]
    """The track step's summary (`track_workspace`)."""
    report: ReportSummary

    def outcome(self, step: str) -> StepOutcome:
        return next(s for s in self.steps if s.step == step)

    @property
    def recordings(self) -> list[Path]:
        """The workspace's Rerun recordings, ``WS/logs/*.rrd``."""
        from recon.workspace import Workspace

        return Workspace(self.root).recordings()

    def lines(self) -> list[str]:
        """The summary `mocap capture` prints: a line per step with its outputs, its notes,
        the recordings and how to view them."""
        out: list[str] = []
        for step in self.steps:
            out.append(step.line())
            out += [f"{'':<12}{note}" for note in step.notes]
        names = ", ".join(p.name for p in self.recordings)
        out += [f"{'recordings':<12}{self.root / 'logs'}/ ({names})",
                f"{'view':<12}mocap view {self.root}"]
        return out


def _run(step: str, fn: Callable[..., _T], *args: Any, **kwargs: Any) -> _T:
    """``fn(*args, **kwargs)``, its one-line failure prefixed by the step's name."""
    from plugins.registry import PluginError

    try:
        return fn(*args, **kwargs)
    except (UserError, PluginError) as exc:
        raise UserError(f"{step}: {' '.join(str(exc).split())}") from exc


def capture(
    ws_root: Path | str,
    videos_dir: Path | str,
    calibration_path: Path | str,
    *,
    background_images: Path | str | None = None,
    config: CaptureConfig | None = None,
    silhouettes: SilhouettesConfig | None = None,
    track_step: TrackStepConfig | None = None,
    track: TrackConfig | None = None,
    report: ReportConfig | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> CaptureResult:
    """Videos in ``videos_dir`` (one per camera of ``calibration_path``) → the video workspace
    ``ws_root`` → silhouettes → tracked motion → motion report (module docstring).

    ``background_images``: a folder of photos of the empty scene, one or more per camera (the
    silhouettes' ``--background-images``; it replaces ``silhouettes.background_images``). The
    step configs default to their commands' defaults. Raises `UserError` ``"<step>: <why>"``.
    """
    from recon.workspace import Workspace
    from tracking.report.step import ReportConfig, report_from_workspace
    from tracking.rig.video import STEP as INIT_STEP
    from tracking.rig.video import init_video
    from tracking.silhouettes.step import SilhouettesConfig, make_silhouettes
    from tracking.track.step import TrackStepConfig, track_workspace
    from tracking.track.tracker import TrackConfig

    config = config or CaptureConfig()
    silhouettes = silhouettes or SilhouettesConfig()
    if background_images is not None:
        silhouettes = _run("silhouettes", dataclasses.replace, silhouettes,
                           background_images=Path(background_images))
    report = report or ReportConfig()
    if report.truth:
        raise UserError("report: a capture reports the tracked motion; report a synthetic "
                        "sequence's truth with `mocap report WS --truth`")
    ws = Workspace(ws_root)

    def init_record() -> dict[str, Any] | None:
        # init_video reports no reuse; its run record, unchanged, tells it.
        return ws.read_run().get("steps", {}).get(INIT_STEP) if ws.run_json.is_file() else None

    before = _run(INIT_STEP, init_record)
    ws = _run(INIT_STEP, init_video, ws.root, videos_dir, calibration_path,
              match=config.match.value, copy=config.copy, overwrite=overwrite)
    after = _run(INIT_STEP, init_record)
    assert after is not None  # init_video records its step
    steps = [_init_outcome(ws, after, reused=before == after)]

    record = _run("silhouettes", make_silhouettes, ws, silhouettes, overwrite=overwrite)
    steps.append(_silhouettes_outcome(ws, record))

    tracked = _run("track", track_workspace, ws, track_step or TrackStepConfig(),
                   track or TrackConfig(), overwrite=overwrite, progress=progress)
    steps.append(_track_outcome(ws, tracked))

    reported = _run("report", report_from_workspace, ws.root, report, overwrite=overwrite)
    steps.append(_report_outcome(reported))
    return CaptureResult(ws.root, tuple(steps), tracked, reported)


# ---------------------------------------------------------------------------------------------
# One line per step


def _init_outcome(ws: Workspace, record: dict[str, Any], *, reused: bool) -> StepOutcome:
    s = record["summary"]
    return StepOutcome(
        "init-video", f"{len(s['cameras'])} cameras x {s['frames']} frames at {s['fps']:g} fps",
        f"{ws.cameras_path}, {ws.videos_dir}", reused, record["seconds"],
        tuple(f"note: {n}" for n in s.get("notes", [])))


def _silhouettes_outcome(ws: Workspace, record: StepRecord) -> StepOutcome:
    import numpy as np

    from tracking.silhouettes.step import camera_correction_text

    s = record.summary
    # A correction is news; cameras kept as calibrated are not (`mocap silhouettes` says both).
    correction = (camera_correction_text(ws, s)
                  if s.get("camera_correction", {}).get("accepted") else None)  # fmt: skip
    median = float(np.median([c["foreground_fraction"]["median"]
                              for c in s["cameras"].values()]))  # fmt: skip
    return StepOutcome(
        "silhouettes", f"{len(s['cameras'])} cameras x {s['processed']} frames, foreground "
        f"{median:.1%} of the image (median)", str(ws.silhouettes_dir),
        bool(s.get("up_to_date")), record.seconds,
        (*((f"note: cameras {correction}",) if correction else ()),
         *(f"warning: {w}" for w in s.get("warnings", []))))


def _track_outcome(ws: Workspace, s: dict[str, Any]) -> StepOutcome:
    notes = ((f"lost frames {s['lost']}",) if s["lost"] else ()) + (
        (f"absent frames {s['absent']} (no subject in view)",) if s.get("absent") else ()) + (
        (f"two-subject frames {s['two_subjects']} (not tracked)",)
        if s.get("two_subjects") else ()) + tuple(f"warning: {w}" for w in s.get("warnings", []))
    return StepOutcome(
        "track", f"{s['tracked']}/{s['frames']} frames tracked, median XOR "
        f"{s['median_xor_fraction']:.1%} of the silhouette, subject height {s['height_m']:.2f} m",
        f"{ws.tracks_dir}/joints.csv, pose.json, motion.bvh, subject.glb",
        bool(s.get("up_to_date")),
        s["seconds_per_frame"] * s["frames"], notes)


def _report_outcome(result: ReportSummary) -> StepOutcome:
    s = result.summary
    return StepOutcome(
        "report", f"{s['frames']} frames at {s['frame_rate']:.4g} Hz, {s['duration_s']:.2f} s",
        f"{result.report_dir / 'index.html'}, CSVs, motion.trc", result.reused,
        float(sum(s.get("seconds", {}).values())), tuple(f"note: {n}" for n in s["notes"]))
