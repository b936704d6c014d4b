"""Synthetic data with known answers for the tracking package: random in-limits poses, point
clouds sampled from a posed body (noisy and partly hidden as one viewpoint would see it), and a
steady walk (`walking_poses`) to drive synthetic sequences.
"""

from __future__ import annotations

import numpy as np

from recon.mesh.normals import face_normals
from tracking.body.model import (
    LOWER_LIMITS,
    PARAM_INDEX,
    UPPER_LIMITS,
    BodyShape,
    Pose,
    TrackedModel,
)


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
    model: TrackedModel,
    pose: Pose,
    rng: np.random.Generator,
    count: int = 5000,
    noise_m: float = 0.005,
    hidden_fraction: float = 0.3,
    view_in_world: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A point cloud of the posed body (any `TrackedModel`: the superquadrics, or e.g. the
    skinned `tracking.body.mpfb.subject.MpfbModel`): points (N, 3) and their true normals
    (N, 3), metres.

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


def walking_poses(frames: int, frame_rate: float, shape: BodyShape, *,
                  speed_m_s: float = 1.2, cadence_hz: float = 0.9, heading_deg: float = 20.0,
                  start_in_world: tuple[float, float] = (-0.3, -0.3),
                  phase_deg: float = 0.0, arm_abduction_deg: float = 12.0,
                  ) -> list[Pose]:  # fmt: skip
    """`frames` poses of a steady walk at `frame_rate`, for synthetic sequences with a known
    answer: the pelvis moves at `speed_m_s` along the heading (degrees from world +Z towards
    +X; the body faces +Z at rest) from (x, z) = `start_in_world`, and bobs 2 cm twice per
    stride; `cadence_hz` strides per second (one stride: a step of each leg), starting at
    `phase_deg` of the stride (0: the legs together, the left one swinging forward; 90: the
    left leg forward, the legs furthest apart). Hips swing by +-23 degrees in opposition, the
    swinging leg's knee bends up to 45 degrees, the arms swing against the legs, held
    `arm_abduction_deg` away from the trunk, with the elbows bent, the trunk leans forward 3
    degrees. Y up, the soles
    at height 0 when the legs are straight (the pelvis at the hip height of `shape`)."""
    heading, abduction = np.deg2rad(heading_deg), np.deg2rad(arm_abduction_deg)
    forward = np.array([np.sin(heading), np.cos(heading)])  # (x, z)
    poses = []
    for k in range(frames):
        t = k / frame_rate
        phase = 2 * np.pi * cadence_hz * t + np.deg2rad(phase_deg)
        swing = np.sin(phase)
        x, z = np.asarray(start_in_world, dtype=float) + speed_m_s * t * forward
        poses.append(Pose.from_dict({
            "root_tx": x, "root_ty": shape.hip_height - 0.03 + 0.01 * np.cos(2 * phase),
            "root_tz": z, "root_ry": heading,
            "spine_flex": 0.05, "neck_flex": -0.05,
            # Hip flexion is negative about X; the leg swinging forward bends its knee.
            "l_hip_rx": -0.4 * swing, "r_hip_rx": 0.4 * swing,
            "l_knee_flex": 0.1 + 0.7 * max(np.sin(phase + 0.6), 0.0),
            "r_knee_flex": 0.1 + 0.7 * max(-np.sin(phase + 0.6), 0.0),
            "l_shoulder_rx": 0.35 * swing, "r_shoulder_rx": -0.35 * swing,
            "l_shoulder_rz": abduction, "r_shoulder_rz": -abduction,
            "l_elbow_flex": 0.35 + 0.15 * max(-swing, 0.0),
            "r_elbow_flex": 0.35 + 0.15 * max(swing, 0.0),
        }))  # fmt: skip
    return poses
