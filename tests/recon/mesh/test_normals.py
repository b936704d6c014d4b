"""Triangle-mesh normals against hand-computed values, a sphere's true normals and Open3D."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from recon.mesh.normals import face_normals, vertex_normals


def test_face_normals_and_areas_of_known_triangles() -> None:
    vertices = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 1]])  # counter-clockwise, reversed, degenerate
    normals, areas = face_normals(vertices, faces)
    np.testing.assert_array_equal(normals, [[0, 0, 1], [0, 0, -1], [0, 0, 0]])
    np.testing.assert_array_equal(areas, [3.0, 3.0, 0.0])


def test_vertex_normals_of_a_sphere_point_outwards_as_open3d_computes_them() -> None:
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=2.0, resolution=20)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    normals = vertex_normals(vertices, faces)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    # Within 2 degrees of the radial direction on a 20-segment sphere (the poles included).
    radial = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip((normals * radial).sum(axis=1), -1, 1))).max() < 2.0
    sphere.compute_vertex_normals()
    np.testing.assert_allclose(normals, np.asarray(sphere.vertex_normals), atol=1e-9)


def test_a_vertex_on_no_triangle_has_a_zero_normal() -> None:
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [5.0, 5.0, 5.0]])
    normals = vertex_normals(vertices, np.array([[0, 1, 2]]))
    np.testing.assert_array_equal(normals, [[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 0]])


def _numpy_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The numpy formula that `vertex_normals` compiled (before session 28): its reference."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    per_corner = np.repeat(np.cross(b - a, c - a), 3, axis=0)
    summed = np.stack([np.bincount(faces.ravel(), weights=per_corner[:, d],
                                   minlength=len(vertices)) for d in range(3)], axis=1)
    return summed / np.maximum(np.linalg.norm(summed, axis=1), 1e-300)[:, None]


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_vertex_normals_are_the_numpy_formulas_floats(dtype: type) -> None:
    # Compiled, the same floats: the tracker's results stay byte for byte what they were.
    rng = np.random.default_rng(7)
    vertices = rng.normal(size=(500, 3)).astype(dtype)
    faces = rng.integers(0, 500, size=(2000, 3)).astype(np.int32)
    np.testing.assert_array_equal(vertex_normals(vertices, faces),
                                  _numpy_vertex_normals(vertices, faces))
    with pytest.raises(IndexError, match="0..499"):
        vertex_normals(vertices, np.vstack([faces, [[0, 1, 500]]]))
