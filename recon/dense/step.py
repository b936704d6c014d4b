"""The `dense` step: undistorted photos and a dense coloured point cloud from the sparse model.

=============  =====================================  =====================================
step           writes                                 reads
=============  =====================================  =====================================
undistort      dense/undistorted/{images,sparse}      sparse/0, images/
dense          dense/fused.ply                        dense/undistorted, a ``dense`` plugin
=============  =====================================  =====================================

Same contract as :mod:`recon.sfm.pipeline`: each step is skipped when its outputs exist and its
fingerprint matches, and writes atomically.
"""

from __future__ import annotations

import errno
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

import plugins
from plugins.protocols import DenseContext, DenseResult
from recon.dense.ply import PlyError, check_ply, quiet_stderr
from recon.errors import UserError
from recon.workspace import StepRecord, Timer, Workspace, atomic_output, fingerprint


@dataclass(frozen=True, kw_only=True)
class DenseConfig:
    """Settings of the dense step. Field help is the CLI's help."""

    dense: str = field(
        default="cpu-stereo", metadata={"help": "dense backend plugin (see `mocap plugins`)"}
    )
    dense_options: tuple[str, ...] = field(
        default=(),
        metadata={"help": "an option of the dense backend as KEY=VALUE (repeatable)",
                  "flags": ("--dense-option",), "metavar": "KEY=VALUE"},
    )
    dense_max_image_size: int = field(
        default=1600,
        metadata={"help": "undistorted images are downscaled to this long side for dense "
                  "matching (memory and time grow with its square)"},
    )
    num_threads: int = field(default=-1, metadata={"help": "threads (-1: all cores)"})

    def __post_init__(self) -> None:
        if self.dense_max_image_size < 64:
            raise UserError(f"--dense-max-image-size {self.dense_max_image_size} is too small")


# Undistortion --------------------------------------------------------------------------------
def undistort(ws: Workspace, config: DenseConfig, *, overwrite: bool = False) -> StepRecord:
    upstream = ws.require_step(
        "mapping", f"no sparse model yet; run `mocap sfm {ws.root}` first", f"mocap sfm {ws.root}")
    registered = upstream.summary.get("registered", 0)
    if registered < 2:
        raise UserError(f"{ws.root}: {registered} registered image(s); dense stereo needs 2")
    settings = {"max_image_size": config.dense_max_image_size}
    fp = fingerprint("undistort", settings, upstream.fingerprint)
    if done := ws.reusable("undistort", fp, ws.undistorted_dir, overwrite=overwrite):
        return done
    options = pycolmap.UndistortCameraOptions()
    options.max_image_size = config.dense_max_image_size
    ws.undistorted_dir.parent.mkdir(parents=True, exist_ok=True)
    with Timer() as timer, atomic_output(ws.undistorted_dir) as out:
        pycolmap.undistort_images(
            out, ws.model_dir, ws.images_dir, undistort_options=options,
            num_threads=config.num_threads,
        )
        model = pycolmap.Reconstruction(out / "sparse")
        sizes = sorted({(c.width, c.height) for c in model.cameras.values()})
    return ws.record_step(
        "undistort", fp, outputs=[ws.undistorted_dir], config=settings, seconds=timer.seconds,
        summary={"images": model.num_reg_images(), "sizes": sizes},
    )


# Dense ---------------------------------------------------------------------------------------
def densify(ws: Workspace, config: DenseConfig, *, overwrite: bool = False) -> StepRecord:
    """The dense cloud of the workspace, by the configured backend, in dense/fused.ply."""
    # Options are checked before any work: a bad value is refused before undistortion.
    backend = plugins.create("dense", config.dense, config.dense_options)
    upstream = undistort(ws, config, overwrite=overwrite)
    settings = {"dense": config.dense, "options": list(config.dense_options)}
    fp = fingerprint("dense", settings, upstream.fingerprint)
    if done := ws.reusable("dense", fp, ws.dense_cloud_path, overwrite=overwrite):
        return done
    with Timer() as timer, tempfile.TemporaryDirectory(dir=ws.root, prefix=SCRATCH_PREFIX) as tmp:
        result: DenseResult = backend.densify(
            DenseContext(undistorted_dir=ws.undistorted_dir, scratch_dir=Path(tmp),
                         num_threads=config.num_threads)
        )
        cloud = result.cloud
        if len(cloud.points) == 0:
            raise UserError(f"dense backend {config.dense} found no 3D points in {ws.root}")
        # The recording is made before the new cloud replaces the old one: when either
        # cannot be written, the previous cloud is kept as it was.
        with atomic_output(ws.dense_cloud_path) as partial:
            write_cloud(partial, cloud, target=ws.dense_cloud_path)
            _log_dense(ws, cloud)
    return ws.record_step(
        "dense", fp, outputs=[ws.dense_cloud_path], config=settings, seconds=timer.seconds,
        summary={"points": len(cloud.points), "notes": list(result.notes),
                 **dict(result.stats)},
    )


SCRATCH_PREFIX = ".dense-"
"""Scratch folders of the dense step; a killed run's are swept by the next run's workspace lock
(:func:`recon.workspace.workspace_lock`)."""


def cloud_file_size(cloud: Any) -> int:
    """Bytes of ``cloud`` as Open3D writes it in binary PLY (double xyz and normals, uchar
    RGB), header excluded."""
    row = 24 + (24 if cloud.has_normals() else 0) + (3 if cloud.has_colors() else 0)
    return row * len(cloud.points)


def check_free_space(folder: Path, needed: int, target: Path) -> None:
    """A one-line error when ``folder``'s file system has less than ``needed`` bytes free."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # unknown: the write itself is checked
    if free < needed:
        raise UserError(
            f"cannot write {target}: no space left on the device ({_mb(needed)} needed, "
            f"{_mb(free)} free); nothing was replaced")


def _mb(size: int) -> str:
    return f"{size / 1e6:.1f} MB"


def write_failure(target: Path, exc: OSError) -> UserError:
    """The one-line error for a file that could not be written (ENOSPC, EROFS, EACCES, ...)."""
    why = "no space left on the device" if exc.errno == errno.ENOSPC else exc.strerror or str(exc)
    return UserError(f"cannot write {target}: {why}; nothing was replaced")


def write_cloud(path: Path, cloud: Any, *, target: Path | None = None) -> None:
    """Write ``cloud`` as binary PLY to ``path`` and read its header back: Open3D's writer
    reports success when its writes fail, so the file's counts and size are checked.

    Raises :class:`UserError` (naming ``target``, default ``path``) when it is not complete.
    """
    import open3d as o3d

    target = target or path
    check_free_space(path.parent, cloud_file_size(cloud) + 4096, target)
    try:
        with quiet_stderr():  # RPly prints a line per failed property write
            ok = o3d.io.write_point_cloud(str(path), cloud, write_ascii=False)
        if not ok:
            raise UserError(f"cannot write {target}: Open3D's PLY writer failed")
        check_ply(path, vertices=len(cloud.points))
    except OSError as exc:
        raise write_failure(target, exc) from None
    except PlyError as exc:
        free = shutil.disk_usage(path.parent).free
        why = ("no space left on the device" if free < 1 << 20
               else f"the written file is incomplete ({exc})")
        raise UserError(f"cannot write {target}: {why}; nothing was replaced") from None


def _cameras(ws: Workspace) -> list[dict[str, Any]]:
    model = pycolmap.Reconstruction(ws.undistorted_dir / "sparse")
    cams = []
    for image in sorted(model.images.values(), key=lambda im: im.name):
        if image.has_pose:
            cam = model.cameras[image.camera_id]
            cams.append({"name": image.name, "K": cam.calibration_matrix(), "width": cam.width,
                         "height": cam.height, "cam_from_world": image.cam_from_world().matrix(),
                         "path": ws.undistorted_dir / "images" / image.name})
    return cams


def log_cameras(rec: Any, ws: Workspace) -> None:
    from recon import recording

    for cam in _cameras(ws):
        recording.log_camera_image(rec, image_name=cam["name"], image_path=cam["path"],
                                   K=cam["K"], width=cam["width"], height=cam["height"],
                                   cam_from_world=cam["cam_from_world"])


def _log_dense(ws: Workspace, cloud: Any) -> None:
    from recon import recording

    with recording.step_recording(ws.log_path("dense"), "dense") as rec:
        log_cameras(rec, ws)
        colors = (np.asarray(cloud.colors) * 255).astype(np.uint8) if cloud.has_colors() else None
        recording.log_points(rec, np.asarray(cloud.points), colors, entity="world/dense")
