"""`mocap body`: the posed body mesh and joint positions of one frame of a BVH clip.

Writes ``DIR/body.ply`` (metres, Y up, in the BVH's world) and ``DIR/joints.json``
(``{"joint name": [x, y, z], ...}``), both atomically.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon.errors import UserError
from recon.workspace import atomic_output, write_json_atomic
from tracking.body.bvh import read_bvh
from tracking.body.model import BodyModel, node_positions_in_world
from tracking.body.retarget import retarget


@dataclass(frozen=True, kw_only=True)
class BodyExportConfig:
    bvh: Path = field(metadata={"help": "BVH clip to read"})
    frame: int = field(default=0, metadata={"help": "frame index (0-based)"})
    out: Path = field(default=Path("workspaces/body"), metadata={"help": "output folder"})
    metres_per_unit: float | None = field(
        default=None,
        metadata={"help": "BVH length unit in metres (default: its naming's; CMU: 0.0254/0.45, "
                  "Daz-style: 0.01)"},
    )


def export_body(config: BodyExportConfig) -> dict[str, Any]:
    """Retarget one frame of the clip onto the body model and write its mesh and joints."""
    import numpy as np
    import open3d as o3d

    try:
        motion = read_bvh(config.bvh)
    except (OSError, ValueError) as exc:
        raise UserError(str(exc).splitlines()[0]) from None
    if not 0 <= config.frame < motion.num_frames:
        raise UserError(f"{config.bvh} has frames 0..{motion.num_frames - 1}; "
                        f"got --frame {config.frame}")
    result = retarget(motion, config.metres_per_unit, frames=[config.frame])
    pose = result.poses[0]
    model = BodyModel(result.shape)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(model.posed_vertices(pose)),
        o3d.utility.Vector3iVector(np.asarray(model.faces, dtype=np.int32)),
    )
    mesh.compute_vertex_normals()
    config.out.mkdir(parents=True, exist_ok=True)
    ply = config.out / "body.ply"
    with atomic_output(ply) as partial:
        if not o3d.io.write_triangle_mesh(str(partial), mesh, write_ascii=False):
            raise UserError(f"could not write {ply}")
    joints = {name: [float(v) for v in xyz]
              for name, xyz in node_positions_in_world(pose, result.shape).items()}
    write_json_atomic(config.out / "joints.json", joints)
    return {
        "mesh": ply, "joints": config.out / "joints.json",
        "vertices": len(mesh.vertices), "faces": len(mesh.triangles),
        "residual_mm": 1000 * float(result.residual_rms_m[0]),
        "height_m": float(result.shape.height),
    }
