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

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

import plugins
from plugins.protocols import DenseContext, DenseResult
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
    upstream = ws.step("mapping")
    if upstream is None or not ws.model_dir.is_dir():
        raise UserError(f"{ws.root} has no sparse model yet; run `mocap sfm {ws.root}` first")
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
        "undistort", fp, config=settings, seconds=timer.seconds,
        summary={"images": model.num_reg_images(), "sizes": sizes},
    )


# Dense ---------------------------------------------------------------------------------------
def densify(ws: Workspace, config: DenseConfig, *, overwrite: bool = False) -> StepRecord:
    """The dense cloud of the workspace, by the configured backend, in dense/fused.ply."""
    import open3d as o3d

    upstream = undistort(ws, config, overwrite=overwrite)
    settings = {"dense": config.dense, "options": list(config.dense_options)}
    fp = fingerprint("dense", settings, upstream.fingerprint)
    if done := ws.reusable("dense", fp, ws.dense_cloud_path, overwrite=overwrite):
        return done
    backend = plugins.create("dense", config.dense, config.dense_options)
    with Timer() as timer, tempfile.TemporaryDirectory(dir=ws.root, prefix=".dense-") as tmp:
        result: DenseResult = backend.densify(
            DenseContext(undistorted_dir=ws.undistorted_dir, scratch_dir=Path(tmp),
                         num_threads=config.num_threads)
        )
        cloud = result.cloud
        if len(cloud.points) == 0:
            raise UserError(f"dense backend {config.dense} found no 3D points in {ws.root}")
        with atomic_output(ws.dense_cloud_path) as partial:
            if not o3d.io.write_point_cloud(str(partial), cloud, write_ascii=False):
                raise UserError(f"could not write {ws.dense_cloud_path}")
        _log_dense(ws, cloud)
    return ws.record_step(
        "dense", fp, config=settings, seconds=timer.seconds,
        summary={"points": len(cloud.points), "notes": list(result.notes),
                 **dict(result.stats)},
    )


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
