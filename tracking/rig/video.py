"""Video workspaces: synchronised multi-camera videos and their calibration (`mocap init-video`).

Layout (read by the silhouettes step and the tracker)::

    WS/
      cameras.json              the calibrated cameras, `tracking.rig.cameras` JSON, one per video
      videos/<camera>.<ext>     the input videos, hard-linked or copied, never written
      run.json                  step ``init-video``: sources, frame count, fps, adjustments

Frames are decoded with OpenCV (its FFmpeg backend) and only ever read.

Matching cameras to videos (``match``):

* ``name`` (default): a camera goes with the video whose file stem equals its name, ignoring
  case and the separators ``_``, ``-`` and spaces (``cam01`` <-> ``CAM01.mp4``, and
  Pose2Sim's ``Calib.toml`` names ``cam_01`` <-> ``cam01.mp4``). The Pose2Sim demo's
  ``Calib.qca.txt`` names its cameras by their ``serial`` attribute, which is ``cam01`` ...
  ``cam04``, the stems of its videos.
* ``order``: Pose2Sim's own rule, for calibrations whose names say nothing (numeric Qualisys
  serials): the k-th camera in calibration file order goes with the k-th video, videos sorted
  by the last number in their name (``cam2`` before ``cam10``), then by name.

Either way the pairing must be one-to-one, or the error lists both sides. The workspace uses
the calibration's camera names: ``videos/<camera name>.<ext>``.

Checks, each a one-line `UserError`: at least 2 cameras; every video decodes and all have the
same frame count; every video has its camera's image size. One exception to the size rule, met
in the Pose2Sim demo: a video that is the calibrated image scaled to fit, aspect ratio kept,
and padded with black bars (cam01 and cam02 there: 1088x1920 images scaled by 1080/1088 to
1080x1906 with 7 black rows above and below, measured by aligning each video with its camera's
extrinsic calibration shot). It is accepted only when the bars are really black in the first
frame, and its camera is rewritten for the video: ``K`` scaled by s and shifted by the bar
widths (with pixel centres at +0.5, image corners map to corners, so ``x_video = s * x_calib +
pad``); distortion acts on normalised coordinates and is unchanged. ``content_box`` in the
step summary keeps the region that holds the image.
"""

from __future__ import annotations

import math
import os
import re
import shutil
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from recon.cameras import Camera, write_cameras_json
from recon.errors import UserError
from recon.sfm.images import IMAGE_SUFFIXES
from recon.workspace import Timer, Workspace, atomic_output, file_digest, fingerprint
from tracking.rig.cameras import read_cameras

# FFmpeg prints its own complaints about a broken file to stderr, around our one-line error that
# names it; quiet unless the user asks (OPENCV_FFMPEG_LOGLEVEL=32). Read when FFmpeg is first
# used in the process.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

STEP = "init-video"
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".webm", ".wmv",
                  ".mts")
MATCH_RULES = ("name", "order")

# Letterbox bars: darkest content that still counts as a black bar (8-bit grey levels). Video
# codecs lift black to 16 in limited range and ring next to edges, hence a mean *and* a
# percentile bound rather than exact zeros.
_BAR_MEAN_MAX = 16.0
_BAR_P95_MAX = 40.0


@dataclass(frozen=True)
class VideoInfo:
    """What OpenCV reports about one video (frames counted, not guessed)."""

    frames: int
    width: int
    height: int
    fps: float


def _open(path: Path) -> cv2.VideoCapture:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise UserError(f"cannot open video {path} (not a video OpenCV's FFmpeg reads, "
                        "or corrupt)")
    return capture


def _count_by_decoding(capture: cv2.VideoCapture) -> int:
    capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
    count = 0
    while capture.grab():
        count += 1
    return count


def video_info(path: Path | str) -> tuple[int, int, int, float]:
    """(frame count, width, height, fps) of a video; a one-line error when it does not decode.

    The container's frame count is verified by decoding its last frame and failing to decode
    one more; when either check fails the frames are counted by decoding them all.
    """
    info = _video_info(Path(path))
    return info.frames, info.width, info.height, info.fps


def _video_info(path: Path) -> VideoInfo:
    capture = _open(path)
    try:
        width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        claimed = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        count = -1
        if claimed > 0:
            capture.set(cv2.CAP_PROP_POS_FRAMES, claimed - 1)
            if capture.grab() and not capture.grab():
                count = claimed
        if count < 0:
            count = _count_by_decoding(capture)
    finally:
        capture.release()
    if count == 0 or width <= 0 or height <= 0:
        raise UserError(f"video {path} has no decodable frame")
    return VideoInfo(count, width, height, fps if math.isfinite(fps) and fps > 0 else 0.0)


def _first_frame(path: Path) -> np.ndarray:
    capture = _open(path)
    try:
        ok, frame = capture.read()
    finally:
        capture.release()
    if not ok:
        raise UserError(f"video {path} has no decodable frame")
    return frame


# Frame access ----------------------------------------------------------------------------------


def video_path(ws: Workspace, camera_name: str) -> Path:
    """The workspace's video of one camera, ``videos/<camera name>.<ext>``."""
    found = [p for p in ws.videos_dir.iterdir()
             if p.stem == camera_name and p.suffix.lower() in VIDEO_SUFFIXES
             ] if ws.videos_dir.is_dir() else []  # fmt: skip
    if len(found) != 1:
        what = "no video" if not found else f"{len(found)} videos"
        raise UserError(f"{ws.videos_dir} holds {what} for camera {camera_name}; "
                        f"recreate the workspace with mocap init-video {ws.root} --overwrite ...")
    return found[0]


def read_frames(ws: Workspace, camera_name: str, frames: Iterable[int] | None = None
                ) -> Iterator[tuple[int, np.ndarray]]:  # fmt: skip
    """Decoded frames of one camera's video as (0-based index, (H, W, 3) uint8 BGR), in
    increasing index order; ``frames``: the indexes wanted (any order, duplicates ignored), or
    None for every frame. Frames in between are skipped without being converted.

    A requested frame past the end of the video is a `UserError`, after the frames before it.
    """
    return read_video_frames(video_path(ws, camera_name), frames)


def read_video_frames(path: Path, frames: Iterable[int] | None = None
                      ) -> Iterator[tuple[int, np.ndarray]]:  # fmt: skip
    """`read_frames` of the video file at ``path`` (in a workspace or not)."""
    wanted = None if frames is None else sorted({int(i) for i in frames})
    if wanted and wanted[0] < 0:
        raise UserError(f"frame indexes are 0-based; got {wanted[0]}")
    if wanted == []:
        return
    capture = _open(path)
    try:
        index, position = 0, 0  # position: next entry of `wanted`
        while True:
            if not capture.grab():
                if wanted is None:
                    return
                raise UserError(f"video {path} ends after {index} frames; frame "
                                f"{wanted[position]} was asked for")
            if wanted is None or index == wanted[position]:
                ok, frame = capture.retrieve()
                if not ok:
                    raise UserError(f"video {path}: frame {index} does not decode")
                yield index, frame
                if wanted is not None:
                    position += 1
                    if position == len(wanted):
                        return
            index += 1
    finally:
        capture.release()


def workspace_cameras(ws: Workspace) -> list[Camera]:
    """The cameras of a video workspace (cameras.json), as `UserError` when unreadable."""
    try:
        return read_cameras(Workspace.open_video(ws.root).cameras_path)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def content_box(ws: Workspace, camera: Camera) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1), end exclusive: the part of the camera's frames that holds the image
    (all of it, unless `init_video` found black bars)."""
    record = ws.step(STEP)
    if record is not None:
        box = record.summary.get("cameras", {}).get(camera.name, {}).get("content_box")
        if box is not None:
            return tuple(int(v) for v in box)  # type: ignore[return-value]
    return 0, 0, camera.width, camera.height


# Matching cameras to videos --------------------------------------------------------------------


def _find_videos(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise UserError(f"video folder {folder} does not exist" if not folder.exists()
                        else f"{folder} is a file; --videos takes a folder of videos")
    videos = sorted(p for p in folder.iterdir()
                    if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES)
    if not videos:
        raise UserError(f"no videos ({', '.join(VIDEO_SUFFIXES)}) in {folder}")
    stems: dict[str, Path] = {}
    for p in videos:
        key = _stem_key(p.stem)
        if key in stems:
            raise UserError(f"{stems[key].name} and {p.name} in {folder} have the same name; "
                            "keep one video per camera")
        stems[key] = p
    return videos


def _last_number(path: Path) -> tuple[int, str]:
    numbers = re.findall(r"\d+", path.stem)
    return (int(numbers[-1]) if numbers else -1, path.name)


def _name_key(camera_name: str) -> str:
    """What a video stem must equal once both are keyed: the camera name, less an image
    extension (COLMAP names cameras by their image, ``cam01.jpg``), lower case, without the
    separators ``_``, ``-`` and spaces (Pose2Sim's ``cam_01`` for ``cam01.mp4``)."""
    stem, dot, suffix = camera_name.rpartition(".")
    if dot and f".{suffix.lower()}" in IMAGE_SUFFIXES:
        camera_name = stem
    return _stem_key(camera_name)


_SEPARATORS = "_- "


def _stem_key(stem: str) -> str:
    return "".join(ch for ch in stem.lower() if ch not in _SEPARATORS)


def name_in_file_name(camera_name: str) -> re.Pattern[str]:
    """A pattern that finds a camera's name as a word in a lower-case file stem, keyed like the
    videos (case and separators ignored): ``cam01_ext`` names cam01 and cam_01, not cam010."""
    between = "[" + re.escape(_SEPARATORS) + "]?"
    body = between.join(re.escape(ch) for ch in _stem_key(camera_name))
    return re.compile(rf"(?<![0-9a-z]){body}(?![0-9a-z])")


def match_videos(cameras: list[Camera], videos: list[Path], rule: str = "name"
                 ) -> list[tuple[Camera, Path]]:  # fmt: skip
    """Pairs (camera, video), in calibration order, by the module's matching ``rule``."""
    if rule not in MATCH_RULES:
        raise UserError(f"unknown camera matching rule {rule!r} (choose {', '.join(MATCH_RULES)})")
    for camera in cameras:
        if "/" in camera.name or "\\" in camera.name:
            raise UserError(f"camera name {camera.name!r} cannot name a video file; give a "
                            "calibration with one camera per video, named like the videos")
    lower = [_name_key(c.name) for c in cameras]
    if len(set(lower)) != len(lower):
        raise UserError("the calibration has camera names that differ only in case or "
                        "separators: "
                        + ", ".join(c.name for c in cameras))
    videos = sorted(videos, key=lambda p: p.name)
    both_sides = (f"calibration cameras: {', '.join(c.name for c in cameras)}; "
                  f"videos: {', '.join(p.name for p in videos)}")
    if rule == "order":
        if len(cameras) != len(videos):
            raise UserError(f"{len(cameras)} calibrated camera(s) but {len(videos)} video(s); "
                            f"matching by order needs as many of each ({both_sides})")
        return list(zip(cameras, sorted(videos, key=_last_number), strict=True))
    by_stem = {_stem_key(p.stem): p for p in videos}
    pairs = [(c, by_stem[key]) for c, key in zip(cameras, lower, strict=True) if key in by_stem]
    if len(pairs) != len(cameras) or len(pairs) != len(videos):
        cams = [c.name for c, key in zip(cameras, lower, strict=True) if key not in by_stem]
        vids = [p.name for p in videos if _stem_key(p.stem) not in lower]
        unmatched = "; ".join(part for part in (
            f"no video for camera(s) {', '.join(cams)}" if cams else "",
            f"no camera for video(s) {', '.join(vids)}" if vids else "") if part)
        raise UserError(f"cameras and videos do not match one-to-one by name (video file name = "
                        f"camera name, any case, '_' and '-' ignored): {unmatched} "
                        f"({both_sides}); rename the videos, "
                        "or pair them in calibration order with --match order")
    return pairs


# Size check and letterboxed videos ---------------------------------------------------------------


def _letterbox(frame: np.ndarray, camera: Camera) -> tuple[float, float, float] | None:
    """(s, pad_x, pad_y) when ``frame`` is the camera's image scaled by s to fit, centred, with
    black bars of pad_x, pad_y pixels on either side; None when it is not."""
    height, width = frame.shape[:2]
    s = min(width / camera.width, height / camera.height)
    pad_x, pad_y = (width - s * camera.width) / 2, (height - s * camera.height) / 2
    # Rows/columns wholly inside a bar, less one for the edge the codec smears.
    bar_x, bar_y = int(pad_x - 0.5), int(pad_y - 0.5)
    if max(bar_x, bar_y) < 1:
        return None
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    bars = (grey[:, :bar_x], grey[:, width - bar_x:]) if bar_x >= 1 else (
        grey[:bar_y], grey[height - bar_y:])
    for bar in bars:
        if bar.mean() > _BAR_MEAN_MAX or np.percentile(bar, 95) > _BAR_P95_MAX:
            return None
    return s, pad_x, pad_y


def _camera_for_video(camera: Camera, scale: float, pad_x: float, pad_y: float, width: int,
                      height: int) -> Camera:  # fmt: skip
    # Pixel centres at +0.5: the image's corner (0, 0) lands on (pad_x, pad_y), so
    # x_video = s * x_calib + pad_x for every point, and K's first two rows follow.
    K = np.diag([scale, scale, 1.0]) @ camera.K
    K[0, 2] += pad_x
    K[1, 2] += pad_y
    return Camera(camera.name, width, height, K, camera.cam_from_world, camera.dist)


# The step ---------------------------------------------------------------------------------------


def _file_identity(path: Path) -> dict[str, Any]:
    stat = path.stat()
    return {"path": str(path.resolve()), "bytes": stat.st_size, "mtime_ns": stat.st_mtime_ns}


def _calibration_digest(path: Path) -> str:
    """Content digest of a calibration file, or of a calibration folder's files (a COLMAP
    model) with their names."""
    if not path.is_dir():
        return file_digest(path)
    return fingerprint({p.relative_to(path).as_posix(): file_digest(p)
                        for p in sorted(path.rglob("*")) if p.is_file()})


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def init_video(ws_root: Path | str, videos_dir: Path | str, calibration: Path | str, *,
               match: str = "name", copy: bool = False, overwrite: bool = False) -> Workspace:
    """Make a video workspace: cameras.json from ``calibration`` (COLMAP model folder,
    Qualisys ``.qca.txt``, Pose2Sim ``Calib.toml`` or ``mocap-cameras-v1`` JSON) and
    ``videos/<camera>.<ext>`` linked (or copied, ``copy=True`` or across file systems) from the
    videos in ``videos_dir``.

    Everything is checked before the workspace is touched. A workspace that already holds
    exactly these inputs is reused; one holding others needs ``overwrite``, which also removes
    what was derived from them (silhouettes, tracks, ground truth). cameras.json is written
    last, so an interrupted run leaves no workspace that `Workspace.open_video` accepts.
    The step summary (``ws.step("init-video").summary``) holds per camera the source, frame
    count, size, fps, content box and any note.
    """
    ws = Workspace(ws_root)
    if ws.root.exists() and not ws.root.is_dir():
        raise UserError(f"workspace path {ws.root} is a file, not a folder")
    source_dir = Path(videos_dir)
    calibration = Path(calibration)
    videos = _find_videos(source_dir)
    try:
        cameras = read_cameras(calibration)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    pairs = match_videos(cameras, videos, match)
    if len(pairs) < 2:
        raise UserError(f"need at least 2 cameras to track in 3D; {calibration} and "
                        f"{source_dir} give {len(pairs)}")
    settings = {"match": match, "calibration": str(calibration.resolve()),
                "calibration_sha256": _calibration_digest(calibration),
                "videos": {c.name: _file_identity(p) for c, p in pairs}}
    fp = fingerprint(STEP, settings)
    outputs = [ws.cameras_path, *(ws.videos_dir / f"{c.name}{p.suffix.lower()}"
                                  for c, p in pairs)]
    if ws.reusable(STEP, fp, *outputs, overwrite=overwrite) is not None:
        return ws
    if (ws.cameras_path.exists() or ws.videos_dir.exists()) and not overwrite:
        raise UserError(f"{ws.root} already holds other videos or cameras; use a new workspace "
                        "or --overwrite")

    with Timer() as timer:
        infos = {c.name: _video_info(p) for c, p in pairs}
        counts = {infos[c.name].frames for c, _ in pairs}
        if len(counts) > 1:
            listed = ", ".join(f"{p.name} {infos[c.name].frames}" for c, p in pairs)
            raise UserError(f"the videos have different frame counts ({listed}); synchronised "
                            "cameras need the same frames: trim them to a common range")
        written: list[Camera] = []
        per_camera: dict[str, dict[str, Any]] = {}
        for camera, path in pairs:
            info = infos[camera.name]
            entry: dict[str, Any] = {
                "video": f"{camera.name}{path.suffix.lower()}", "source": str(path.resolve()),
                "frames": info.frames, "width": info.width, "height": info.height,
                "fps": info.fps, "content_box": [0, 0, info.width, info.height]}
            if (info.width, info.height) != (camera.width, camera.height):
                fit = _letterbox(_first_frame(path), camera)
                if fit is None:
                    raise UserError(
                        f"camera {camera.name}: video {path.name} is {info.width}x{info.height} "
                        f"but {calibration.name} calibrates {camera.width}x{camera.height} "
                        "(and the video is not that image scaled to fit with black bars); "
                        "use the calibration of these videos")
                scale, pad_x, pad_y = fit
                calibrated = f"{camera.width}x{camera.height}"
                camera = _camera_for_video(camera, scale, pad_x, pad_y, info.width, info.height)
                x0, y0 = math.ceil(pad_x - 1e-6), math.ceil(pad_y - 1e-6)
                entry["content_box"] = [x0, y0, info.width - x0, info.height - y0]
                bars = (f"{pad_y:.2f} px top and bottom" if pad_y > pad_x
                        else f"{pad_x:.2f} px left and right")
                entry["note"] = (f"{path.name} ({info.width}x{info.height}) is the calibrated "
                                 f"{calibrated} image scaled by {scale:.5f} with black bars of "
                                 f"{bars}; camera {camera.name} is adjusted to match")
            written.append(camera)
            per_camera[camera.name] = entry
        fps = sorted({round(i.fps, 3) for i in infos.values()})
        notes = [e["note"] for e in per_camera.values() if "note" in e]
        if len(fps) > 1:
            notes.append(f"the videos report different frame rates ({', '.join(map(str, fps))} "
                         "fps); frames are paired by index")

        ws.root.mkdir(parents=True, exist_ok=True)
        # From here on the workspace is not a video workspace until cameras.json is back.
        _remove(ws.cameras_path)
        with atomic_output(ws.videos_dir) as tmp:
            tmp.mkdir()
            for camera, path in pairs:
                target = tmp / per_camera[camera.name]["video"]
                if copy:
                    shutil.copy2(path, target)
                else:
                    try:
                        os.link(path, target)
                    except OSError:
                        shutil.copy2(path, target)
        for stale in (ws.silhouettes_dir, ws.tracks_dir, ws.gt_dir, ws.run_json):
            _remove(stale)
        write_cameras_json(ws.cameras_path, written)
    ws.record_step(STEP, fp, outputs=outputs, config=settings, seconds=timer.seconds, summary={
        "cameras": per_camera, "frames": counts.pop(), "fps": fps[0], "notes": notes})
    return ws

