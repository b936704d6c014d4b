"""The `mesh` step: mesh/mesh.{ply,obj,glb} from dense/fused.ply, by a ``mesh`` plugin.

Same contract as :mod:`recon.sfm.pipeline`: skipped when its outputs exist and its fingerprint
matches, and written atomically.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import plugins
from recon.dense.ply import PlyError, check_ply, quiet_stderr
from recon.dense.step import check_free_space, log_cameras, write_failure
from recon.errors import UserError
from recon.workspace import StepRecord, Timer, Workspace, fingerprint


@dataclass(frozen=True, kw_only=True)
class MeshConfig:
    mesher: str = field(
        default="poisson", metadata={"help": "mesh backend plugin (see `mocap plugins`)"}
    )
    mesh_options: tuple[str, ...] = field(
        default=(),
        metadata={"help": "an option of the mesh backend as KEY=VALUE (repeatable)",
                  "flags": ("--mesh-option",), "metavar": "KEY=VALUE"},
    )
    faces: int | None = field(
        default=None, metadata={"help": "decimate the cleaned mesh to about this many faces"}
    )
    min_component_fraction: float = field(
        default=0.01,
        metadata={"help": "remove connected pieces with fewer than this fraction of the faces, "
                  "in [0, 1)"},
    )

    def __post_init__(self) -> None:
        if self.faces is not None and self.faces < 4:
            raise UserError(f"--faces {self.faces}: a mesh needs at least 4 faces")
        if not 0 <= self.min_component_fraction < 1:  # NaN fails too
            raise UserError(f"--min-component-fraction {self.min_component_fraction} must be "
                            "in [0, 1)")


def mesh_paths(ws: Workspace) -> dict[str, Path]:
    return {ext: ws.mesh_dir / f"mesh.{ext}" for ext in ("ply", "obj", "glb")}


def make_mesh(ws: Workspace, config: MeshConfig, *, overwrite: bool = False) -> StepRecord:
    from recon.mesh.meshing import CleanupConfig, MeshingError, clean_mesh, write_mesh

    # Options are checked before anything is read: a bad value is refused in one line.
    backend = plugins.create("mesh", config.mesher, config.mesh_options)
    upstream = ws.require_step(
        "dense", f"no dense cloud yet; run `mocap dense {ws.root}` first", f"mocap dense {ws.root}")
    settings = {"mesher": config.mesher, "options": list(config.mesh_options),
                "faces": config.faces, "min_component_fraction": config.min_component_fraction}
    fp = fingerprint("mesh", settings, upstream.fingerprint)
    paths = mesh_paths(ws)
    if done := ws.reusable("mesh", fp, *paths.values(), overwrite=overwrite):
        return done
    with Timer() as timer:
        cloud = read_cloud(ws)
        try:
            mesh = backend.mesh(cloud)
            mesh = clean_mesh(mesh, CleanupConfig(
                min_component_fraction=config.min_component_fraction,
                target_faces=config.faces))
        except MeshingError as exc:
            raise UserError(f"{ws.dense_cloud_path}: {exc}") from None
        try:
            ws.mesh_dir.mkdir(parents=True, exist_ok=True)
            check_free_space(ws.mesh_dir, mesh_files_size(mesh), paths["ply"])
            # The recording is made before the new files replace the old ones: when anything
            # cannot be written, the previous mesh is kept as it was.
            write_mesh(mesh, paths["ply"], also=(".obj", ".glb"),
                       before_replace=lambda: _log_mesh(ws, mesh))
        except OSError as exc:
            raise write_failure(ws.mesh_dir, exc) from None
    return ws.record_step(
        "mesh", fp, outputs=list(paths.values()), config=settings, seconds=timer.seconds,
        summary={"vertices": len(mesh.vertices), "faces": len(mesh.triangles),
                 "files": [str(p.relative_to(ws.root)) for p in paths.values()]},
    )


def read_cloud(ws: Workspace) -> Any:
    """The dense cloud, checked: a file that is not a PLY or is cut short is a one-line error
    that says so (Open3D's reader returns an empty cloud for both)."""
    import open3d as o3d

    path = ws.dense_cloud_path
    redo = f"run `mocap dense {ws.root} --overwrite`"
    try:
        header = check_ply(path)
    except PlyError as exc:
        raise UserError(f"{path} is not a usable point cloud: {exc}; {redo}") from None
    except OSError as exc:
        raise UserError(f"cannot read {path}: {exc.strerror or exc}") from None
    with quiet_stderr():  # RPly prints a line per value it fails to read
        cloud = o3d.io.read_point_cloud(str(path))
    if len(cloud.points) != header.count("vertex"):
        raise UserError(f"{path} is not a usable point cloud: {len(cloud.points)} of the "
                        f"{header.count('vertex')} points its header declares could be read; "
                        f"{redo}")
    return cloud


def mesh_files_size(mesh: Any) -> int:
    """About the bytes of the three mesh files (binary PLY, OBJ text, GLB), a lower bound
    with some margin for the free-space check; the writes themselves are checked too."""
    vertices, faces = len(mesh.vertices), len(mesh.triangles)
    ply = vertices * (24 + 24 + 3) + faces * 13
    obj = vertices * 40 + faces * 15
    glb = vertices * 36 + faces * 12
    return ply + obj + glb


def _log_mesh(ws: Workspace, mesh: Any) -> None:
    from recon import recording

    mesh.compute_vertex_normals()
    with recording.step_recording(ws.log_path("mesh"), "mesh") as rec:
        log_cameras(rec, ws)
        recording.log_mesh(
            rec, "world/mesh", np.asarray(mesh.vertices), np.asarray(mesh.triangles),
            np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None,
            np.asarray(mesh.vertex_normals),
        )
