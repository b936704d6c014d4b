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
from recon.dense.step import log_cameras
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
        metadata={"help": "remove connected pieces with fewer than this fraction of the faces"},
    )


def mesh_paths(ws: Workspace) -> dict[str, Path]:
    return {ext: ws.mesh_dir / f"mesh.{ext}" for ext in ("ply", "obj", "glb")}


def make_mesh(ws: Workspace, config: MeshConfig, *, overwrite: bool = False) -> StepRecord:
    import open3d as o3d

    from recon.mesh.meshing import CleanupConfig, MeshingError, clean_mesh, write_mesh

    upstream = ws.step("dense")
    if upstream is None or not ws.dense_cloud_path.exists():
        raise UserError(f"{ws.root} has no dense cloud yet; run `mocap dense {ws.root}` first")
    settings = {"mesher": config.mesher, "options": list(config.mesh_options),
                "faces": config.faces, "min_component_fraction": config.min_component_fraction}
    fp = fingerprint("mesh", settings, upstream.fingerprint)
    paths = mesh_paths(ws)
    if done := ws.reusable("mesh", fp, *paths.values(), overwrite=overwrite):
        return done
    backend = plugins.create("mesh", config.mesher, config.mesh_options)
    with Timer() as timer:
        cloud = o3d.io.read_point_cloud(str(ws.dense_cloud_path))
        try:
            mesh = backend.mesh(cloud)
            mesh = clean_mesh(mesh, CleanupConfig(
                min_component_fraction=config.min_component_fraction,
                target_faces=config.faces))
        except MeshingError as exc:
            raise UserError(f"{ws.dense_cloud_path}: {exc}") from None
        ws.mesh_dir.mkdir(parents=True, exist_ok=True)
        write_mesh(mesh, paths["ply"], also=(".obj", ".glb"))
        _log_mesh(ws, mesh)
    return ws.record_step(
        "mesh", fp, config=settings, seconds=timer.seconds,
        summary={"vertices": len(mesh.vertices), "faces": len(mesh.triangles),
                 "files": [str(p.relative_to(ws.root)) for p in paths.values()]},
    )


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
