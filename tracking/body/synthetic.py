"""Synthetic data with known answers for the tracking package: random in-limits poses and
point clouds sampled from a posed body, noisy and partly hidden as one viewpoint would see it.
"""

from __future__ import annotations

import numpy as np

from tracking.body.model import LOWER_LIMITS, PARAM_INDEX, UPPER_LIMITS, BodyModel, Pose


def random_pose(rng: np.random.Generator, spread: float = 0.6) -> Pose:
    """An upright pose with random joint angles drawn from the middle `spread` of every joint's
    range (the full range gives contortions no one holds), a random heading and a random pelvis
    position within 1 m of the origin. Roll and pitch of the whole body stay within 10 degrees.
    """
    # Translations have no limits; they are drawn below.
    lo = np.where(np.isfinite(LOWER_LIMITS), LOWER_LIMITS, 0.0)
    hi = np.where(np.isfinite(UPPER_LIMITS), UPPER_LIMITS, 0.0)
    mid, half = (lo + hi) / 2, (hi - lo) / 2 * spread
    params = rng.uniform(mid - half, mid + half)
    for name in ("root_tx", "root_tz"):
        params[PARAM_INDEX[name]] = rng.uniform(-1.0, 1.0)
    params[PARAM_INDEX["root_ty"]] = rng.uniform(0.8, 1.0)
    for name in ("root_rz", "root_rx"):
        params[PARAM_INDEX[name]] = np.deg2rad(rng.uniform(-10.0, 10.0))
    params[PARAM_INDEX["root_ry"]] = rng.uniform(-np.pi, np.pi)
    return Pose(params)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) unit outward normals and (F,) areas of a counter-clockwise triangle mesh."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    norm = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(norm, 1e-300)[:, None], norm / 2


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """`count` points uniformly over the surface (area-weighted) and their face normals."""
    normals, areas = face_normals(vertices, faces)
    tri = rng.choice(len(faces), size=count, p=areas / areas.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = (vertices[faces[tri, k]] for k in range(3))
    return a + u[:, None] * (b - a) + v[:, None] * (c - a), normals[tri]


def body_cloud(
    model: BodyModel,
    pose: Pose,
    rng: np.random.Generator,
    count: int = 5000,
    noise_m: float = 0.005,
    hidden_fraction: float = 0.3,
    view_in_world: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A point cloud of the posed body: points (N, 3) and their true normals (N, 3), metres.

    The `hidden_fraction` of the surface that faces away from the viewing direction most is
    removed (a viewpoint on one side sees the front, not the back); then isotropic Gaussian noise
    of `noise_m` per axis is added to the positions. view_in_world: (3,) direction from the
    viewer towards the body, default a random horizontal one. N is about count * (1 - hidden).
    """
    points, normals = sample_surface(model.posed_vertices(pose), model.faces, count, rng)
    if view_in_world is None:
        angle = rng.uniform(0, 2 * np.pi)
        view_in_world = np.array([np.cos(angle), 0.0, np.sin(angle)])
    facing = -(normals @ np.asarray(view_in_world, dtype=float))
    keep = facing >= np.quantile(facing, hidden_fraction)
    points = points[keep] + rng.normal(0.0, noise_m, size=(int(keep.sum()), 3))
    return points, normals[keep]
