"""Joint forces and moments by Newton-Euler inverse dynamics, from the free extremities inwards.

Each segment is a rigid body with the mass, centre of mass and inertia of
`tracking.report.anthropometry` (de Leva 1996). For segment s with proximal joint p (its node's
origin), distal joints c (its children's proximal joints), centre of mass x, acceleration a,
angular velocity w and acceleration al (world axes), and inertia I = R I_node R^T:

    F_p = m (a - g) + sum_c F_c
    M_p = I al + w x (I w) - (p - x) x F_p + sum_c [M_c + (c - x) x F_c]

where F_p, M_p are the force and the moment about the joint centre that the proximal segment
exerts on s. Starting from the segments without children (head, hands, feet) the recursion runs
towards the pelvis; what is left there is the external load the environment must supply.

Assumptions, stated in every report (`ASSUMPTIONS`):

* No external force acts on the head, hands or feet: ground reaction forces cannot be seen on
  video. The arm, neck and spine loads are therefore right whenever nothing touches the hands
  or head. Leg loads are computed from free feet, so they are the true loads only while that
  foot is off the ground (swing); during stance they lack the ground reaction.
* The load left at the pelvis (``pelvis`` in the outputs: force and moment about the pelvis
  joint centre, in world axes) is the net external load on the body. When only the feet touch
  the ground it equals the total ground reaction (moved to the pelvis joint centre), which
  still cannot be split between the two feet without force plates.
* Segments are rigid, with de Leva's inertial parameters scaled to the subject's segment lengths
  and an assumed body mass; wrists and ankles are rigid in the body model.
* Gravity is -9.81 m/s^2 along the world Y axis (the body model's up axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.report.kinematics import CONVENTION_OF_JOINT, Kinematics

STANDARD_GRAVITY = 9.80665
GRAVITY_IN_WORLD: np.ndarray = np.array([0.0, -STANDARD_GRAVITY, 0.0])
GRAVITY_IN_WORLD.flags.writeable = False

ASSUMPTIONS: tuple[str, ...] = (
    "Ground reaction forces are unknown from video: no external force is assumed on the head, "
    "hands or feet, and the loads are solved from these free extremities towards the pelvis.",
    "Neck, spine, shoulder, elbow and wrist loads are valid whenever nothing touches the head "
    "or hands.",
    "Hip, knee and ankle loads are computed from free feet: they hold only while that foot is "
    "off the ground (swing); during stance they lack the ground reaction.",
    "The load left at the pelvis ('pelvis' row) is the net external load the environment must "
    "supply, in world axes about the pelvis joint centre: the total ground reaction when only "
    "the feet touch the ground (it cannot be split between the feet).",
    "Segments are rigid, with de Leva (1996) masses, centres of mass and inertias scaled to the "
    "subject's segment lengths and the stated body mass; wrists and ankles are rigid.",
    f"Gravity is {STANDARD_GRAVITY} m/s^2 along the world -Y axis.",
)


@dataclass(frozen=True)
class JointLoads:
    """Net joint loads per frame; NaN where the kinematics have no derivatives.

    joints: (S,) the proximal joint of each segment of ``Kinematics.segments`` ("pelvis": the
    external load). force_in_world: (T, S, 3) N, exerted by the proximal segment on the distal
    one. moment_in_world: (T, S, 3) N m about the joint centre. moment_anatomical: (T, S, 3)
    (flexion, abduction, rotation) components of that moment on the proximal segment's axes
    (the world's for the pelvis), signed like the joint angles of `tracking.report.kinematics`: a
    positive flexion moment pushes the joint towards flexion.
    """

    joints: tuple[str, ...]
    force_in_world: np.ndarray
    moment_in_world: np.ndarray
    moment_anatomical: np.ndarray


def inverse_dynamics(kin: Kinematics, gravity: np.ndarray = GRAVITY_IN_WORLD) -> JointLoads:
    """Newton-Euler joint loads of every segment's proximal joint (see the module docstring)."""
    seg = kin.segments
    n_frames, n_seg = len(kin.frames), len(seg.names)
    g = np.asarray(gravity, dtype=float)
    rot = kin.segment_rotation
    inertia = rot @ seg.inertia_in_node[None] @ np.swapaxes(rot, -1, -2)  # (T, S, 3, 3) world
    w, al = kin.segment_angular_velocity, kin.segment_angular_acceleration
    iw = np.einsum("tsij,tsj->tsi", inertia, w)
    dh = np.einsum("tsij,tsj->tsi", inertia, al) + np.cross(w, iw)  # rate of angular momentum
    joint = kin.world_from_node[:, seg.node][..., :3, 3]  # (T, S, 3) proximal joint centres
    x = kin.segment_com
    force = np.zeros((n_frames, n_seg, 3))
    moment = np.zeros((n_frames, n_seg, 3))
    # Segments are ordered parents first, so the reverse order visits children first.
    for s in reversed(range(n_seg)):
        f = seg.mass_kg[s] * (kin.segment_acceleration[:, s] - g)
        m = dh[:, s].copy()
        for c in np.flatnonzero(seg.parent == s):
            f += force[:, c]
            m += moment[:, c] + np.cross(joint[:, c] - x[:, s], force[:, c])
        m -= np.cross(joint[:, s] - x[:, s], f)
        force[:, s], moment[:, s] = f, m

    anatomical = np.empty_like(moment)
    for s, name in enumerate(seg.joint_names):
        parent = seg.parent[s]
        local = moment[:, s] if parent < 0 else np.einsum(
            "tji,tj->ti", rot[:, parent], moment[:, s])  # fmt: skip
        signs = np.array(CONVENTION_OF_JOINT[name].signs)
        anatomical[:, s] = local[:, [0, 2, 1]] * signs  # about X, Z, Y
    return JointLoads(seg.joint_names, force, moment, anatomical)
