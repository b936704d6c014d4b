"""Rerun recordings of every step. This is the only module that imports rerun.

Conventions, stated once here and used everywhere:

- One recording per step, saved to ``WS/logs/<step>.rrd`` (application id ``mocap``), written to
  a ``.partial`` file and renamed when complete.
- Entity tree: ``world/points``; ``world/cameras/<image>`` carries the camera pose;
  ``world/cameras/<image>/image`` carries the ``Pinhole`` and the photo; its child
  ``.../image/keypoints`` the 2D observations. Children inherit their parent's transform.
- COLMAP poses are ``cam_from_world``; they are logged with
  ``relation=ChildFromParent`` (the camera entity is the child, the world its parent), as a
  rotation matrix, so no quaternion order is involved (COLMAP files store quaternions wxyz,
  pycolmap's ``Rotation3d.quat`` is xyzw, Rerun's ``Quaternion`` is xyzw).
- Camera axes are RDF (x right, y down, z forward), as in COLMAP and OpenCV. The world frame is
  COLMAP's arbitrary model frame, shown as right-handed Y-down like its cameras.
- Photos are logged JPEG-encoded and downscaled to at most ``MAX_LOGGED_IMAGE_SIZE`` pixels; the
  ``Pinhole`` is scaled to match, so that rays still hit the same pixels. Lens distortion is not
  modelled by ``Pinhole``: the photo is shown as captured.
- Anything constant (cameras, photos, the final model) is logged ``static=True``; progress
  curves go on sequence timelines (``image``, ``pair``, ``registration``), one timeline per
  recording's curves, so that the timeline its blueprint shows holds every curve (values per
  item that are not a progress, such as each image's reprojection error, are bar charts).
- Each step's recording carries its default blueprint (`BLUEPRINTS`), the layout the viewer
  opens it with, and its own application id (``mocap-<step>``): the viewer shares one blueprint
  between the recordings of an application id, and `mocap view` opens them all at once.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import tempfile
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from recon.workspace import atomic_output

APP_ID = "mocap"
MAX_LOGGED_IMAGE_SIZE = 1024


def application_id(step: str) -> str:
    """The application id of a step's recordings: one per step, because the viewer gives every
    recording of an application id the same blueprint."""
    return f"{APP_ID}-{step}"


_logged_cameras: dict[int, list[str]] = {}
"""The camera entities (``world/cameras/<name>``) logged so far into each open step recording
(by ``id`` of its stream), which its blueprint lays out."""


@contextlib.contextmanager
def step_recording(path: Path, step: str) -> Iterator[rr.RecordingStream]:
    """A recording stream saved atomically to ``path``, with the step's default blueprint
    (`BLUEPRINTS`) sent when the block ends without an error.

    Raises :class:`~recon.errors.UserError` when the file cannot be written in full (a full
    disk), after the block; ``path`` is then left as it was.
    """
    with atomic_output(path) as tmp, _checked_sink(tmp, path) as sink:
        rec = rr.RecordingStream(application_id(step),
                                 recording_id=f"{step}-{path.parent.parent.name}")
        rec.save(sink)
        rec.send_recording_name(step)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Y_DOWN, static=True)
        _logged_cameras[id(rec)] = []
        try:
            yield rec
            # Sent last, as it lays out the cameras the step logged: a blueprint is a store of
            # its own in the file, so its place in the stream does not matter.
            blueprint = default_blueprint(step, _logged_cameras[id(rec)])
            if blueprint is not None:
                rec.send_blueprint(blueprint, make_active=True, make_default=True)
        finally:
            _logged_cameras.pop(id(rec), None)
            try:
                rec.flush()
            finally:
                rec.disconnect()  # closes the FIFO: the copier reads to its end and stops


_RRD_FOOTER = b"RRF2FOOT"
"""How a complete .rrd file of rerun-sdk 0.41 ends (then a 4-byte version): a file cut short
by a failed write does not."""


class _Copier(threading.Thread):
    """Copies what Rerun writes into a FIFO to the real file, and keeps any write error.

    Rerun's own file sink cannot fail safely: once a write fails (a full disk), its flush waits
    forever and so does dropping the stream (rerun-sdk 0.41, measured; issue 23 saw a 12-minute
    hang). Behind a FIFO, Rerun's writes always succeed; this thread does the real writes, and
    after a failure it goes on reading (and dropping) so that Rerun never blocks.
    """

    def __init__(self, fifo: Path, target: Path) -> None:
        super().__init__(daemon=True, name=f"rrd-copy-{target.name}")
        self.fifo, self.target = fifo, target
        self.error: OSError | None = None
        self.opened = False
        self.tail = b""

    def run(self) -> None:
        try:
            source = open(self.fifo, "rb")  # noqa: SIM115 - closed below, after draining
        except OSError as exc:
            self.error = exc
            return
        self.opened = True
        with source:
            try:
                sink = open(self.target, "wb")  # noqa: SIM115
            except OSError as exc:
                self.error, sink = exc, None
            try:
                while chunk := source.read(1 << 20):
                    self.tail = (self.tail + chunk)[-16:]
                    if sink is not None and self.error is None:
                        try:
                            sink.write(chunk)
                        except OSError as exc:
                            self.error = exc
                if sink is not None and self.error is None:
                    sink.flush()
                    os.fsync(sink.fileno())
            except OSError as exc:
                self.error = self.error or exc
            finally:
                if sink is not None:
                    try:
                        sink.close()
                    except OSError as exc:
                        self.error = self.error or exc

    def release(self) -> None:
        """End the thread when Rerun never opened the FIFO (its ``save`` failed)."""
        with contextlib.suppress(OSError):
            os.close(os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK))


@contextlib.contextmanager
def _checked_sink(tmp: Path, path: Path) -> Iterator[Path]:
    """The path for Rerun to save to, so that writing ``tmp`` is checked (see `_Copier`).

    Where FIFOs do not exist (Windows), Rerun writes ``tmp`` itself and only the footer of the
    result is checked.
    """
    from recon.errors import UserError

    if not hasattr(os, "mkfifo"):
        yield tmp
        copier = None
    else:
        with tempfile.TemporaryDirectory(prefix="mocap-rrd-") as folder:
            fifo = Path(folder) / "stream.rrd"
            os.mkfifo(fifo)
            copier = _Copier(fifo, tmp)
            copier.start()
            try:
                yield fifo
            finally:
                # Rerun has closed the FIFO (disconnect) by now, so an opened copier ends as
                # soon as it has written the rest; one still waiting for Rerun is released.
                if not copier.opened:
                    copier.release()
                copier.join(timeout=5.0)
                if copier.is_alive() and copier.opened:
                    copier.join()
    if copier is not None and copier.error is not None:
        exc = copier.error
        why = ("no space left on the device" if exc.errno == errno.ENOSPC
               else exc.strerror or str(exc))
        raise UserError(f"cannot write the recording {path}: {why}")
    tail = copier.tail if copier is not None else _tail(tmp)
    if tail[-12:-4] != _RRD_FOOTER:
        raise UserError(f"cannot write the recording {path}: it was left incomplete")


def _tail(path: Path) -> bytes:
    try:
        with open(path, "rb") as handle:
            handle.seek(max(path.stat().st_size - 16, 0))
            return handle.read()
    except OSError:
        return b""


def entity_name(image_name: str) -> str:
    """An entity path part for an image name (no slashes or dots, which Rerun parses)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", image_name)


def _encoded_image(path: Path, size: tuple[int, int], scale: float) -> rr.EncodedImage | None:
    """The photo for the viewer, or None when it is not on disk (a model made without photos).

    Small JPEG and PNG files are logged as their own bytes (no decode, no quality loss); larger
    ones are downscaled and re-encoded as JPEG to keep recordings small.
    """
    if not path.is_file():
        return None
    media = {".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".png": "image/png"}
    if scale >= 1.0 and path.suffix.lower() in media:
        return rr.EncodedImage(contents=path.read_bytes(), media_type=media[path.suffix.lower()])
    image = thumbnail(path, size, scale)
    if image is None:
        return None
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg") if ok else None


def thumbnail(path: Path, size: tuple[int, int], scale: float) -> np.ndarray | None:
    """BGR pixels of the photo (full ``size`` = (w, h)) resized by ``scale``, or None."""
    # JPEG decoders can scale by 1/2, 1/4, 1/8 while decoding (DCT scaling): several times
    # faster than decoding full size, which dominated logging time for large photos.
    flag = cv2.IMREAD_COLOR
    for factor, reduced_flag in ((8, cv2.IMREAD_REDUCED_COLOR_8), (4, cv2.IMREAD_REDUCED_COLOR_4),
                                 (2, cv2.IMREAD_REDUCED_COLOR_2)):
        if scale * factor <= 1.0:
            flag = reduced_flag
            break
    image = cv2.imread(str(path), flag)
    if image is None:
        return None
    # Exactly the size the Pinhole is logged with (a reduced decode rounds sides up).
    target = (round(size[0] * scale), round(size[1] * scale))
    if (image.shape[1], image.shape[0]) != target:
        image = cv2.resize(image, target, interpolation=cv2.INTER_AREA)
    return image


def _display_scale(width: int, height: int) -> float:
    return min(1.0, MAX_LOGGED_IMAGE_SIZE / max(width, height))


def log_camera_image(
    rec: rr.RecordingStream,
    *,
    image_name: str,
    image_path: Path | None,
    K: np.ndarray,
    width: int,
    height: int,
    cam_from_world: np.ndarray | None = None,
    points2D: np.ndarray | None = None,
) -> None:
    """Log one camera: pose (if known), pinhole, photo (unless ``image_path`` is None) and
    keypoints (``points2D``: (N, 2) px).

    ``K`` is the 3x3 calibration in pixels of the full-size image.
    """
    base = f"world/cameras/{entity_name(image_name)}"
    if base not in (logged := _logged_cameras.get(id(rec), [])):
        logged.append(base)
    if cam_from_world is not None:
        rec.log(
            base,
            rr.Transform3D(
                mat3x3=cam_from_world[:, :3],
                translation=cam_from_world[:, 3],
                relation=rr.TransformRelation.ChildFromParent,
            ),
            static=True,
        )
    scale = _display_scale(width, height)
    K_display = np.diag([scale, scale, 1.0]) @ K
    pinhole = rr.Pinhole(
        image_from_camera=K_display,
        resolution=[round(width * scale), round(height * scale)],
        camera_xyz=rr.ViewCoordinates.RDF,
        image_plane_distance=0.5,
    )
    photo = None if image_path is None else _encoded_image(image_path, (width, height), scale)
    rec.log(f"{base}/image", pinhole, *([photo] if photo is not None else []), static=True)
    if points2D is not None and len(points2D):
        rec.log(
            f"{base}/image/keypoints",
            rr.Points2D(np.asarray(points2D) * scale, radii=1.5, colors=[40, 220, 40]),
            static=True,
        )


def log_points(
    rec: rr.RecordingStream,
    points_in_world: np.ndarray,
    colors: np.ndarray | None = None,
    entity: str = "world/points",
) -> None:
    """``points_in_world``: (N, 3); ``colors``: (N, 3) uint8 RGB."""
    rec.log(entity, rr.Points3D(points_in_world, colors=colors, radii=-1.5), static=True)


def log_mesh(
    rec: rr.RecordingStream,
    entity: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    vertex_colors: np.ndarray | None = None,
    vertex_normals: np.ndarray | None = None,
) -> None:
    """A triangle mesh: ``vertices`` (V, 3) world, ``faces`` (F, 3) int, colours (V, 3) in
    [0, 1] float or uint8, normals (V, 3) for shading."""
    colors = None
    if vertex_colors is not None and len(vertex_colors):
        colors = np.asarray(vertex_colors)
        if colors.dtype != np.uint8:
            colors = np.clip(np.round(colors * 255), 0, 255).astype(np.uint8)
    rec.log(
        entity,
        rr.Mesh3D(
            vertex_positions=np.asarray(vertices, dtype=np.float32),
            triangle_indices=np.asarray(faces, dtype=np.uint32),
            vertex_colors=colors,
            vertex_normals=None if vertex_normals is None else np.asarray(vertex_normals,
                                                                           dtype=np.float32),
        ),
        static=True,
    )


def log_series(
    rec: rr.RecordingStream, timeline: str, entity: str, values: Sequence[float]
) -> None:
    """One scalar curve on a sequence timeline, index 0..N-1."""
    for i, value in enumerate(values):
        rec.set_time(timeline, sequence=i)
        rec.log(entity, rr.Scalars(float(value)))
    rec.reset_time()


def log_bars(rec: rr.RecordingStream, entity: str, values: Sequence[float]) -> None:
    """Values per item (index 0..N-1) as a static bar chart: unlike a curve on a timeline, it
    shows whichever timeline the viewer is on."""
    rec.log(entity, rr.BarChart(np.asarray(values, dtype=float)), static=True)


def log_table(rec: rr.RecordingStream, entity: str, title: str, rows: Sequence[Mapping]) -> None:
    """A Markdown table (a list of dicts with the same keys) as a static text document."""
    if rows:
        keys = list(rows[0])
        lines = [
            f"# {title}",
            "",
            "| " + " | ".join(keys) + " |",
            "|" + "---|" * len(keys),
            *("| " + " | ".join(_fmt(r[k]) for k in keys) + " |" for r in rows),
        ]
    else:
        lines = [f"# {title}", "", "(empty)"]
    rec.log(entity, rr.TextDocument("\n".join(lines), media_type="text/markdown"), static=True)


def _fmt(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


# Motion over frames (tracking.report.step). Timelines shared with the tracking recording: ``frame``
# (sequence: the frame number) and ``time`` (duration: frame number / frame rate, seconds).
FRAME_TIMELINE = "frame"
TIME_TIMELINE = "time"


@contextlib.contextmanager
def _at_frame(rec: rr.RecordingStream, frame: int, time_s: float) -> Iterator[None]:
    """Log what the block logs at this frame on the ``frame`` and ``time`` timelines."""
    rec.set_time(FRAME_TIMELINE, sequence=frame)
    rec.set_time(TIME_TIMELINE, duration=time_s)
    try:
        yield
    finally:
        rec.reset_time()


def _frame_indexes(frames: np.ndarray, times_s: np.ndarray) -> list[rr.TimeColumn]:
    return [
        rr.TimeColumn(FRAME_TIMELINE, sequence=np.asarray(frames, dtype=np.int64)),
        rr.TimeColumn(TIME_TIMELINE, duration=np.asarray(times_s, dtype=float)),
    ]


def log_y_up_world(rec: rr.RecordingStream, entity: str = "world") -> None:
    """The body model's world: right-handed, Y up, metres (not COLMAP's Y-down model frame)."""
    rec.log(entity, rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)


def log_frame_series(
    rec: rr.RecordingStream, entity: str, frames: np.ndarray, times_s: np.ndarray,
    values: np.ndarray,
) -> None:  # fmt: skip
    """One scalar curve over frames (T,), on the ``frame`` and ``time`` timelines; NaN values
    (frames without data) are not logged."""
    values = np.asarray(values, dtype=float)
    ok = np.isfinite(values)
    if ok.any():
        rec.send_columns(entity, indexes=_frame_indexes(frames[ok], times_s[ok]),
                         columns=rr.Scalars.columns(scalars=values[ok]))


def log_skeleton_frames(
    rec: rr.RecordingStream, entity: str, frames: np.ndarray, times_s: np.ndarray,
    points_in_world: np.ndarray, bones: Sequence[tuple[int, int]], radius: float = 0.02,
) -> None:  # fmt: skip
    """Joint centres (T, N, 3) as ``entity/joints`` and bones (index pairs) as ``entity/bones``,
    one skeleton per frame on the ``frame`` and ``time`` timelines; frames with NaN skipped."""
    points = np.asarray(points_in_world, dtype=float)
    ok = np.isfinite(points).all(axis=(1, 2))
    if not ok.any():
        return
    points = points[ok]
    indexes = _frame_indexes(frames[ok], times_s[ok])
    n_frames, n_points = points.shape[:2]
    rec.send_columns(
        f"{entity}/joints", indexes=indexes,
        columns=rr.Points3D.columns(positions=points.reshape(-1, 3),
                                    radii=np.full(n_frames * n_points, radius, np.float32),
                                    ).partition([n_points] * n_frames),
    )  # fmt: skip
    if bones:
        pairs = np.asarray(bones, dtype=int)
        strips = points[:, pairs].reshape(-1, 2, 3)
        rec.send_columns(
            f"{entity}/bones", indexes=indexes,
            columns=rr.LineStrips3D.columns(strips=list(strips)).partition([len(pairs)] * n_frames),
        )


SKELETON_RGB: tuple[int, int, int] = (30, 110, 230)
"""The colour of a skeleton's joints and bones: blue, apart from the skin-toned body mesh."""


def log_skeleton_context(
    rec: rr.RecordingStream, entity: str, names: Sequence[str],
    connections: Sequence[tuple[int, int]], class_id: int = 0, label: str = "body",
    color: tuple[int, int, int] = SKELETON_RGB,
) -> None:  # fmt: skip
    """The keypoint names and bone connections of a skeleton class, as a static
    `AnnotationContext` on `entity`: points logged below it with that class id and keypoint ids
    are drawn connected, in ``color`` and named on hover (Rerun's human_pose_tracking
    convention)."""
    rec.log(
        entity,
        rr.AnnotationContext([
            rr.ClassDescription(
                info=rr.AnnotationInfo(id=class_id, label=label, color=color),
                keypoint_annotations=[rr.AnnotationInfo(id=i, label=name)
                                      for i, name in enumerate(names)],
                keypoint_connections=[(int(a), int(b)) for a, b in connections],
            )
        ]),
        static=True,
    )  # fmt: skip


def log_skeleton(
    rec: rr.RecordingStream, entity: str, points_in_world: np.ndarray, class_id: int = 0,
    radius: float = 0.015, static: bool = False,
) -> None:  # fmt: skip
    """Joint positions (N, 3) as keypoints 0..N-1 of `class_id` (see `log_skeleton_context`),
    their names shown on hover only: 16 labels drawn at once hid the body (issue 21)."""
    points = np.asarray(points_in_world, dtype=np.float32)
    rec.log(
        entity,
        rr.Points3D(points, radii=radius, class_ids=class_id, keypoint_ids=np.arange(len(points)),
                    show_labels=False),
        static=static,
    )


# Silhouettes: class 0 is the background, 1 the person (foreground).
SILHOUETTE_CLASSES = ((0, "background", (0, 0, 0)), (1, "person", (255, 190, 40)))


def log_silhouette_context(rec: rr.RecordingStream, entity: str = "world/cameras") -> None:
    """Static colours and labels of the silhouette classes, for every mask logged below
    ``entity``."""
    rec.log(entity, rr.AnnotationContext([rr.AnnotationInfo(id=i, label=label, color=color)
                                          for i, label, color in SILHOUETTE_CLASSES]),
            static=True)  # fmt: skip


def log_silhouette(
    rec: rr.RecordingStream, entity: str, mask: np.ndarray, frame: int, time_s: float
) -> None:
    """A foreground mask (H, W) (bool, or 0/255) as a `SegmentationImage` of one frame on the
    ``frame`` and ``time`` timelines; downscaled like `log_camera_image`'s Pinhole, so logged at
    a camera's ``.../image`` entity it overlays that camera's view."""
    _log_segmentation_frame(rec, entity, (np.asarray(mask) > 0).astype(np.uint8), frame, time_s)


def _log_segmentation_frame(rec: rr.RecordingStream, entity: str, ids: np.ndarray, frame: int,
                            time_s: float) -> None:  # fmt: skip
    """Class ids (H, W) uint8 as a `SegmentationImage` of one frame, downscaled (nearest) like
    `log_camera_image`'s Pinhole so that it overlays the camera's view."""
    height, width = ids.shape
    scale = _display_scale(width, height)
    if scale < 1.0:
        ids = cv2.resize(ids, (round(width * scale), round(height * scale)),
                         interpolation=cv2.INTER_NEAREST)
    with _at_frame(rec, frame, time_s):
        rec.log(entity, rr.SegmentationImage(ids))


def log_frame_image(
    rec: rr.RecordingStream, entity: str, image_bgr: np.ndarray, frame: int | None = None,
    time_s: float | None = None,
) -> None:  # fmt: skip
    """A video frame (H, W, 3) BGR uint8 as JPEG on the ``frame`` and ``time`` timelines (static
    when ``frame`` is None), downscaled like `log_camera_image`'s Pinhole: at a camera's
    ``.../image`` entity it fills that camera's view and `log_silhouette` masks overlay it."""
    height, width = image_bgr.shape[:2]
    scale = _display_scale(width, height)
    if scale < 1.0:
        image_bgr = cv2.resize(image_bgr, (round(width * scale), round(height * scale)),
                               interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", image_bgr, [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        return
    if frame is not None:
        rec.set_time(FRAME_TIMELINE, sequence=frame)
        if time_s is not None:
            rec.set_time(TIME_TIMELINE, duration=time_s)
    rec.log(entity, rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg"),
            static=frame is None)
    rec.reset_time()


# XOR overlay of tracking: which silhouette covers a pixel (model, image, both).
XOR_CLASSES = ((0, "neither", (0, 0, 0)), (1, "model only", (230, 60, 60)),
               (2, "image only", (60, 120, 240)), (3, "both", (200, 200, 200)))  # fmt: skip


def log_xor_context(rec: rr.RecordingStream, entity: str = "world/cameras") -> None:
    """Static colours and labels of the XOR classes, for every overlay logged below ``entity``:
    logged once, before the overlays (issue 21 saw the viewer's own palette and "Label 0" ...
    "Label 3" when the context was re-logged between frames)."""
    rec.log(entity, rr.AnnotationContext([rr.AnnotationInfo(id=i, label=label, color=color)
                                          for i, label, color in XOR_CLASSES]),
            static=True)  # fmt: skip
    # Sent now: the batcher holds a small row up to its 0.2 s tick while an image of 1 MB and
    # more goes out at once, so an overlay logged sooner came first in the file (session 33:
    # the tracker, faster, logged its first overlay within the tick).
    rec.flush()


def log_xor_overlay(
    rec: rr.RecordingStream, entity: str, model: np.ndarray, image: np.ndarray, frame: int,
    time_s: float,
) -> None:  # fmt: skip
    """Model and image silhouettes (H, W) bool as one `SegmentationImage` (class = model +
    2 * image, so XOR pixels are classes 1 and 2); its classes are `log_xor_context`'s, logged
    once on an ancestor of ``entity``."""
    ids = (np.asarray(model, bool).astype(np.uint8) + 2 * np.asarray(image, bool)).astype(np.uint8)
    _log_segmentation_frame(rec, entity, ids, frame, time_s)


BODY_COLOUR_RGBA: tuple[int, int, int, int] = (222, 184, 150, 110)
"""The albedo of a tracked or synthetic body mesh in a recording: a skin tone, see-through
(alpha 110 of 255), so that the skeleton inside it shows."""

SKELETON_RADIUS_M = 0.025
"""Joint radius of a tracked skeleton, drawn inside its see-through body mesh: 2.5 cm, so that
the joints show."""


def log_mesh_frame(
    rec: rr.RecordingStream, entity: str, vertices: np.ndarray, faces: np.ndarray, frame: int,
    time_s: float, normals: np.ndarray | None = None,
    colour_rgba: tuple[int, int, int, int] = BODY_COLOUR_RGBA,
) -> None:  # fmt: skip
    """A mesh that moves: its vertices (and unit ``normals``, shaded smooth by the viewer when
    given) on the ``frame`` and ``time`` timelines, in one ``colour_rgba``."""
    with _at_frame(rec, frame, time_s):
        rec.log(entity, rr.Mesh3D(
            vertex_positions=np.asarray(vertices, dtype=np.float32),
            triangle_indices=np.asarray(faces, dtype=np.uint32),
            vertex_normals=None if normals is None else np.asarray(normals, dtype=np.float32),
            albedo_factor=colour_rgba))


def log_skeleton_frame(
    rec: rr.RecordingStream, entity: str, points_in_world: np.ndarray, frame: int, time_s: float,
) -> None:  # fmt: skip
    """`log_skeleton` of one frame on the ``frame`` and ``time`` timelines."""
    with _at_frame(rec, frame, time_s):
        log_skeleton(rec, entity, points_in_world, radius=SKELETON_RADIUS_M)


def log_frame_scalar(rec: rr.RecordingStream, entity: str, value: float, frame: int,
                     time_s: float) -> None:  # fmt: skip
    with _at_frame(rec, frame, time_s):
        rec.log(entity, rr.Scalars(float(value)))


def log_frame_text(rec: rr.RecordingStream, entity: str, text: str, level: str, frame: int,
                   time_s: float) -> None:  # fmt: skip
    """A line of text (level: Rerun's "INFO", "WARN", ...) at this frame."""
    with _at_frame(rec, frame, time_s):
        rec.log(entity, rr.TextLog(text, level=level))


# Default blueprints ---------------------------------------------------------------------------
# One builder per step, registered here and sent by `step_recording`; README.md ("Recordings")
# describes each in one line. A builder takes the camera entities the step logged
# (``world/cameras/<name>``, in logging order).
BlueprintBuilder = Callable[[Sequence[str]], rrb.Blueprint]
BLUEPRINTS: dict[str, BlueprintBuilder] = {}

MAX_CAMERA_VIEWS = 16
"""At most this many 2D views of cameras in a layout (the first ones): a tab per photo of a
200-photo model is no overview; the 3D view shows them all."""


def _blueprint(*steps: str) -> Callable[[BlueprintBuilder], BlueprintBuilder]:
    def register(builder: BlueprintBuilder) -> BlueprintBuilder:
        for step in steps:
            BLUEPRINTS[step] = builder
        return builder

    return register


def default_blueprint(step: str, cameras: Sequence[str] = ()) -> rrb.Blueprint | None:
    """The layout the viewer opens ``step``'s recording with (None: the viewer's automatic one,
    for a step without a builder)."""
    builder = BLUEPRINTS.get(step)
    return None if builder is None else builder(list(cameras))


def _camera_views(cameras: Sequence[str]) -> list[rrb.Spatial2DView]:
    """One 2D view per camera, in its image (the ``Pinhole``) with everything logged below it."""
    return [rrb.Spatial2DView(origin=f"{camera}/image", name=camera.rsplit("/", 1)[-1])
            for camera in cameras[:MAX_CAMERA_VIEWS]]  # fmt: skip


def _layout(*parts: rrb.BlueprintPart) -> rrb.Blueprint:
    # Views are chosen by the step: the viewer adds none of its own (its automatic views once
    # showed an empty `world/cameras` space with an error).
    return rrb.Blueprint(*parts, auto_views=False, auto_layout=False)


@_blueprint("features")
def _features(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Horizontal(rrb.Tabs(*_camera_views(cameras), name="photos"),
                                  rrb.TimeSeriesView(origin="stats", name="keypoints per image"),
                                  column_shares=[3, 1]),  # fmt: skip
                   rrb.TimePanel(timeline="image"))


@_blueprint("matches")
def _matches(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Vertical(rrb.TimeSeriesView(origin="stats", name="inliers per pair"),
                                rrb.TextDocumentView(origin="tables/pairs", name="pairs")),
                   rrb.TimePanel(timeline="pair"))


@_blueprint("intrinsics")
def _intrinsics(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.TextDocumentView(origin="tables/intrinsics", name="focal priors"))


@_blueprint("mapping")
def _mapping(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="sparse model"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="stats/registered_images", name="registered images"),
                rrb.BarChartView(origin="stats/reprojection_error_px",
                                 name="reprojection error per image (px)"),
                rrb.TextDocumentView(origin="tables/images", name="images")),
            column_shares=[2, 1]),
        rrb.TimePanel(timeline="registration"))  # fmt: skip


@_blueprint("dense")
def _dense(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Spatial3DView(origin="world", name="dense cloud"))


@_blueprint("mesh")
def _mesh(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Spatial3DView(origin="world", name="mesh"))


@_blueprint("compare")
def _compare(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(
        rrb.Horizontal(
            rrb.TextDocumentView(origin="tables/methods", name="focal by method"),
            rrb.Vertical(rrb.TimeSeriesView(origin="kruppa", name="Kruppa focal per pair (px)"),
                         rrb.TextDocumentView(origin="tables/pairs", name="Kruppa pairs"))),
        rrb.TimePanel(timeline="pair"))  # fmt: skip


def _frame_panel() -> rrb.TimePanel:
    return rrb.TimePanel(timeline=FRAME_TIMELINE)


@_blueprint("synth")
def _synth(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Horizontal(rrb.Spatial3DView(origin="world", name="truth and cameras"),
                                  rrb.Grid(*_camera_views(cameras), name="silhouettes")),
                   _frame_panel())  # fmt: skip


@_blueprint("silhouettes")
def _silhouettes(cameras: Sequence[str]) -> rrb.Blueprint:
    backgrounds = [rrb.Spatial2DView(origin=f"backgrounds/{camera.rsplit('/', 1)[-1]}",
                                     name=f"{camera.rsplit('/', 1)[-1]} background")
                   for camera in cameras[:MAX_CAMERA_VIEWS]]  # fmt: skip
    return _layout(
        rrb.Vertical(
            rrb.Grid(*_camera_views(cameras), name="frames and silhouettes"),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="silhouettes", name="foreground fraction"),
                rrb.Tabs(rrb.TextDocumentView(origin="silhouettes/summary", name="summary"),
                         rrb.Grid(*backgrounds, name="backgrounds"),
                         rrb.Spatial3DView(origin="world", name="cameras"))),
            row_shares=[2, 1]),
        _frame_panel())  # fmt: skip


@_blueprint("track")
def _track(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="body over the cameras"),
                rrb.Horizontal(rrb.TimeSeriesView(origin="track/energy_px", name="energy (px)"),
                               rrb.TimeSeriesView(origin="track/xor_fraction",
                                                  name="XOR fraction of the silhouette"),
                               rrb.TextLogView(origin="track/status",
                                               name="frame status (lost, recovered)")),
                row_shares=[3, 1]),
            rrb.Grid(*_camera_views(cameras), name="XOR per camera"),
            column_shares=[3, 2]),
        _frame_panel())  # fmt: skip


@_blueprint("report")
def _report(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="skeleton and centre of mass"),
            rrb.Tabs(rrb.TimeSeriesView(origin="report/joint_angles", name="joint angles (deg)"),
                     rrb.TimeSeriesView(origin="report/joint_moments",
                                        name="joint moments (N m)"),
                     rrb.TimeSeriesView(origin="report/center_of_mass",
                                        name="centre of mass (m, m/s)"))),
        _frame_panel())  # fmt: skip


@_blueprint("fit")
def _fit(cameras: Sequence[str]) -> rrb.Blueprint:
    return _layout(rrb.Horizontal(rrb.Spatial3DView(origin="world", name="body in the cloud"),
                                  rrb.TextDocumentView(origin="fit", name="body fit"),
                                  column_shares=[3, 1]))  # fmt: skip


LOOPBACK = "127.0.0.1"


def viewer_command(recordings: Sequence[Path], bind: str = LOOPBACK) -> list[str]:
    """The command that opens recordings in the Rerun viewer (shipped in the rerun-sdk wheel),
    its server listening on ``bind`` only: rerun 0.41 binds 0.0.0.0 (every interface) unless
    told otherwise, which serves the recordings to the whole network."""
    import ipaddress
    import shutil
    import sys

    from recon.errors import UserError

    try:
        address = str(ipaddress.ip_address(bind))
    except ValueError:
        raise UserError(f"--bind {bind}: not an IP address (e.g. 127.0.0.1, 0.0.0.0, ::)"
                        ) from None
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    return [exe, "--bind", address, *map(str, recordings)]


def has_display() -> bool:
    import os
    import sys

    return sys.platform in ("darwin", "win32") or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


def open_viewer(recordings: Sequence[Path], bind: str = LOOPBACK) -> list[str] | None:
    """Start the viewer in the background when there is a display; else return its command."""
    import subprocess

    command = viewer_command(recordings, bind)
    if not has_display():
        return command
    subprocess.Popen(command, start_new_session=True)
    return None
