"""Surface scores, point-to-mesh distances and the ray-cast picture, against exact answers."""

from __future__ import annotations

import math
import time
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pytest

from recon.evaluation.surface import (
    BACKGROUND_RGB,
    RenderView,
    framing_camera,
    points_to_mesh_distance,
    render_mesh,
    render_mesh_png,
    sample_surface,
    surface_scores,
)


def plane_patch(z: float = 0.0, half: float = 1.0) -> o3d.geometry.TriangleMesh:
    """The square [-half, half]² at height z, two triangles."""
    corners = [[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]]
    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.array(corners, dtype=np.float64)),
        o3d.utility.Vector3iVector([[0, 1, 2], [0, 2, 3]]),
    )


def unit_sphere(resolution: int = 100) -> o3d.geometry.TriangleMesh:
    return o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)


# ---------------------------------------------------------------------------------------------
# Sampling


def test_sample_surface_is_uniform_by_area_on_the_mesh_and_seeded() -> None:
    # Two triangles of areas 0.5 and 1.5, apart in x so each sample tells which it is on.
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(
            [[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [8, 0, 0], [5, 1, 0.0]]
        ),
        o3d.utility.Vector3iVector([[0, 1, 2], [3, 4, 5]]),
    )
    samples = sample_surface(mesh, 100_000, seed=7)
    assert samples.shape == (100_000, 3)
    assert np.mean(samples[:, 0] >= 5) == pytest.approx(0.75, abs=0.01)
    assert np.abs(points_to_mesh_distance(samples, mesh)).max() < 1e-6
    # Uniform within a triangle: the mean is the centroid.
    first = samples[samples[:, 0] < 5]
    assert np.allclose(first.mean(axis=0), [1 / 3, 1 / 3, 0], atol=0.005)
    assert np.array_equal(samples, sample_surface(mesh, 100_000, seed=7))
    assert not np.array_equal(samples, sample_surface(mesh, 100_000, seed=8))


# ---------------------------------------------------------------------------------------------
# Distances


def test_points_to_mesh_distance_to_a_box_is_exact() -> None:
    # Far from the origin (as COLMAP models can be): float32 queries there would be off by 3e-5.
    corner = np.array([1234.567, -987.6543, 4321.0987])
    box = o3d.geometry.TriangleMesh.create_box(2.0, 2.0, 2.0).translate(corner)
    centre = corner + 1.0
    offsets_and_distances = [
        ([3.1, 0.2, -0.4], 2.1),  # beside a face
        ([1.7, 1.9, 0.33], math.hypot(0.7, 0.9)),  # beside an edge
        ([2.3, -3.1, 4.2], math.sqrt(1.3**2 + 2.1**2 + 3.2**2)),  # beside a corner
        ([0.25, 0.1, 0.0], 0.75),  # inside: unsigned distance to the nearest face
        ([1.0, 0.3, 0.3], 0.0),  # on a face
    ]
    points = centre + np.array([offset for offset, _ in offsets_and_distances])
    expected = np.array([distance for _, distance in offsets_and_distances])
    assert np.allclose(points_to_mesh_distance(points, box), expected, rtol=0, atol=2e-6)


def test_points_to_mesh_distance_to_a_unit_sphere_is_exact() -> None:
    sphere = unit_sphere(100)
    vertices = np.asarray(sphere.vertices)
    triangles = np.asarray(sphere.triangles)
    corners = vertices[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # The mesh lies between the sphere and the nearest plane of its faces to the centre.
    inner_radius = np.abs(np.sum(normals * corners[:, 0], axis=1)).min()
    sagitta = 1.0 - inner_radius
    assert 0 < sagitta < 1e-3

    rng = np.random.default_rng(0)
    directions = rng.standard_normal((20_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = rng.uniform(0.2, 3.0, len(directions))
    distances = points_to_mesh_distance(directions * radii[:, None], sphere)

    outside, inside = radii > 1, radii < inner_radius
    slack = 1e-6  # float32 queries
    assert np.all(distances[outside] >= radii[outside] - 1 - slack)
    assert np.all(distances[outside] <= radii[outside] - inner_radius + slack)
    assert np.all(distances[inside] <= 1 - radii[inside] + slack)
    assert np.all(distances[inside] >= inner_radius - radii[inside] - slack)
    assert np.allclose(points_to_mesh_distance(vertices, sphere), 0.0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Scores


def test_identical_meshes_score_perfectly() -> None:
    sphere = unit_sphere(60)
    scores = surface_scores(sphere, sphere, threshold=0.01, samples=50_000)
    assert scores.precision == scores.recall == scores.f_score == 1.0
    assert scores.accuracy < 1e-6 and scores.completeness < 1e-6 and scores.chamfer < 1e-6
    assert scores.threshold == 0.01


def test_a_plane_shifted_by_two_thresholds_scores_zero_and_the_shift_as_distance() -> None:
    tau = 0.01
    truth, shifted = plane_patch(0.0), plane_patch(2 * tau)
    scores = surface_scores(shifted, truth, threshold=tau, samples=50_000)
    assert scores.precision == scores.recall == scores.f_score == 0.0
    for distance in (scores.accuracy, scores.accuracy_median, scores.completeness, scores.chamfer):
        assert distance == pytest.approx(2 * tau, abs=1e-6)


def test_a_sphere_shifted_by_two_thresholds_keeps_half_its_surface_within_tau() -> None:
    """Shifted by d along x, a point at angle θ from x is d |cos θ| off: within τ = d/2 when
    |cos θ| < 1/2, which is half the sphere's area (cos θ is uniform on a sphere)."""
    tau = 0.01
    sphere = unit_sphere(100)
    shifted = o3d.geometry.TriangleMesh(sphere).translate((2 * tau, 0.0, 0.0))
    scores = surface_scores(shifted, sphere, threshold=tau, samples=100_000)
    assert scores.precision == pytest.approx(0.5, abs=0.02)
    assert scores.recall == pytest.approx(0.5, abs=0.02)
    assert scores.f_score == pytest.approx(0.5, abs=0.02)
    assert scores.accuracy == pytest.approx(tau, rel=0.03)  # mean of 2τ |cos θ| is τ


def test_half_a_plane_has_full_precision_half_recall_and_known_completeness() -> None:
    tau = 0.01
    truth = plane_patch(0.0)  # [-1, 1]²
    half = o3d.geometry.TriangleMesh(  # [-1, 0] x [-1, 1]
        o3d.utility.Vector3dVector([[-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0.0]]),
        o3d.utility.Vector3iVector([[0, 1, 2], [0, 2, 3]]),
    )
    scores = surface_scores(half, truth, threshold=tau, samples=100_000)
    assert scores.precision == 1.0 and scores.accuracy < 1e-6
    # Truth points with x in (0, tau) are within tau: recall is (1 + tau) / 2.
    assert scores.recall == pytest.approx((1 + tau) / 2, abs=0.01)
    # Half the truth is at distance 0, the other half at x ~ U(0, 1): mean 1/4, median ~0.
    assert scores.completeness == pytest.approx(0.25, abs=0.005)
    assert scores.completeness_median == pytest.approx(0.0, abs=0.01)
    assert scores.f_score == pytest.approx(2 * scores.recall / (1 + scores.recall))
    assert scores.chamfer == pytest.approx((scores.accuracy + scores.completeness) / 2)
    assert scores.chamfer == pytest.approx(0.125, abs=0.003)


def test_point_sets_are_scored_by_nearest_points_and_an_empty_reconstruction_by_zero() -> None:
    rng = np.random.default_rng(1)
    points = rng.uniform(-1, 1, (5_000, 3))
    scores = surface_scores(points, points, threshold=1e-3)
    assert scores.f_score == 1.0 and scores.chamfer == 0.0
    moved = points + np.array([0.0, 0.0, 0.5])
    assert surface_scores(moved, points, threshold=1e-3).f_score < 0.05

    empty = surface_scores(np.zeros((0, 3)), points, threshold=0.1)
    assert empty.f_score == 0.0 and math.isinf(empty.accuracy)
    with pytest.raises(ValueError, match="threshold"):
        surface_scores(points, points, threshold=0.0)
    with pytest.raises(ValueError, match="truth is empty"):
        surface_scores(points, o3d.geometry.TriangleMesh(), threshold=0.1)


# ---------------------------------------------------------------------------------------------
# Pictures


def projection_mask(
    mesh: o3d.geometry.TriangleMesh, K: np.ndarray, cam_from_world: np.ndarray, size: tuple
) -> np.ndarray:
    """(H, W) bool: pixels whose centre (i + 0.5, j + 0.5) falls in the projection of a face."""
    height, width = size
    in_camera = np.asarray(mesh.vertices) @ cam_from_world[:, :3].T + cam_from_world[:, 3]
    assert np.all(in_camera[:, 2] > 0)
    projected = in_camera @ K.T
    projected = projected[:, :2] / projected[:, 2:]
    cols, rows = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    centres = np.stack([cols, rows], axis=-1)  # (H, W, 2)
    mask = np.zeros((height, width), dtype=bool)
    for a, b, c in projected[np.asarray(mesh.triangles)]:
        # Inside when the three edge functions (2-D cross products) agree in sign, either winding.
        edges = [
            (q[0] - p[0]) * (centres[..., 1] - p[1]) - (q[1] - p[1]) * (centres[..., 0] - p[0])
            for p, q in ((a, b), (b, c), (c, a))
        ]
        mask |= np.all([e >= 0 for e in edges], axis=0) | np.all([e <= 0 for e in edges], axis=0)
    return mask


def test_render_mesh_png_shows_the_object_where_it_projects(tmp_path: Path) -> None:
    # An oblong box far from the origin, in one colour, so every lit pixel is that colour.
    box = o3d.geometry.TriangleMesh.create_box(2.0, 1.0, 0.5).translate((5.0, -3.0, 10.0))
    box.vertex_colors = o3d.utility.Vector3dVector(np.tile([0.2, 0.6, 1.0], (8, 1)))
    view = RenderView(azimuth_deg=35.0, elevation_deg=25.0)
    path = render_mesh_png(box, tmp_path / "box.png", width=320, height=240, view=view)
    assert path == tmp_path / "box.png" and list(tmp_path.iterdir()) == [path]

    image = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
    assert image.shape == (240, 320, 3)
    foreground = np.any(image != np.array(BACKGROUND_RGB, dtype=np.uint8), axis=2)
    K, cam_from_world = framing_camera(box, width=320, height=240, view=view)
    expected = projection_mask(box, K, cam_from_world, (240, 320))
    # Pixel-exact: a half-pixel error in the camera would differ in ~270 pixels.
    assert np.sum(foreground ^ expected) <= 5, np.sum(foreground ^ expected)
    assert 0.05 < foreground.mean() < 0.6  # framed: visible, and not cut off
    assert not (foreground[0].any() or foreground[-1].any())
    assert not (foreground[:, 0].any() or foreground[:, -1].any())
    # Colour times a Lambert term: the hue is kept, and differently turned faces differ.
    rgb = image[foreground].astype(np.float64)
    bright = rgb[:, 2] > 100
    assert np.allclose(rgb[bright, 0] / rgb[bright, 2], 0.2, atol=0.02)
    assert np.allclose(rgb[bright, 1] / rgb[bright, 2], 0.6, atol=0.02)
    assert len(np.unique(rgb[:, 2])) >= 3  # three faces of a box are seen, lit differently


def project(K: np.ndarray, cam_from_world: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(2,) pixel coordinates of a world point (3,)."""
    x = K @ (cam_from_world[:, :3] @ point + cam_from_world[:, 3])
    return x[:2] / x[2]


def test_framing_camera_looks_from_the_view_direction_with_up_upwards() -> None:
    box = o3d.geometry.TriangleMesh.create_box(1.0, 3.0, 2.0).translate((-4.0, 7.0, 1.0))
    centre = np.array([-3.5, 8.5, 2.0])
    cases = [  # azimuth, elevation, up, the unit vector from the centre to the eye
        (0.0, 0.0, (0.0, 0.0, 1.0), [1.0, 0.0, 0.0]),
        (90.0, 0.0, (0.0, 0.0, 1.0), [0.0, 1.0, 0.0]),
        (0.0, 30.0, (0.0, 0.0, 1.0), [math.sqrt(3) / 2, 0.0, 0.5]),
        (0.0, 0.0, (0.0, 1.0, 0.0), [1.0, 0.0, 0.0]),
    ]
    for azimuth, elevation, up, towards_eye in cases:
        view = RenderView(azimuth_deg=azimuth, elevation_deg=elevation, up=up)
        K, cam_from_world = framing_camera(box, width=400, height=300, view=view)
        rotation = cam_from_world[:, :3]
        assert np.allclose(rotation @ rotation.T, np.eye(3)) and np.linalg.det(rotation) > 0
        assert np.allclose(rotation[2], -np.array(towards_eye))  # the optical axis
        assert np.allclose(project(K, cam_from_world, centre), [200.0, 150.0])
        above = project(K, cam_from_world, centre + 0.1 * np.array(up))
        assert above[1] < 150.0 and above[0] == pytest.approx(200.0)  # up is up, not tilted


def test_render_mesh_interpolates_vertex_colours_barycentrically() -> None:
    # A triangle in the plane z = 0 with red, green and blue corners, seen from straight above.
    triangle = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]),
        o3d.utility.Vector3iVector([[0, 1, 2]]),
    )
    triangle.vertex_colors = o3d.utility.Vector3dVector(np.eye(3))
    view = RenderView(elevation_deg=89.0, up=(0.0, 0.0, 1.0))
    rendering = render_mesh(triangle, width=201, height=201, view=view)
    K, cam_from_world = rendering.K, rendering.cam_from_world

    weights = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8], [1 / 3, 1 / 3, 1 / 3]])
    corners = np.asarray(triangle.vertices)
    for w in weights:
        col, row = project(K, cam_from_world, w @ corners).astype(int)
        assert rendering.hit[row, col]
        colour = rendering.image_rgb[row, col].astype(np.float64)
        # Up to the pixel's offset from the exact point (~1/100 of the triangle a pixel).
        assert np.allclose(colour / colour.sum(), w, atol=0.03), (w, colour)


def test_render_mesh_png_at_the_default_size_takes_about_a_second(tmp_path: Path) -> None:
    sphere = unit_sphere(150)  # 89,400 faces
    sphere.vertex_colors = o3d.utility.Vector3dVector(0.5 + 0.5 * np.asarray(sphere.vertices))
    start = time.perf_counter()
    path = render_mesh_png(sphere, tmp_path / "sphere.png")
    elapsed = time.perf_counter() - start
    assert cv2.imread(str(path)).shape == (600, 800, 3)
    assert elapsed < 3.0, elapsed
