"""Two photos are enough (thesis ch. 5): Kruppa focal, essential matrix, cheirality, dense
matching and a mesh, scored against the synthetic truth after a similarity alignment."""

from __future__ import annotations

import dataclasses

import numpy as np
import open3d as o3d
import pycolmap
import pytest
from PIL import Image

from recon.dense.step import DenseConfig, densify
from recon.evaluation.synthetic_room import (
    SyntheticSceneConfig,
    render_scene,
    visible_surface_points,
)
from recon.mesh.step import MeshConfig, make_mesh
from recon.sfm.pipeline import SfMConfig, run_sfm
from recon.workspace import Workspace

PAIR = (3, 4)  # consecutive views of the demo scene, ~20° apart


@pytest.fixture(scope="module")
def two_view_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("twoview")
    scene = render_scene(SyntheticSceneConfig(num_views=12, seed=0))
    views = [scene.views[i] for i in PAIR]
    (root / "photos").mkdir()
    for view in views:
        Image.fromarray(view.image_rgb).save(root / "photos" / f"{view.name}.png")
    ws, _ = Workspace.create(root / "ws", root / "photos")
    summary = run_sfm(ws, SfMConfig(intrinsics="kruppa", intrinsics_options=("refine=false",)))
    densify(ws, DenseConfig())
    make_mesh(ws, MeshConfig())
    return ws, summary, dataclasses.replace(scene, views=views)


def _align(model: pycolmap.Reconstruction, views):
    """x_true = f(x_est): camera 1's pose fixes rotation and origin, the baseline the scale."""
    est = sorted(model.images.values(), key=lambda im: im.name)
    e1, e2 = (im.cam_from_world().matrix() for im in est)
    t1, t2 = (v.cam_from_world for v in views)

    def centre(P):
        return -P[:, :3].T @ P[:, 3]

    scale = np.linalg.norm(centre(t2) - centre(t1)) / np.linalg.norm(centre(e2) - centre(e1))

    def to_true(points):
        in_cam1 = points @ e1[:, :3].T + e1[:, 3]
        return (scale * in_cam1 - t1[:, 3]) @ t1[:, :3]

    rotation_error = np.degrees(np.arccos(np.clip(
        (np.trace(t2[:, :3] @ t1[:, :3].T @ (e2[:, :3] @ e1[:, :3].T).T) - 1) / 2, -1, 1)))
    return to_true, rotation_error


def test_two_photos_give_a_metric_coloured_mesh(two_view_run):
    ws, summary, scene = two_view_run
    prior = summary.steps["intrinsics"].summary["cameras"][0]
    assert prior["prior"] and prior["source"].startswith("kruppa 1/1")
    assert prior["focal_px"] == pytest.approx(600.0, rel=0.02)  # Kruppa from one pair
    assert summary.mapping["registered"] == 2
    model = pycolmap.Reconstruction(ws.model_dir)
    to_true, rotation_error = _align(model, scene.views)
    assert rotation_error < 0.5  # degrees, relative rotation of the pair

    truth = visible_surface_points(scene)
    extent = float(np.linalg.norm(np.ptp(truth, axis=0)))
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth)))
    cloud = o3d.io.read_point_cloud(str(ws.dense_cloud_path))
    dense = to_true(np.asarray(cloud.points))
    distances = np.array([np.sqrt(tree.search_knn_vector_3d(p, 1)[2][0]) for p in dense[::20]])
    assert np.median(distances) < 0.005 * extent  # metres, after the similarity alignment
    assert np.mean(distances < 0.01 * extent) > 0.9
    assert cloud.has_colors() and np.asarray(cloud.colors).std() > 0.05
    mesh = o3d.io.read_triangle_mesh(str(ws.mesh_dir / "mesh.ply"))
    assert len(mesh.triangles) > 10_000 and mesh.has_vertex_colors()
