"""`mocap demo`: the three modules on generated data with known answers, in a few minutes.

1. Photos (`recon.demo.run_demo`): a synthetic textured room photographed by known cameras →
   sparse model → dense cloud → mesh, with the focal length, pose errors and mesh accuracy
   against the truth. Workspace ``OUT/``.
2. Self-calibration (`recon.calibration.compare.compare_intrinsics`, `mocap compare`): every
   focal initialiser on the same photos' features and matches, against the true cameras
   (``OUT/scene/truth.json``). In ``OUT/compare/``.
3. Motion (`tracking.capture.capture`): mocap synth's default subject (MakeHuman's body,
   shorter and heavier than the tracker's average start, in 2 cm of clothes) walking the
   stride of a 1.68 m skeleton diagonally (`tracking.body.synthetic.walking_poses`), filmed
   by a ring of cameras (`mocap synth --videos --clean`: ``OUT/motion/synth/``, its truth in
   ``gt/`` and ``silhouettes/``), then
   captured from those videos and their calibration to a motion report
   (``OUT/motion/capture/``), scored against the truth: joint errors (MPJPE) and the IoU of
   the silhouettes with the exact renders (`tracking.rig.synth_video.capture_scores`).

Every step resumes as its command does: a second run reuses everything. ``OUT/evaluation.json``
holds the photo figures, ``OUT/motion/evaluation.json`` the capture's.

`DemoCommand` is the ``mocap demo`` subcommand; `mocap --help` imports this module to list it,
so the pipeline is imported inside the functions only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from recon.errors import UserError

if TYPE_CHECKING:
    from recon.calibration.compare import Comparison
    from recon.demo import DemoConfig, DemoReport
    from recon.sfm.pipeline import SfMConfig
    from tracking.capture import CaptureResult
    from tracking.rig.synth import SynthSummary
    from tracking.rig.synth_video import CaptureScores

MOTION_DIR = "motion"
"""``OUT/motion/``: the synthetic sequence (``synth/``) and its capture (``capture/``)."""
_SUBJECT_HEIGHT_M = 1.68  # the skeleton of the walk that drives the subject
_FRAME_RATE = 30.0


@dataclass(frozen=True, kw_only=True)
class MotionDemoConfig:
    """What the demo adds to the photo demo (`recon.demo.DemoConfig`). Field help is the
    CLI's help."""

    compare: bool = field(
        default=True,
        metadata={"help": "compare the focal initialisers on the demo's photos against the "
                  "true cameras (mocap compare; --no-compare to skip)"})
    capture: bool = field(
        default=True,
        metadata={"help": "film a synthetic walk with a ring of cameras and capture it from "
                  "the videos to a motion report, scored against the truth (--no-capture to "
                  "skip)"})
    capture_frames: int = field(
        default=12, metadata={"help": "frames of the synthetic walk, at 30 Hz (10 or more: "
                              "the report's low-pass filter needs them)"})
    capture_size: str = field(
        default="320x240", metadata={"help": "image size of the synthetic videos, WxH",
                                     "metavar": "WxH"})
    capture_cameras: int = field(
        default=4, metadata={"help": "cameras on the ring around the walk (2 or more)"})

    def __post_init__(self) -> None:
        if self.capture_frames < 10:
            raise UserError(f"--capture-frames {self.capture_frames}: the report needs at "
                            "least 10 frames")
        if self.capture_cameras < 2:
            raise UserError(f"--capture-cameras {self.capture_cameras}: need at least 2 "
                            "cameras to track in 3D")


@dataclass(frozen=True)
class MotionDemo:
    """Part 3 of the demo: the synthetic sequence, its capture and the scores."""

    synth: SynthSummary
    capture: CaptureResult
    scores: CaptureScores

    def lines(self) -> list[str]:
        return [*self.synth.lines()[:1], *self.capture.lines(), *self.scores.lines()]


@dataclass(frozen=True)
class FullDemoReport:
    """What `run_demo` did: the photo demo's report, and the comparison and the capture when
    they ran."""

    out: Path
    photos: DemoReport
    comparison: Comparison | None
    motion: MotionDemo | None

    def lines(self) -> list[str]:
        out = list(self.photos.lines())
        if self.comparison is not None:
            out += ["", "focal initialisers on the same matches (mocap compare), against the "
                    "true cameras:",
                    *(f"  {line}" if line else "" for line in self.comparison.lines())]
        if self.motion is not None:
            out += ["", "motion capture of a synthetic walk from its videos (mocap synth "
                    "--videos, then mocap capture):", *self.motion.lines()]
        return [*out, "", *self.where()]

    def where(self) -> list[str]:
        """Where each picture, recording and report is, a line each."""
        out = self.out
        pictures = [out / "mesh" / "preview.png"] if self.photos.mesh is not None else []
        reports = [out / "evaluation.json"]
        recordings = [sorted((out / "logs").glob("*.rrd"))]
        if self.comparison is not None:
            pictures += [p for k, p in self.comparison.outputs.items() if k.endswith("_png")]
            reports.append(self.comparison.outputs["report"])
        if self.motion is not None:
            report = self.motion.capture.report.report_dir
            pictures += sorted(report.glob("*.png")) + sorted(report.glob("*.svg"))
            reports += [report / "index.html", out / MOTION_DIR / "evaluation.json"]
            recordings += [sorted((self.motion.synth.root / "logs").glob("*.rrd")),
                           self.motion.capture.recordings]
        lines = [f"picture     {p}" for p in pictures]
        lines += [f"recording   {group[0].parent}/ ({', '.join(p.name for p in group)})"
                  for group in recordings if group]
        lines += [f"report      {p}" for p in reports]
        return lines


def _walk_bvh(path: Path, frames: int) -> Path:
    """The subject's motion as a body-model BVH (what `mocap synth` reads), written unless the
    file holds it already."""
    from tracking.body.bvh import format_bvh, write_bvh
    from tracking.body.model import BodyShape
    from tracking.body.motion import motion_from_poses
    from tracking.body.synthetic import walking_poses

    shape = BodyShape.default(_SUBJECT_HEIGHT_M)
    motion = motion_from_poses(walking_poses(frames, _FRAME_RATE, shape), shape,
                               1.0 / _FRAME_RATE)
    if not (path.is_file() and path.read_text() == format_bvh(motion)):
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bvh(motion, path)
    return path


def run_capture_demo(out: Path | str, config: MotionDemoConfig | None = None, *,
                     seed: int = 0, overwrite: bool = False,
                     progress: bool = True) -> MotionDemo:  # fmt: skip
    """Part 3 of the demo in ``out`` (``OUT/motion/``): synthesise the walk and its videos,
    capture it, score it against the truth; also writes ``out/evaluation.json``."""
    from plugins.registry import create
    from recon.workspace import write_json_atomic
    from tracking.body.motion import read_pose_file
    from tracking.capture import capture
    from tracking.rig.synth import SynthConfig, synthesize
    from tracking.rig.synth_video import RENDER_DIR, capture_scores

    config = config or MotionDemoConfig()
    out = Path(out)
    bvh = _walk_bvh(out / "walk.bvh", config.capture_frames)
    synth = synthesize(out / "synth", SynthConfig(
        bvh=bvh, cameras=config.capture_cameras, size=config.capture_size, clean=True,
        videos=True, seed=seed), overwrite=overwrite)
    render = synth.root / RENDER_DIR
    # New videos (the settings changed) replace those of the capture workspace.
    result = capture(out / "capture", render / "videos", synth.root / "cameras.json",
                     background_images=render / "backgrounds",
                     overwrite=overwrite or not synth.reused, progress=progress)
    scores = capture_scores(result.root, synth.root)
    truth = read_pose_file(synth.root / "gt" / "pose.json")
    subject = create("body", truth.body["name"]).model_from_record(truth.body, truth.shape)
    write_json_atomic(out / "evaluation.json", {
        "scores": scores.as_dict(), "config": dataclasses.asdict(config),
        "subject_height_m": subject.shape.height,
        "tracked_height_m": result.track["height_m"],
        "median_xor_fraction": result.track["median_xor_fraction"]})
    return MotionDemo(synth, result, scores)


def run_demo(
    config: DemoConfig,
    motion: MotionDemoConfig | None = None,
    sfm_config: SfMConfig | None = None,
    dense_config: Any = None,
    mesh_config: Any = None,
    *,
    overwrite: bool = False,
    progress: bool = True,
) -> FullDemoReport:
    """The whole demo (module docstring) in ``config.out``."""
    from recon.calibration.compare import CompareConfig, compare_intrinsics
    from recon.demo import run_demo as run_photo_demo
    from recon.sfm.pipeline import SfMConfig
    from recon.workspace import Workspace

    motion = motion or MotionDemoConfig()
    sfm_config = sfm_config or SfMConfig()
    photos = run_photo_demo(config, sfm_config, dense_config, mesh_config, overwrite=overwrite)
    comparison = None
    if motion.compare:
        comparison = compare_intrinsics(
            Workspace.open(config.out), sfm_config,
            CompareConfig(gt=config.out / "scene" / "truth.json"), overwrite=overwrite)
    captured = None
    if motion.capture:
        captured = run_capture_demo(config.out / MOTION_DIR, motion, seed=config.seed,
                                    overwrite=overwrite, progress=progress)
    return FullDemoReport(Path(config.out), photos, comparison, captured)
