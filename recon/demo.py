"""`mocap demo`: photos of a synthetic scene with known cameras → the pipeline → errors vs truth.

Needs no download: the scene is rendered here (:mod:`recon.evaluation.synthetic_room`).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from recon.sfm.pipeline import SfMConfig, SfMSummary, cams_from_world, run_sfm
from recon.workspace import Workspace, atomic_output, write_json_atomic


@dataclass(frozen=True, kw_only=True)
class DemoConfig:
    out: Path = field(
        default=Path("workspaces/demo"),
        metadata={"help": "workspace folder of the demo; the scene goes to OUT/scene"},
    )
    num_views: int = field(default=12, metadata={"help": "number of synthetic photos (8-20)"})
    seed: int = field(default=0, metadata={"help": "scene seed"})
    mesh: bool = field(
        default=True,
        metadata={"help": "also run dense stereo and meshing, and score the mesh (--no-mesh: "
                  "sparse model only)"},
    )


@dataclass(frozen=True)
class DemoReport:
    sfm: SfMSummary
    true_focal_px: float
    focal_px: float
    focal_rel_error: float
    rotation_error_deg: dict[str, float]
    center_error: dict[str, float]
    scene_extent: float
    mesh: dict[str, Any] | None = None
    """Mesh figures against the truth (see :func:`score_mesh`), when the mesh was built."""

    def as_dict(self) -> dict[str, Any]:
        rot = np.array(list(self.rotation_error_deg.values()))
        ctr = np.array(list(self.center_error.values()))
        return {
            "true_focal_px": self.true_focal_px,
            "focal_px": self.focal_px,
            "focal_rel_error": self.focal_rel_error,
            "registered": self.sfm.mapping["registered"],
            "images": self.sfm.mapping["images"],
            "rotation_error_deg": {"median": float(np.median(rot)), "max": float(rot.max())},
            "center_error_m": {"median": float(np.median(ctr)), "max": float(ctr.max())},
            "per_image": {
                n: {"rotation_deg": self.rotation_error_deg[n], "center_m": self.center_error[n]}
                for n in sorted(self.rotation_error_deg)
            },
            "mesh": self.mesh,
        }

    def lines(self) -> list[str]:
        d = self.as_dict()
        return [
            *self.sfm.lines(),
            "",
            "against the truth (poses aligned by a similarity transform):",
            f"  focal       {self.focal_px:.1f} px, truth {self.true_focal_px:.1f} px "
            f"({100 * self.focal_rel_error:+.2f}%)",
            f"  rotation    median {d['rotation_error_deg']['median']:.3f}°, "
            f"max {d['rotation_error_deg']['max']:.3f}°",
            f"  position    median {1000 * d['center_error_m']['median']:.1f} mm, "
            f"max {1000 * d['center_error_m']['max']:.1f} mm "
            f"(cameras span {self.scene_extent:.1f} m)",
            *self._mesh_lines(),
        ]

    def _mesh_lines(self) -> list[str]:
        if self.mesh is None:
            return []
        m = self.mesh
        return [
            f"  mesh        F-score {m['f_score']:.3f} at {100 * m['threshold_m']:.1f} cm "
            f"(1% of the scene): precision {m['precision']:.3f}, recall {m['recall']:.3f}",
            f"              accuracy {1000 * m['accuracy_m']:.1f} mm, completeness "
            f"{1000 * m['completeness_m']:.1f} mm (means); {m['faces']} faces, "
            f"{m['dense_points']} dense points",
            f"  files       {m['files']}",
            f"  picture     {m['picture']}",
        ]


def make_scene(config: DemoConfig) -> tuple[Path, Path, bool]:
    """Render the scene into OUT/scene once; reuse it while the settings are unchanged.

    Returns the images folder, the truth file, and whether the scene was (re)rendered.
    """
    from recon.evaluation.synthetic_room import SyntheticSceneConfig, render_scene, write_scene

    scene_dir = config.out / "scene"
    settings = {"num_views": config.num_views, "seed": config.seed, "format": 1}
    stamp = scene_dir / "scene.json"
    if stamp.exists() and json.loads(stamp.read_text()) == settings:
        return scene_dir / "images", scene_dir / "truth.json", False
    config.out.mkdir(parents=True, exist_ok=True)
    scene = render_scene(SyntheticSceneConfig(num_views=config.num_views, seed=config.seed))
    with atomic_output(scene_dir) as tmp:
        tmp.mkdir()
        write_scene(scene, tmp / "images", tmp / "truth.json")
        (tmp / "scene.json").write_text(json.dumps(settings))
    return scene_dir / "images", scene_dir / "truth.json", True


def score_mesh(ws: Workspace, config: DemoConfig, estimated: dict[str, np.ndarray],
               truth: dict[str, Any]) -> dict[str, Any]:
    """The mesh, aligned to the true world by the camera centres, against the true surfaces
    seen by two or more cameras: accuracy, completeness and F-score at 1% of the scene extent.
    Also renders the aligned mesh to WS/mesh/preview.png."""
    import open3d as o3d

    from recon.evaluation.surface import render_mesh_png, surface_scores
    from recon.evaluation.synthetic_room import (
        SyntheticSceneConfig,
        render_scene,
        visible_surface_points,
    )
    from recon.evaluation.truth import camera_center, umeyama_sim3

    scene = render_scene(SyntheticSceneConfig(num_views=config.num_views, seed=config.seed))
    truth_points = visible_surface_points(scene)
    names = sorted(set(estimated) & set(truth))
    scale, R, t = umeyama_sim3(
        np.array([camera_center(estimated[n]) for n in names]),
        np.array([truth[n].center_in_world for n in names]),
    )
    mesh = o3d.io.read_triangle_mesh(str(ws.mesh_dir / "mesh.ply"))
    vertices = np.asarray(mesh.vertices) @ (scale * R).T + t
    mesh.vertices = o3d.utility.Vector3dVector(vertices)
    extent = float(np.linalg.norm(np.ptp(truth_points, axis=0)))
    scores = surface_scores(mesh, truth_points, threshold=0.01 * extent)
    # Seen from the first photo's camera, pulled back 1.5 m, to compare with that photo.
    first = truth[names[0]]
    cam_from_world = first.cam_from_world.copy()
    cam_from_world[2, 3] += 1.5
    picture = render_mesh_png(mesh, ws.mesh_dir / "preview.png", width=first.width,
                              height=first.height, camera=(first.K, cam_from_world))
    return {
        "threshold_m": scores.threshold,
        "f_score": scores.f_score,
        "precision": scores.precision,
        "recall": scores.recall,
        "accuracy_m": scores.accuracy,
        "completeness_m": scores.completeness,
        "chamfer_m": scores.chamfer,
        "faces": len(mesh.triangles),
        "dense_points": ws.step("dense").summary["points"],  # type: ignore[union-attr]
        "files": ", ".join(str(ws.mesh_dir / f"mesh.{e}") for e in ("ply", "obj", "glb")),
        "picture": str(picture),
    }


def run_demo(
    config: DemoConfig,
    sfm_config: SfMConfig | None = None,
    dense_config: Any = None,
    mesh_config: Any = None,
    *,
    overwrite: bool = False,
) -> DemoReport:
    from recon.cameras import read_cameras_json
    from recon.dense.step import DenseConfig, densify
    from recon.evaluation.truth import focal_error, pose_errors
    from recon.mesh.step import MeshConfig, make_mesh

    images, truth_path, rendered = make_scene(config)
    ws, _ = Workspace.create(config.out, images, overwrite=rendered or overwrite)
    summary = run_sfm(ws, sfm_config or SfMConfig(), overwrite=overwrite)
    truth = {c.name: c for c in read_cameras_json(truth_path)}
    model = pycolmap.Reconstruction(ws.model_dir)
    estimated = cams_from_world(model)
    errors = pose_errors(estimated, {n: t.cam_from_world for n, t in truth.items()})
    true_focal = float(next(iter(truth.values())).K[0, 0])
    focal = float(np.mean([c["focal_px"] for c in summary.mapping["cameras"]]))
    centers = np.array([t.center_in_world for t in truth.values()])
    mesh = None
    if config.mesh:
        densify(ws, dense_config or DenseConfig(), overwrite=overwrite)
        make_mesh(ws, mesh_config or MeshConfig(), overwrite=overwrite)
        mesh = score_mesh(ws, config, estimated, truth)
    report = DemoReport(
        sfm=summary,
        true_focal_px=true_focal,
        focal_px=focal,
        focal_rel_error=focal_error(focal, true_focal),
        rotation_error_deg=dict(errors.rotation_deg),
        center_error=dict(errors.center),
        scene_extent=float(np.ptp(centers, axis=0).max()),
        mesh=mesh,
    )
    write_json_atomic(ws.root / "evaluation.json", report.as_dict() | {"config": asdict(config)})
    return report
