"""`mocap track WS`: the silhouette tracker over a video workspace's sequence.

Reads the cameras (``WS/silhouettes/cameras.json`` as `mocap silhouettes` corrected them, else
``WS/cameras.json``) and ``WS/silhouettes/<camera>/<frame:06d>.png`` (from `mocap synth`
or `mocap silhouettes`) and writes, each atomically:

* ``tracks/joints.csv``: ``frame,joint,x,y,z``, metres, world frame, the joint names of
  `tracking.body.model.NODE_NAMES` (those of ``gt/joints.csv``); lost frames have no rows;
* ``tracks/pose.json``: ``{"frame_rate", "shape": {BodyShape}, "body": {"name": the body
  model plugin, and what rebuilds its subject, e.g. mpfb's "macro"}, "world_from_upright":
  (3, 3), "frames": [{"frame", "params" (26, POSE_LAYOUT order) or null when lost, "energy_px",
  "xor_fraction", "event", "status", "partly_out_of_view": [camera, ...],
  "unexplained_hull"}], "lost", "diverged", "recovered", "absent", "two_subjects",
  "partly_out_of_view", "unexplained": [frame, ...]}``:
  a frame's status is one of `tracking.track.tracker.STATUSES` (init, tracked, recovered,
  diverged: a pose kept but not trusted, lost: no pose, absent: no pose, no camera sees a
  subject, two-subjects: no pose, two subjects or more in view), and the lists name the
  frames of the last five (`status_lists`) and those where a camera's silhouette touches
  its image border (`FrameResult.cut_by`: the subject partly out of its view; a flag, not
  a status) and those whose visual hull has a part the body leaves out
  (`tracking.track.unexplained`; "unexplained_hull" is that part's share of the hull's
  surface, null when not checked: a limb is likely misplaced; a flag, not a status).
  Tracking starts at the first frame with a silhouette in some camera and one subject in
  view; frames before it are absent or two-subjects;
* ``tracks/motion.bvh``: the tracked frames on the body skeleton (`tracking.body.motion`); a
  BVH has no gaps, so a lost frame repeats the last tracked pose (pose.json says which);
* ``tracks/subject.glb``: the subject's mesh (the body model's full resolution) skinned on
  its skeleton with the tracked motion, a glTF 2.0 binary that Blender and three.js play
  (`tracking.body.gltf`; lost frames held as in the BVH);
* ``tracks/meshes/<frame:06d>.ply`` with ``--meshes``: that mesh posed in each tracked frame,
  world frame, metres;
* ``logs/track.rrd``: silhouettes and the XOR overlay per camera over the video frame
  (`TrackStepConfig.logged_images` of them), the body mesh and skeleton, the energy per
  frame, and each frame's status (``track/status``: a text log, lost, diverged, absent and
  two-subjects frames as warnings; ``track/status_index``: its index in `STATUSES`), on the
  ``frame`` and ``time`` timelines.

The poses, the BVH and the recording are in the *upright frame* of the camera rig
(`tracking.rig.cameras.upright_frame`): Y up, as the body model, BVH and OpenSim expect, and the
world rotated about its origin by ``world_from_upright``. An upright body then has a root
pitch near 0, far from the gimbal lock of the root's ZXY angles, which a Z-up world
(Qualisys, Pose2Sim) would put at its 90 degree pitch. ``joints.csv`` is in the world frame.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import functools
import io
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from recon.errors import UserError
from recon.parallel import Beside, settings_of, single_blas_thread, workers_for
from recon.progress import bar as progress_bar
from recon.workspace import Timer, Workspace, atomic_output, fingerprint, write_json_atomic
from tracking.body.model import BONES, NODE_NAMES, Pose, TrackedModel, pose_in_frame
from tracking.body.motion import read_pose_file
from tracking.rig.video import read_frames
from tracking.silhouettes.step import UNKNOWN_NAME
from tracking.track.render import render_views
from tracking.track.tracker import (
    STATUSES,
    FrameResult,
    SilhouetteTracker,
    TrackConfig,
    TrackingLost,
    subjects_in_view,
)


@dataclass(frozen=True, kw_only=True)
class TrackStepConfig:
    init_pose: Path | None = field(
        default=None,
        metadata={"help": "initial pose and shape (a pose file: tracks/pose.json, gt/pose.json "
                  "or mocap fit's fit.json; its first pose is used) instead of the automatic "
                  "initialisation",
                  "metavar": "FILE"},
    )  # fmt: skip
    first: int = field(default=0, metadata={"help": "first frame to track"})
    last: int | None = field(default=None, metadata={"help": "last frame to track (inclusive)"})
    meshes: bool = field(
        default=False,
        metadata={"help": "also write tracks/meshes/<frame:06d>.ply: the subject's full mesh "
                  "in each tracked frame (world frame, metres, with normals)"},
    )  # fmt: skip
    logged_images: int = field(
        default=10,
        metadata={"help": "video frames per camera logged under the XOR overlays of "
                  "logs/track.rrd, spread over the tracked frames (0: none; a workspace "
                  "without videos has none)"},
    )  # fmt: skip

    def __post_init__(self) -> None:
        if self.logged_images < 0:
            raise UserError(f"--logged-images must be >= 0, got {self.logged_images}")


def frame_rate_of(ws: Workspace) -> float:
    """The sequence's frame rate as recorded by `mocap synth` or `mocap init-video`."""
    steps = ws.read_run().get("steps", {})
    for step, key in (("synth", "frame_rate"), ("init-video", "fps")):
        value = steps.get(step, {}).get("summary", {}).get(key)
        if value:
            return float(value)
    return 30.0


def silhouette_frames(ws: Workspace, names: list[str]) -> list[int]:
    """Frame indices that every camera has a silhouette for; a one-line error otherwise."""
    per_camera = {}
    for name in names:
        folder = ws.silhouettes_dir / name
        if not folder.is_dir():
            raise UserError(f"{ws.root}: no silhouettes for camera {name}; run "
                            f"`mocap silhouettes {ws.root}` first")  # fmt: skip
        per_camera[name] = {int(p.stem) for p in folder.glob("*.png") if p.stem.isdigit()}
    counts = {name: len(frames) for name, frames in per_camera.items()}
    if len(set(map(frozenset, per_camera.values()))) > 1:
        raise UserError(f"{ws.root}: cameras have different silhouette frames ({counts})")
    frames = sorted(next(iter(per_camera.values())))
    if not frames:
        raise UserError(f"{ws.root}: no silhouette frames")
    return frames


def unknown_pixels(ws: Workspace, cameras: Sequence[Any]) -> list[np.ndarray | None]:
    """Per camera, its pixels of unknown background (``silhouettes/<camera>/unknown.png``,
    `tracking.silhouettes.step`), or None when it has none."""
    out: list[np.ndarray | None] = []
    for camera in cameras:
        path = ws.silhouettes_dir / camera.name / UNKNOWN_NAME
        out.append(_read_mask(path, camera) if path.exists() else None)
    return out


class HeldMasks:
    """The silhouettes of the frames a track back may still replace (`track_workspace` holds
    the last `SilhouetteTracker.back_frames`), bit-packed: 24 frames of 8 cameras at
    1920x1080 take 50 MB rather than 400. Given back as they were added, bit for bit."""

    def __init__(self) -> None:
        self._packed: dict[int, list[tuple[np.ndarray, tuple[int, ...]]]] = {}

    def add(self, frame: int, masks: Sequence[np.ndarray]) -> None:
        self._packed[frame] = [(np.packbits(m), m.shape) for m in masks]

    def masks(self, frame: int) -> list[np.ndarray]:
        """The silhouettes of `frame` (bool), as added; a KeyError when not held."""
        return [np.unpackbits(bits, count=int(np.prod(shape))).reshape(shape).view(bool)
                for bits, shape in self._packed[frame]]

    def pop(self, frame: int) -> list[np.ndarray]:
        """`masks` of `frame`, no longer held."""
        masks = self.masks(frame)
        del self._packed[frame]
        return masks


class FramesRead(Sequence[list[np.ndarray]]):
    """The silhouettes of `frames` (`masks_of`), read each time they are asked for and not
    held: a shape pass may read 3 times its frames (`calibrate_shape`), 1.2 GB at 1920x1080
    from 8 cameras."""

    def __init__(self, frames: Sequence[int], masks_of: Callable[[int], list[np.ndarray]]
                 ) -> None:  # fmt: skip
        self.frames, self.masks_of = list(frames), masks_of

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, index):  # type: ignore[override]  # (an index, not a slice)
        return self.masks_of(self.frames[index])


def _read_mask(path: Path, camera: Any) -> np.ndarray:
    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise UserError(f"{path}: not a readable image")
    if mask.shape != (camera.height, camera.width):
        raise UserError(f"{path}: {mask.shape[1]}x{mask.shape[0]} does not match camera "
                        f"{camera.name} ({camera.width}x{camera.height})")  # fmt: skip
    return mask > 127


def track_workspace(ws: Workspace, step: TrackStepConfig, config: TrackConfig, *,
                    overwrite: bool = False, progress: bool = True) -> dict[str, Any]:  # fmt: skip
    """Track the sequence of `ws`; returns the step summary."""
    from tracking.silhouettes.step import tracked_cameras

    cameras = tracked_cameras(ws)
    frames = [f for f in silhouette_frames(ws, [c.name for c in cameras])
              if f >= step.first and (step.last is None or f <= step.last)]  # fmt: skip
    if not frames:
        raise UserError(f"no silhouette frames between {step.first} and {step.last}")
    init_model, init_pose = None, None
    given = read_pose_file(step.init_pose) if step.init_pose is not None else None
    if given is not None:
        init_model = _model_of_pose_file(step.init_pose, given, config.body)
        init_pose = next((Pose(p) for _, p in given.frames if p is not None), None)
        if init_pose is None:
            raise UserError(f"{step.init_pose}: has no pose")
    upstream = [ws.step(n).fingerprint for n in ("synth", "silhouettes") if ws.step(n)]
    settings = {"step": dataclasses.asdict(step), "track": settings_of(config),
                "frames": [frames[0], frames[-1], len(frames)]}  # fmt: skip
    fp = fingerprint("track", settings, upstream)
    outputs = {"joints": ws.tracks_dir / "joints.csv", "pose": ws.tracks_dir / "pose.json",
               "bvh": ws.tracks_dir / "motion.bvh", "glb": ws.tracks_dir / "subject.glb",
               "rrd": ws.logs_dir / "track.rrd",
               **({"meshes": ws.tracks_dir / "meshes"} if step.meshes else {})}
    if done := ws.reusable("track", fp, *outputs.values(), overwrite=overwrite):
        return {**done.summary, "up_to_date": True}
    frame_rate = frame_rate_of(ws)

    def masks_of(frame: int) -> list[np.ndarray]:
        masks = [_read_mask(ws.silhouettes_dir / c.name / f"{frame:06d}.png", c) for c in cameras]
        if any(m.all() for m in masks):
            raise UserError(_all_foreground_message(ws, cameras, frames))
        return masks

    # The start: the first frame where some camera has a silhouette (the subject may enter
    # the view after the recording began) of one subject; the frames before it are absent or
    # show two subjects, and are refused as such.
    first, crowded, unknown = None, [], unknown_pixels(ws, cameras)
    for i, f in enumerate(frames):
        masks = masks_of(f)
        if not any(m.any() for m in masks):
            continue
        if len(subjects_in_view(cameras, masks, config, unknown)) >= 2:
            crowded.append(f)
            continue
        first = i
        break
    if first is None:
        from tracking.silhouettes.step import _ranges

        raise UserError(f"{ws.silhouettes_dir}: no silhouette in any camera in any of frames "
                        f"{frames[0]}-{frames[-1]}: nobody to track" if not crowded else
                        f"{ws.silhouettes_dir}: no frame shows one subject: two or more "
                        f"subjects are in view in frame(s) {_ranges(crowded, 1)} and nobody "
                        "in the others; track frames with one subject (--first/--last)")
    world_from_upright = _upright_frame(cameras, masks_of(frames[first]))
    if given is not None:
        assert init_pose is not None  # a file without a pose was refused above
        init_pose = pose_in_frame(init_pose, world_from_upright.T @ given.world_from_upright)
    upright = [c.in_frame(world_from_upright) for c in cameras]
    tracker = SilhouetteTracker(upright, config, model=init_model,
                                unknown=unknown,
                                frame_interval_s=1.0 / frame_rate)
    results: list[FrameResult] = []
    warnings: list[str] = []

    logged = {frames[i] for i in np.unique(np.linspace(
        0, len(frames) - 1, min(step.logged_images, len(frames))).round().astype(int))}
    shape_pass = Timer()  # its seconds stay 0 without a shape pass
    with (Timer() as timer, _Recorder(ws, upright, frame_rate, logged) as recorder,
          single_blas_thread()):
        if init_model is None and config.shape_frames > 1:
            # (A start over the bar moves the pass on, up to `shape_frames` - 1 frames, and a
            # second opinion at its end once more: those are read too, `calibrate_shape`.)
            shape_frames = frames[first:first + 3 * config.shape_frames]
            bar = progress_bar(min(len(shape_frames), config.shape_frames), "shape", "frame",
                               enabled=progress)
            try:
                with shape_pass:
                    init_pose = tracker.calibrate_shape(
                        FramesRead(shape_frames, masks_of), progress=bar.update,
                        frames=shape_frames)
            except TrackingLost as exc:
                raise UserError(f"cannot start tracking at frame {frames[first]}: {exc}"
                                ) from None
            bar.close()
            warnings.extend(_short_shape_pass(config, shape_frames, tracker.shape_frames_used))
        bar = progress_bar(len(frames), "track", "frame", enabled=progress)
        # The frames a track back may still replace (the opening, `track_back`; a divergence
        # or loss a later frame recovers from, `track_back_gap`: the last `back_frames`) are
        # held, their silhouettes kept, and recorded once it can no longer reach them: once.
        # A track back runs beside the track, in a forked process (`Beside`: it leaves the
        # tracker as it found it, so the track goes on alike), and the frames it may replace
        # wait for it; the next track back, which reads their statuses, waits for it too.
        opening_end = min(first + tracker.back_frames, len(frames)) - 1
        held = HeldMasks()  # frame -> its silhouettes, not yet recorded
        recorded, back_s = 0, 0.0  # results[:recorded] are in the recording
        workers = workers_for(config.workers)
        pending: tuple[int, Beside[dict[int, FrameResult]]] | None = None  # (from index, job)

        def settle() -> None:
            nonlocal pending
            if pending is not None:
                for i, again in pending[1].result().items():
                    results[i] = again
                pending = None

        for index, frame in enumerate(frames):
            masks = masks_of(frame)
            result = tracker.track(frame, masks, init=init_pose if index == first else None)
            results.append(result)
            held.add(frame, masks)
            bar.set_postfix_str(f"XOR {result.xor_fraction:.0%} {result.event}"[:40])
            bar.update()
            started = time.perf_counter()
            if pending is not None and pending[1].done():
                settle()
            backs = []  # (track back, the first index it may replace)
            if result.status == "recovered":  # (`track_back_gap` does nothing after others)
                bar.set_postfix_str("tracking back from the recovery")
                backs.append((tracker.track_back_gap, index + 1 - tracker.back_frames))
            if index == opening_end:
                # A start gone wrong that the track found its way out of: tracked again,
                # backwards, from the opening's frame of lowest XOR.
                bar.set_postfix_str("the opening again, backwards")
                backs.append((tracker.track_back, first))
            if backs:
                settle()
            for k, (track_back, reach) in enumerate(backs):
                job = Beside(functools.partial(track_back, list(results), held.masks), workers)
                pending = (max(reach, 0), job)
                if k + 1 < len(backs):
                    settle()  # the next one reads what this one replaces
            back_s += time.perf_counter() - started
            while (recorded < len(results) - tracker.back_frames
                   and (pending is None or recorded < pending[0])):
                recorder.frame(tracker, results[recorded], held.pop(results[recorded].frame))
                recorded += 1
        started = time.perf_counter()
        settle()
        back_s += time.perf_counter() - started
        for r in results[recorded:]:
            recorder.frame(tracker, r, held.pop(r.frame))
        bar.close()
    if tracker.model is None or all(r.pose is None for r in results):
        reasons = sorted({r.event.removeprefix("lost: ") for r in results})
        raise UserError(f"the subject was lost in every frame ({'; '.join(reasons[:3])}"
                        f"{'; ...' if len(reasons) > 3 else ''}); see {ws.log_path('track')}")
    _write_outputs(outputs, results, tracker.model, frame_rate, world_from_upright)
    tracked = [r for r in results if r.pose is not None]
    summary = {
        "frames": len(results), "tracked": len(tracked),
        "lost": [r.frame for r in results if r.status == "lost"],
        "absent": [r.frame for r in results if r.status == "absent"],
        "two_subjects": [r.frame for r in results if r.status == "two-subjects"],
        "partly_out_of_view": [r.frame for r in results if r.cut_by],
        "unexplained": [r.frame for r in results if r.unexplained],
        "diverged": [r.frame for r in results if r.status == "diverged"],
        "recovered": [r.frame for r in results if r.status == "recovered"],
        "events": {str(r.frame): r.event for r in results if r.event},
        "median_xor_fraction": float(np.median([r.xor_fraction for r in tracked])),
        "seconds_per_frame": timer.seconds / len(results),
        # Where the time went: the start and shape pass, once per sequence, then each frame.
        "shape_pass_seconds": shape_pass.seconds,
        # Tracking frames again backwards, from the opening's lowest XOR and from recoveries:
        # the time the track waited for it (beside the track, with workers, it takes more).
        "track_back_seconds": back_s,
        "tracking_seconds_per_frame": float(np.mean([r.seconds for r in results])),
        "evaluations_per_frame": float(np.mean([r.evaluations for r in results])),
        # Energy evaluations per second of the frames' tracking (the shape pass's not counted).
        "evaluations_per_second": float(sum(r.evaluations for r in results)
                                        / max(sum(r.seconds for r in results), 1e-9)),
        "height_m": tracker.model.shape.height, "frame_rate": frame_rate,
        "warnings": warnings,
        "body": tracker.model.record(),
    }
    ws.record_step("track", fp, outputs=list(outputs.values()), config=settings,
                   seconds=timer.seconds, summary=summary)
    return summary


def _short_shape_pass(config: TrackConfig, frames: list[int], used: list[int]) -> list[str]:
    """The warning for a shape pass that refined the segment lengths with fewer poses than a
    full one (`TrackConfig.shape_frames` frames, every `shape_stride`-th): a sequence shorter
    than the pass, or a subject lost in it. `frames`: the pass's frames; `used`: the indices
    into them of the poses it used."""
    full = len(range(0, config.shape_frames, config.shape_stride))
    if len(used) >= full:
        return []
    names = ", ".join(str(frames[i]) for i in used)
    why = (f"the sequence has {len(frames)} frames for --shape-frames {config.shape_frames}"
           if len(frames) < config.shape_frames else
           f"the sequence has {len(frames) - used[0]} frames from frame {frames[used[0]]}, "
           f"where the shape pass started (the start search before it was over the bar), "
           f"for --shape-frames {config.shape_frames}"
           if len(frames) - used[0] < config.shape_frames
           else f"the shape pass lost the subject after frame {frames[used[-1]]}")
    return [f"{why}: the body's shape comes from {len(used)} pose(s) (frame(s) {names}) "
            f"instead of {full}, and is less certain; track a longer sequence, or give a known "
            "shape with --init-pose"]


def _all_foreground_message(ws: Workspace, cameras: Sequence[Any], frames: list[int]) -> str:
    """The error for silhouettes that are foreground in every pixel, naming every camera and
    frame (of `frames`) with one: read again on this failure path only."""
    from tracking.silhouettes.step import _ranges

    full: dict[str, list[int]] = {}
    for camera in cameras:
        hits = [f for f in frames if _read_mask(
            ws.silhouettes_dir / camera.name / f"{f:06d}.png", camera).all()]
        if hits:
            full[camera.name] = hits
    where = "; ".join(f"{name} in frame(s) {_ranges(hits, 1)}"
                      + (f" (all {len(frames)})" if len(hits) == len(frames) else "")
                      for name, hits in full.items())  # fmt: skip
    return (f"{ws.silhouettes_dir}: every pixel is foreground in {where}: the background "
            f"model failed there, so no subject can be found; redo `mocap silhouettes "
            f"{ws.root}` (e.g. with frames of the empty scene: --background frames:A-B), or "
            "track other frames (--first/--last)")


def _model_of_pose_file(path: Path, given: Any, body: str) -> TrackedModel:
    """The body model an ``--init-pose`` file describes, for the tracker's ``body`` plugin; a
    one-line `UserError` when the file was written for another body model (its poses drive
    that model's rig, and its shape is that model's)."""
    from plugins.registry import create

    name = given.body["name"]
    if name != body:
        raise UserError(f"{path}: its pose and shape are for the body model {name!r}, not "
                        f"{body!r}; track with --body {name} or give a pose file of {body}")
    try:
        return create("body", body).model_from_record(given.body, given.shape)
    except ValueError as exc:
        raise UserError(f"{path}: its body entry does not describe a subject of the "
                        f"{body} model ({exc})") from None


def _upright_frame(cameras: Sequence[Any], masks: Sequence[np.ndarray]) -> np.ndarray:
    """`upright_frame` of the rig around the subject of the first frame's silhouettes (the
    identity when fewer than two views see it)."""
    from tracking.rig.cameras import upright_frame
    from tracking.silhouettes.hull import rays_meeting_point

    try:
        subject = rays_meeting_point(cameras, masks)
    except ValueError:
        return np.eye(3)
    return upright_frame(cameras, subject)


def status_lists(results: Sequence[FrameResult]) -> dict[str, list[int]]:
    """pose.json's summary of the frames' `FrameResult.status`: the frames lost (no pose),
    diverged (a divergence that the start search found nothing better for: the best pose is
    kept, but not trusted), recovered (found again by the start search after a divergence
    or after frames without a pose, or by the tracking after a divergence: back under the XOR
    of before it, the visual hull explained), absent (no pose: no camera has a silhouette) and
    two_subjects (no pose: two subjects or more in view, status "two-subjects")."""
    return {name.replace("-", "_"): [r.frame for r in results if r.status == name]
            for name in ("lost", "diverged", "recovered", "absent", "two-subjects")}


def _write_outputs(outputs: dict[str, Path], results: list[FrameResult], model: TrackedModel,
                   frame_rate: float, world_from_upright: np.ndarray) -> None:  # fmt: skip
    from tracking.body.bvh import write_bvh
    from tracking.body.motion import motion_from_poses

    outputs["joints"].parent.mkdir(parents=True, exist_ok=True)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["frame", "joint", "x", "y", "z"])
    for r in results:
        if r.pose is None:
            continue
        for name, xyz in zip(NODE_NAMES, model.joints(r.pose), strict=True):
            writer.writerow([r.frame, name, *(f"{v:.6f}" for v in world_from_upright @ xyz)])
    with atomic_output(outputs["joints"]) as partial:
        partial.write_text(text.getvalue())
    write_json_atomic(outputs["pose"], {
        "frame_rate": frame_rate,
        "shape": dataclasses.asdict(model.shape),
        "body": model.record(),
        "world_from_upright": world_from_upright.tolist(),
        **status_lists(results),
        "partly_out_of_view": [r.frame for r in results if r.cut_by],
        "unexplained": [r.frame for r in results if r.unexplained],
        "frames": [{"frame": r.frame,
                    "params": None if r.pose is None else [float(v) for v in r.pose.params],
                    "energy_px": None if not np.isfinite(r.energy) else r.energy,
                    "xor_fraction": None if not np.isfinite(r.energy) else r.xor_fraction,
                    "event": r.event, "status": r.status,
                    "partly_out_of_view": list(r.cut_by),
                    "unexplained_hull": r.unexplained_share} for r in results],
    })  # fmt: skip
    held: list[Pose] = []
    last = next(r.pose for r in results if r.pose is not None)
    for r in results:
        last = r.pose if r.pose is not None else last
        held.append(last)
    with atomic_output(outputs["bvh"]) as partial:
        write_bvh(motion_from_poses(held, model.shape, 1.0 / frame_rate), partial)
    write_subject_glb(outputs["glb"], model, held, frame_rate)
    if "meshes" in outputs:
        write_frame_meshes(outputs["meshes"], model, results, world_from_upright)


def write_frame_meshes(folder: Path, model: TrackedModel, results: Sequence[FrameResult],
                       world_from_upright: np.ndarray) -> None:  # fmt: skip
    """``folder``/<frame:06d>.ply for every tracked frame: the full mesh (`TrackedModel.skin`)
    posed in the world frame. Written into a sibling and renamed, replacing an older folder
    whole (no mesh of a frame no longer tracked is left behind)."""
    import shutil

    import open3d as o3d

    from recon.mesh.meshing import write_mesh

    skin = model.skin()
    partial = folder.with_name(folder.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    for r in results:
        if r.pose is None:
            continue
        vertices = skin.posed(*model.skin_pose(r.pose)) @ world_from_upright.T
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                         o3d.utility.Vector3iVector(skin.faces.astype(np.int32)))
        mesh.compute_vertex_normals()
        write_mesh(mesh, partial / f"{r.frame:06d}.ply", also=())
    shutil.rmtree(folder, ignore_errors=True)
    partial.rename(folder)


def write_subject_glb(path: Path, model: TrackedModel, poses: Sequence[Pose],
                      frame_rate: float) -> None:  # fmt: skip
    """``path`` (atomically): the subject's full mesh skinned on its skeleton, playing
    ``poses`` at ``frame_rate`` (`tracking.body.gltf`), in the poses' upright frame."""
    from tracking.body.gltf import write_skinned_glb

    skin = model.skin()
    animation = [model.skin_pose(p) for p in poses]
    with atomic_output(path) as partial:
        write_skinned_glb(partial, vertices_m=skin.vertices_m, faces=skin.faces,
                          normals=skin.normals, joint_names=skin.joint_names,
                          joint_parents=skin.joint_parents, joint_heads_m=skin.joint_heads_m,
                          skin_weights=skin.weights,
                          rotations=np.stack([r for r, _ in animation]),
                          root_translation_m=np.stack([t for _, t in animation]),
                          frame_rate=frame_rate, name=model.name)


class _Recorder:
    """logs/track.rrd, written as the frames are tracked."""

    def __init__(self, ws: Workspace, cameras: list[Any], frame_rate: float,
                 logged: set[int] = frozenset()) -> None:  # fmt: skip
        self.ws, self.cameras, self.frame_rate = ws, cameras, frame_rate
        self.logged = logged  # frames whose video images are logged under the overlays

    def __enter__(self) -> _Recorder:
        from recon import recording

        self.recording = recording
        self._context = recording.step_recording(self.ws.log_path("track"), "track")
        self.rec = self._context.__enter__()
        recording.log_y_up_world(self.rec)
        recording.log_skeleton_context(self.rec, "world/body/skeleton", NODE_NAMES, BONES)
        recording.log_xor_context(self.rec, "world/cameras")
        for cam in self.cameras:
            recording.log_camera_image(self.rec, image_name=cam.name, image_path=None, K=cam.K,
                                       width=cam.width, height=cam.height,
                                       cam_from_world=cam.cam_from_world)  # fmt: skip
        # The video frames of `logged`, read once in frame order (`frame` is called so).
        self._videos = {}
        if self.logged and self.ws.videos_dir.is_dir():
            for cam in self.cameras:
                with contextlib.suppress(UserError):  # a camera without its video: no images
                    self._videos[cam.name] = read_frames(self.ws, cam.name, sorted(self.logged))
        return self

    def frame(self, tracker: SilhouetteTracker, result: FrameResult, masks: list) -> None:
        r, t = self.recording, result.frame / self.frame_rate
        if result.frame in self.logged:
            for name, video in list(self._videos.items()):
                try:
                    index, image = next(video, (None, None))
                except UserError:  # the video ends early, or a frame does not decode
                    del self._videos[name]
                    continue
                if index == result.frame:
                    r.log_frame_image(self.rec, f"world/cameras/{r.entity_name(name)}/image",
                                      image, result.frame, t)  # fmt: skip
        # The frame's status as a text log (lost, diverged and absent frames as warnings) and
        # as a scalar (its index in STATUSES) on the frame timeline.
        level = "WARN" if result.status in ("lost", "diverged", "absent",
                                            "two-subjects") else "INFO"
        text = f"{result.status}: {result.event}" if result.event else result.status
        if result.cut_by:
            text += f" (partly out of view of {', '.join(result.cut_by)})"
        if result.unexplained:
            level = "WARN"
            text += (f" (the visual hull has a part the body leaves out, "
                     f"{result.unexplained_share:.1%} of its surface: a limb is likely "
                     "misplaced)")
        r.log_frame_text(self.rec, "track/status", text, level, result.frame, t)
        if result.unexplained_share is not None:
            r.log_frame_scalar(self.rec, "track/unexplained_hull", result.unexplained_share,
                               result.frame, t)  # fmt: skip
        r.log_frame_scalar(self.rec, "track/status_index", STATUSES.index(result.status),
                           result.frame, t)  # fmt: skip
        if result.pose is None or tracker.model is None:
            if np.isfinite(result.energy):
                r.log_frame_scalar(self.rec, "track/xor_fraction", result.xor_fraction,
                                   result.frame, t)  # fmt: skip
            return
        vertices, normals = tracker.model.posed_surface(result.pose)
        model_masks = render_views(tracker.renderer, vertices, tracker.model.faces, self.cameras)
        for cam, image, model in zip(self.cameras, masks, model_masks, strict=True):
            base = f"world/cameras/{r.entity_name(cam.name)}/image"
            r.log_xor_overlay(self.rec, f"{base}/xor", model, image, result.frame, t)
        r.log_mesh_frame(self.rec, "world/body/mesh", vertices, tracker.model.faces,
                         result.frame, t, normals)  # fmt: skip
        joints = tracker.model.joints(result.pose)
        r.log_skeleton_frame(self.rec, "world/body/skeleton", joints, result.frame, t)
        r.log_frame_scalar(self.rec, "track/xor_fraction", result.xor_fraction, result.frame, t)
        r.log_frame_scalar(self.rec, "track/energy_px", result.energy, result.frame, t)

    def __exit__(self, *exc: Any) -> None:
        self._context.__exit__(*exc)
