"""Multi-view consistency filtering and point-cloud fusion against the synthetic room."""

from __future__ import annotations

import dataclasses

import numpy as np
import open3d
import pytest

from recon.dense.backends import stereo_pair_depths
from recon.dense.fusion import FusionConfig, filter_consistent, fuse
from recon.dense.stereo import DepthMap, StereoConfig, View, select_pairs
from recon.evaluation.synthetic_room import (
    ROOM_MAX,
    ROOM_MIN,
    SyntheticSceneConfig,
    render_scene,
    scene_quads,
)
from tests.recon.dense.test_stereo import Truth, depth_seen, distance_to_scene, scene_truths

# The room's diagonal, metres: the "scene extent" of the accuracy criteria.
EXTENT_M = float(np.linalg.norm(ROOM_MAX - ROOM_MIN))


@pytest.fixture(scope="module")
def truths() -> list[Truth]:
    return scene_truths(render_scene(SyntheticSceneConfig(num_views=6)))


@pytest.fixture(scope="module")
def views(truths: list[Truth]) -> list[View]:
    return [t.view for t in truths]


@pytest.fixture(scope="module")
def depths(views: list[View]) -> list[DepthMap]:
    config = StereoConfig()
    # As the cpu-stereo backend computes them: both maps of every pair, in pair order.
    return [m for pair in select_pairs(views, config)
            for m in stereo_pair_depths(pair, views, config)]


def gross_error_fraction(maps: list[DepthMap], truths: list[Truth], tol: float = 0.05) -> float:
    errors = []
    for m in maps:
        truth = truths[m.view].depth
        both = np.isfinite(m.depth) & np.isfinite(truth)
        errors.append(np.abs(m.depth[both] - truth[both]) / truth[both])
    return float(np.mean(np.concatenate(errors) > tol))


def test_filter_consistent_drops_injected_outliers_and_keeps_true_depths(
    depths: list[DepthMap], views: list[View], truths: list[Truth]
):
    rng = np.random.default_rng(3)
    target = 2
    original = depths[target]
    rows, cols = np.nonzero(np.isfinite(original.depth))
    pick = rng.choice(len(rows), 3000, replace=False)
    # Wrong by 7-25 %, in front of the surface (free space) or behind it (occluded elsewhere).
    factors = 1.0 + rng.choice([-1.0, 1.0], len(pick)) * rng.uniform(0.07, 0.25, len(pick))
    corrupted = original.depth.copy()
    corrupted[rows[pick], cols[pick]] *= factors
    maps = list(depths)
    maps[target] = DepthMap(original.view, original.source, corrupted)

    kept = filter_consistent(maps, views, FusionConfig())
    assert [(m.view, m.source) for m in kept] == [(m.view, m.source) for m in maps]
    survived = np.isfinite(kept[target].depth[rows[pick], cols[pick]])
    assert survived[factors < 1].mean() < 0.02 and survived[factors > 1].mean() < 0.02
    truth = truths[original.view].depth
    good = np.isfinite(original.depth) & (np.abs(original.depth - truth) < 0.005 * truth)
    good[rows[pick], cols[pick]] = False
    assert np.isfinite(kept[target].depth[good]).mean() > 0.7
    # Kept values are untouched; nothing is added.
    finite = np.isfinite(kept[target].depth)
    np.testing.assert_array_equal(kept[target].depth[finite], corrupted[finite])
    # Without the requirement the outliers stay: the check above measures the filter.
    unfiltered = filter_consistent(maps, views, FusionConfig(min_consistent_views=0))
    assert np.isfinite(unfiltered[target].depth[rows[pick], cols[pick]]).all()


def test_filter_consistent_removes_stereo_errors(
    depths: list[DepthMap], views: list[View], truths: list[Truth]
):
    before = gross_error_fraction(depths, truths, tol=0.02)
    after = gross_error_fraction(filter_consistent(depths, views, FusionConfig()), truths, 0.02)
    assert after < 0.01 and after < 0.5 * before


def test_same_pair_is_not_evidence(depths: list[DepthMap], views: list[View]):
    # Only one stereo pair: its two maps agree by construction, which must not count.
    pair = [m for m in depths if {m.view, m.source} == {depths[0].view, depths[0].source}]
    assert len(pair) == 2
    kept = filter_consistent(pair, views, FusionConfig(min_consistent_views=1))
    assert all(np.isnan(m.depth).all() for m in kept)


def nearest_face_normals(points_in_world: np.ndarray) -> np.ndarray:
    """(N, 3) outward (seen-side) unit normal of the scene face nearest to each point."""
    quads = scene_quads()
    best = np.full(len(points_in_world), np.inf)
    normals = np.zeros((len(points_in_world), 3))
    for quad in quads:
        offset = points_in_world - quad.origin
        u = np.clip(offset @ quad.edge_u / (quad.edge_u @ quad.edge_u), 0, 1)
        v = np.clip(offset @ quad.edge_v / (quad.edge_v @ quad.edge_v), 0, 1)
        distance = np.linalg.norm(
            offset - u[:, None] * quad.edge_u - v[:, None] * quad.edge_v, axis=1
        )
        closer = distance < best
        best[closer] = distance[closer]
        normals[closer] = quad.normal
    return normals


@pytest.fixture(scope="module")
def cloud(depths: list[DepthMap], views: list[View]) -> open3d.geometry.PointCloud:
    return fuse(depths, views, FusionConfig())


def test_fused_points_lie_on_the_scene(cloud: open3d.geometry.PointCloud):
    points = np.asarray(cloud.points)
    assert len(points) > 20000
    distance = distance_to_scene(points)
    assert np.mean(distance < 0.01 * EXTENT_M) > 0.95
    # Much tighter than the criterion: depth errors are ~0.2 % at 2-5 m.
    assert np.mean(distance < 0.02) > 0.9


def test_fused_normals_face_the_cameras(cloud: open3d.geometry.PointCloud):
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    true_normals = nearest_face_normals(points)
    cos = np.sum(normals * true_normals, axis=1)
    # Scene faces are seen from their normal's side, so facing the cameras = agreeing in sign.
    assert np.mean(cos > 0) > 0.98
    assert np.median(np.degrees(np.arccos(np.clip(cos, -1, 1)))) < 15.0


def test_fused_colours_are_the_images_colours(
    cloud: open3d.geometry.PointCloud, truths: list[Truth]
):
    points, colours = np.asarray(cloud.points), np.asarray(cloud.colors)
    assert colours.shape == points.shape and colours.min() >= 0 and colours.max() <= 1
    truth = truths[2]
    z, seen = depth_seen(truth, points)
    visible = np.abs(z - seen) < 0.01 * z
    assert visible.sum() > 10000
    R, t = truth.view.cam_from_world[:, :3], truth.view.cam_from_world[:, 3]
    projected = (points[visible] @ R.T + t) @ truth.view.K.T
    cols = np.floor(projected[:, 0] / projected[:, 2]).astype(int)
    rows = np.floor(projected[:, 1] / projected[:, 2]).astype(int)
    rgb = truth.view.image_bgr[rows, cols][:, ::-1].astype(float)
    difference = np.abs(rgb - 255 * colours[visible]).mean(axis=1)
    # Swapped channels or colours from the wrong pixel differ by ~50 levels on these textures.
    assert np.median(difference) < 8.0


def test_voxel_size_sets_the_density(
    depths: list[DepthMap], views: list[View], cloud: open3d.geometry.PointCloud
):
    coarse = fuse(depths, views, FusionConfig(voxel_size=0.1))
    points = np.asarray(coarse.points)
    assert 0 < len(points) < len(cloud.points) / 4
    # One merged point per occupied voxel: neighbours about a voxel side apart.
    spacing = np.median(np.asarray(coarse.compute_nearest_neighbor_distance()))
    assert 0.05 < spacing < 0.12


def test_fuse_without_depth_gives_an_empty_cloud(depths: list[DepthMap], views: list[View]):
    empty = [dataclasses.replace(d, depth=np.full_like(d.depth, np.nan)) for d in depths]
    assert len(fuse(empty, views, FusionConfig()).points) == 0
    assert len(fuse([], views, FusionConfig()).points) == 0


def test_config_validation():
    with pytest.raises(ValueError, match="rel_depth_tol"):
        FusionConfig(rel_depth_tol=0.0)
    with pytest.raises(ValueError, match="voxel_size"):
        FusionConfig(voxel_size=-1.0)
    for f in dataclasses.fields(FusionConfig):
        assert f.metadata.get("help"), f.name
