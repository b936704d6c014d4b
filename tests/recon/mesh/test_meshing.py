"""Meshing against known surfaces: Poisson and ball pivoting, trimming, clean-up, mesh files."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import open3d as o3d
import pymeshlab
import pytest
from scipy.spatial import cKDTree

from recon.errors import UserError
from recon.evaluation.surface import sample_surface, surface_scores
from recon.mesh import meshing
from recon.mesh.meshing import (
    BallPivotingConfig,
    CleanupConfig,
    MeshingError,
    PoissonConfig,
    ball_pivoting_mesh,
    clean_mesh,
    linear_to_srgb,
    mean_point_spacing,
    poisson_mesh,
    srgb_to_linear,
    write_mesh,
)


def colour_of(points: np.ndarray) -> np.ndarray:
    """(N, 3) smooth colour field of world position (N, 3), so colours can be checked anywhere."""
    return np.clip(0.5 + 0.4 * np.sin(2.0 * points + np.array([0.0, 1.0, 2.0])), 0.0, 1.0)


def oriented_cloud(
    points: np.ndarray, normals: np.ndarray, *, with_colours: bool = True
) -> o3d.geometry.PointCloud:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    if with_colours:
        cloud.colors = o3d.utility.Vector3dVector(colour_of(points))
    return cloud


def noisy_cloud_on(
    mesh: o3d.geometry.TriangleMesh, n: int, *, noise: float, seed: int = 0
) -> o3d.geometry.PointCloud:
    """``n`` points uniformly on ``mesh`` with its (outward) face normals, plus Gaussian noise."""
    o3d.utility.random.seed(seed)
    sampled = mesh.sample_points_uniformly(n, use_triangle_normal=True)
    rng = np.random.default_rng(seed)
    points = np.asarray(sampled.points) + noise * rng.standard_normal((n, 3))
    return oriented_cloud(points, np.asarray(sampled.normals))


def boundary_edge_fraction(mesh: o3d.geometry.TriangleMesh) -> float:
    """Fraction of edges with one face (or more than two): 0 for a closed manifold surface."""
    bad = len(np.asarray(mesh.get_non_manifold_edges(allow_boundary_edges=False)))
    return bad / (1.5 * len(mesh.triangles))


SPHERE = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=100)  # extent 2
BOX = o3d.geometry.TriangleMesh.create_box(1.0, 1.0, 1.0)  # extent 1


# ---------------------------------------------------------------------------------------------
# Poisson


@pytest.mark.parametrize(("truth", "extent"), [(SPHERE, 2.0), (BOX, 1.0)], ids=["sphere", "box"])
def test_poisson_on_a_noisy_closed_surface_matches_the_truth(
    truth: o3d.geometry.TriangleMesh, extent: float
) -> None:
    cloud = noisy_cloud_on(truth, 30_000, noise=0.0025 * extent)
    mesh = poisson_mesh(cloud, PoissonConfig(depth=8))

    scores = surface_scores(mesh, truth, threshold=0.01 * extent, samples=100_000)
    assert scores.f_score >= 0.95, scores
    assert scores.accuracy < 0.002 * extent, scores
    # Closed in, closed out: the distance trim must not punch holes into a well-sampled surface.
    assert boundary_edge_fraction(mesh) < 1e-3
    # Colours are interpolated from the points: compare with the field they were drawn from.
    vertices = np.asarray(mesh.vertices)
    colour_error = np.abs(np.asarray(mesh.vertex_colors) - colour_of(vertices))
    assert mesh.has_vertex_colors() and np.median(colour_error) < 0.02


def test_the_density_quantile_trims_holes_into_a_closed_surface() -> None:
    """Why the density trim is off by default: it removes vertices wherever density is lowest."""
    cloud = noisy_cloud_on(SPHERE, 30_000, noise=0.005)
    trimmed = poisson_mesh(cloud, PoissonConfig(depth=8, density_quantile=0.02))
    assert boundary_edge_fraction(trimmed) > 3e-3


def hemisphere_cloud(rng: np.random.Generator) -> tuple[o3d.geometry.PointCloud, np.ndarray]:
    directions = rng.standard_normal((40_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions = directions[directions[:, 2] > 0]
    points = directions + 0.003 * rng.standard_normal(directions.shape)
    return oriented_cloud(points, directions), np.zeros((0, 3))


HOLES = np.array([[0.3, 0.3, 0.2], [-0.4, -0.2, 0.15], [0.2, -0.5, 0.25]])  # centre x, y, radius


def plane_with_holes_cloud(rng: np.random.Generator) -> tuple[o3d.geometry.PointCloud, np.ndarray]:
    xy = rng.uniform(-1.0, 1.0, (30_000, 2))
    to_centres = np.linalg.norm(xy[:, None, :] - HOLES[None, :, :2], axis=2)  # (N, holes)
    xy = xy[np.all(to_centres > HOLES[:, 2], axis=1)]
    points = np.column_stack([xy, 0.003 * rng.standard_normal(len(xy))])
    normals = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    return oriented_cloud(points, normals), HOLES


@pytest.mark.parametrize("make_cloud", [hemisphere_cloud, plane_with_holes_cloud])
def test_poisson_on_an_open_surface_grows_no_blobs_beyond_the_cloud(make_cloud) -> None:
    cloud, holes = make_cloud(np.random.default_rng(1))
    points = np.asarray(cloud.points)
    spacing = mean_point_spacing(points)
    tree = cKDTree(points)

    mesh = poisson_mesh(cloud, PoissonConfig(depth=8))
    samples = sample_surface(mesh, 100_000, seed=0)
    to_cloud, _ = tree.query(samples)
    assert to_cloud.max() < 4.0 * spacing  # max_distance_factor = 3, plus a face's interior
    assert np.quantile(to_cloud, 0.999) < 3.0 * spacing
    # ... while it still covers the cloud: (nearly) every point has the surface close by.
    assert surface_scores(mesh, points, threshold=2.0 * spacing).recall > 0.99
    # The holes of the plane stay holes: nothing nearer their centres than the trim allows.
    for cx, cy, radius in holes:
        inside = np.hypot(samples[:, 0] - cx, samples[:, 1] - cy) < radius - 4.0 * spacing
        assert not inside.any()

    # The control: untrimmed, Poisson closes the open surface far beyond the cloud.
    untrimmed = poisson_mesh(cloud, PoissonConfig(depth=8, max_distance_factor=0.0))
    to_cloud, _ = tree.query(sample_surface(untrimmed, 100_000, seed=0))
    assert np.mean(to_cloud > 3.0 * spacing) > 0.1


# ---------------------------------------------------------------------------------------------
# Ball pivoting


def test_ball_pivoting_on_a_noisy_sphere_matches_the_truth() -> None:
    cloud = noisy_cloud_on(SPHERE, 20_000, noise=0.002)
    mesh = ball_pivoting_mesh(cloud, BallPivotingConfig())
    scores = surface_scores(mesh, SPHERE, threshold=0.02, samples=100_000)
    assert scores.f_score >= 0.9, scores
    assert mesh.has_vertex_colors()
    # Its vertices are input points, so their colours are the points' exactly.
    vertices = np.asarray(mesh.vertices)
    assert np.allclose(np.asarray(mesh.vertex_colors), colour_of(vertices))


def test_ball_pivoting_on_a_plane_patch_matches_the_truth() -> None:
    rng = np.random.default_rng(2)
    xy = rng.uniform(-1.0, 1.0, (20_000, 2))
    points = np.column_stack([xy, np.zeros(len(xy))])
    cloud = oriented_cloud(points, np.tile([0.0, 0.0, 1.0], (len(xy), 1)))
    mesh = ball_pivoting_mesh(cloud, BallPivotingConfig(radii_factors=(1.0, 2.0)))
    truth = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]]),
        o3d.utility.Vector3iVector([[0, 1, 2], [0, 2, 3]]),
    )
    scores = surface_scores(mesh, truth, threshold=0.02, samples=100_000)
    assert scores.f_score >= 0.9, scores


# ---------------------------------------------------------------------------------------------
# Clouds that cannot be meshed


@pytest.mark.parametrize("mesher", [poisson_mesh, ball_pivoting_mesh])
def test_a_cloud_too_small_or_without_normals_raises_a_one_line_meshing_error(mesher) -> None:
    rng = np.random.default_rng(4)
    ten = oriented_cloud(rng.standard_normal((10, 3)), np.tile([0.0, 0.0, 1.0], (10, 1)))
    no_normals = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.standard_normal((500, 3))))
    config = PoissonConfig() if mesher is poisson_mesh else BallPivotingConfig()
    for cloud, words in [(ten, "10 points"), (no_normals, "no normals")]:
        with pytest.raises(MeshingError, match=words) as caught:
            mesher(cloud, config)
        assert "\n" not in str(caught.value)
        assert isinstance(caught.value, UserError) and isinstance(caught.value, ValueError)


# ---------------------------------------------------------------------------------------------
# Clean-up


def coloured(mesh: o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh(mesh)
    mesh.vertex_colors = o3d.utility.Vector3dVector(colour_of(np.asarray(mesh.vertices)))
    return mesh


def triangle_soup(mesh: o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    """Every face with three vertices of its own: each vertex duplicated ~6 times."""
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.triangles)].reshape(-1, 3)
    soup = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(corners),
        o3d.utility.Vector3iVector(np.arange(len(corners)).reshape(-1, 3)),
    )
    soup.vertex_colors = o3d.utility.Vector3dVector(colour_of(corners))
    return soup


def test_clean_mesh_removes_floaters_duplicates_and_non_manifold_faces() -> None:
    body = coloured(o3d.geometry.TriangleMesh.create_sphere(1.0, 40))  # 6,240 faces
    floater = o3d.geometry.TriangleMesh.create_sphere(0.05, 4).translate((3.0, 0.0, 0.0))  # 48
    soup = triangle_soup(body + coloured(floater))
    # A fin: a third face on an edge of the sphere makes that edge non-manifold.
    a, b = np.asarray(body.triangles)[0][:2]
    fin_vertices = np.asarray(body.vertices)[[a, b]]
    fin_vertices = np.vstack([fin_vertices, fin_vertices.mean(axis=0) * 1.3])
    fin = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(fin_vertices), o3d.utility.Vector3iVector([[0, 1, 2]])
    )
    dirty = soup + coloured(fin)
    welded = o3d.geometry.TriangleMesh(dirty).merge_close_vertices(1e-12)
    assert not welded.is_edge_manifold() and len(dirty.vertices) > 5 * len(body.vertices)

    cleaned = clean_mesh(dirty, CleanupConfig(min_component_fraction=0.01))

    vertices = np.asarray(cleaned.vertices)
    assert np.linalg.norm(vertices, axis=1).max() < 1.3  # the floater is gone
    # Duplicates merged: the sphere's own vertices, and perhaps the fin's tip.
    assert len(body.vertices) <= len(cleaned.vertices) <= len(body.vertices) + 1
    assert cleaned.is_edge_manifold(allow_boundary_edges=True) and cleaned.is_vertex_manifold()
    # MeshLab makes the edge manifold by removing the smaller faces on it (here the sphere's).
    assert len(body.triangles) - 2 <= len(cleaned.triangles) <= len(body.triangles)
    assert cleaned.has_vertex_colors() and cleaned.has_vertex_normals()
    colour_error = np.abs(np.asarray(cleaned.vertex_colors) - colour_of(vertices))
    assert colour_error.max() <= 0.5 / 255 + 1e-9  # MeshLab keeps 8 bits a channel
    # The control: without the component filter the floater stays.
    kept = clean_mesh(dirty, CleanupConfig(min_component_fraction=0.0))
    assert np.linalg.norm(np.asarray(kept.vertices), axis=1).max() > 2.9
    # The input was not modified.
    assert len(dirty.vertices) == len(soup.vertices) + 3


def test_clean_mesh_decimates_to_the_target_keeping_shape_and_colours() -> None:
    sphere = coloured(o3d.geometry.TriangleMesh.create_sphere(1.0, 100))  # 39,600 faces
    decimated = clean_mesh(sphere, CleanupConfig(target_faces=4000))
    assert 3600 <= len(decimated.triangles) <= 4400
    assert boundary_edge_fraction(decimated) == 0.0
    scores = surface_scores(decimated, SPHERE, threshold=0.01, samples=50_000)
    assert scores.f_score > 0.99, scores
    vertices = np.asarray(decimated.vertices)
    colour_error = np.abs(np.asarray(decimated.vertex_colors) - colour_of(vertices))
    assert np.median(colour_error) < 0.02 and colour_error.max() < 0.1


def test_clean_mesh_of_a_mesh_without_faces_is_a_meshing_error() -> None:
    with pytest.raises(MeshingError, match="no faces"):
        clean_mesh(o3d.geometry.TriangleMesh(), CleanupConfig())


# ---------------------------------------------------------------------------------------------
# Files


def read_glb(path: Path) -> tuple[dict, dict[str, np.ndarray], np.ndarray]:
    """A reader written from the glTF 2.0 spec: JSON document, attributes (N, 3), faces (F, 3)."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON" and json_length % 4 == 0
    document = json.loads(data[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", data, 20 + json_length)
    assert bin_type == b"BIN\x00" and bin_length % 4 == 0
    assert 28 + json_length + bin_length == len(data)
    binary = data[28 + json_length :]
    assert document["buffers"][0]["byteLength"] == bin_length

    def accessor(index: int) -> np.ndarray:
        spec = document["accessors"][index]
        view = document["bufferViews"][spec["bufferView"]]
        dtype = {5126: np.float32, 5125: np.uint32}[spec["componentType"]]
        width = {"VEC3": 3, "SCALAR": 1}[spec["type"]]
        values = np.frombuffer(
            binary, dtype, count=spec["count"] * width, offset=view["byteOffset"]
        )
        assert values.nbytes == view["byteLength"]
        return values.reshape(spec["count"], width)

    primitive = document["meshes"][0]["primitives"][0]
    assert primitive["mode"] == 4
    attributes = {name: accessor(i) for name, i in primitive["attributes"].items()}
    position = document["accessors"][primitive["attributes"]["POSITION"]]
    assert np.allclose(position["min"], attributes["POSITION"].min(axis=0))
    assert np.allclose(position["max"], attributes["POSITION"].max(axis=0))
    return document, attributes, accessor(primitive["indices"]).reshape(-1, 3)


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``v x y z r g b`` rows (V, 6) and 0-based faces (F, 3)."""
    lines = path.read_text().splitlines()
    rows = [line.split()[1:] for line in lines if line.startswith("v ")]
    faces = [line.split()[1:] for line in lines if line.startswith("f ")]
    return np.array(rows, dtype=np.float64), np.array(faces, dtype=np.int64) - 1


@pytest.fixture
def sphere_mesh() -> o3d.geometry.TriangleMesh:
    mesh = coloured(o3d.geometry.TriangleMesh.create_sphere(1.0, 30).translate((5.0, -2.0, 1.0)))
    mesh.compute_vertex_normals()
    return mesh


def test_write_mesh_writes_ply_obj_glb_that_read_back(
    tmp_path: Path, sphere_mesh: o3d.geometry.TriangleMesh
) -> None:
    vertices = np.asarray(sphere_mesh.vertices)
    faces = np.asarray(sphere_mesh.triangles)
    colours = np.asarray(sphere_mesh.vertex_colors)

    paths = write_mesh(sphere_mesh, tmp_path / "out" / "mesh.ply")

    assert [p.name for p in paths] == ["mesh.ply", "mesh.obj", "mesh.glb"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(p.name for p in paths)

    ply = o3d.io.read_triangle_mesh(str(paths[0]))
    assert np.array_equal(np.asarray(ply.triangles), faces)
    assert np.allclose(np.asarray(ply.vertices), vertices)
    assert np.abs(np.asarray(ply.vertex_colors) - colours).max() <= 0.5 / 255 + 1e-9
    assert paths[0].read_bytes().startswith(b"ply\nformat binary_little_endian")

    rows, obj_faces = read_obj(paths[1])
    assert np.array_equal(obj_faces, faces)
    assert np.allclose(rows[:, :3], vertices, rtol=0, atol=1e-7)
    assert np.allclose(rows[:, 3:], colours, rtol=0, atol=1e-5)
    meshset = pymeshlab.MeshSet()
    meshset.load_new_mesh(str(paths[1]))  # MeshLab knows the "v x y z r g b" extension
    assert meshset.current_mesh().face_number() == len(faces)
    assert np.abs(meshset.current_mesh().vertex_color_matrix()[:, :3] - colours).max() < 1 / 255

    document, attributes, glb_faces = read_glb(paths[2])
    assert np.array_equal(glb_faces, faces)
    assert np.allclose(attributes["POSITION"], vertices, rtol=1e-7)
    assert np.allclose(np.linalg.norm(attributes["NORMAL"], axis=1), 1.0, atol=1e-6)
    assert np.allclose(linear_to_srgb(attributes["COLOR_0"]), colours, atol=1e-5)
    assert document["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    # An independent reader (Assimp, inside Open3D) reads the same mesh, vertices reordered.
    glb = o3d.io.read_triangle_mesh(str(paths[2]))
    assert len(glb.vertices) == len(vertices) and len(glb.triangles) == len(faces)
    _, order = cKDTree(vertices).query(np.asarray(glb.vertices))
    assert np.allclose(np.asarray(glb.vertex_colors), srgb_to_linear(colours[order]), atol=1e-6)


def test_write_mesh_that_fails_leaves_no_file_and_keeps_the_old_ones(
    tmp_path: Path, sphere_mesh: o3d.geometry.TriangleMesh, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "mesh.obj").write_text("old\n")

    def half_write_then_fail(path: Path, mesh: o3d.geometry.TriangleMesh) -> None:
        path.write_bytes(b"glTF half")
        raise OSError("disk full")

    monkeypatch.setitem(meshing._WRITERS, ".glb", half_write_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_mesh(sphere_mesh, tmp_path / "mesh.ply")
    assert [p.name for p in tmp_path.iterdir()] == ["mesh.obj"]
    assert (tmp_path / "mesh.obj").read_text() == "old\n"


def test_write_mesh_rejects_what_it_cannot_write(
    tmp_path: Path, sphere_mesh: o3d.geometry.TriangleMesh
) -> None:
    with pytest.raises(ValueError, match=r"\.ply"):
        write_mesh(sphere_mesh, tmp_path / "mesh.obj")
    with pytest.raises(ValueError, match=r"\.stl"):
        write_mesh(sphere_mesh, tmp_path / "mesh.ply", also=(".stl",))
    with pytest.raises(MeshingError, match="no faces"):
        write_mesh(o3d.geometry.TriangleMesh(), tmp_path / "mesh.ply")
    assert list(tmp_path.iterdir()) == []
    assert [p.name for p in write_mesh(sphere_mesh, tmp_path / "m.ply", also=())] == ["m.ply"]


def test_srgb_linear_round_trip() -> None:
    values = np.linspace(0.0, 1.0, 1001)
    assert np.allclose(linear_to_srgb(srgb_to_linear(values)), values, atol=1e-12)
    assert srgb_to_linear(np.array([0.5]))[0] == pytest.approx(0.21404, abs=1e-5)
