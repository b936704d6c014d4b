"""A pose of the thesis' layout (`tracking.body.model`) on MPFB2's ``cmu_mb`` rig.

Our rest pose stands upright, arms hanging at the sides, every joint frame parallel to the
world (Y up, facing +Z, left +X); MPFB's stands in an A pose, arms 45 degrees from the trunk,
forearms a little forward, legs a little apart. Each rig bone follows one node of ours
(`NODE_OF_BONE`), after a fixed rest correction:

* a limb bone (upper arm, forearm, thigh, shank) is first turned, about its head, by the
  smallest rotation that makes it hang along -Y as ours do (`limb_corrections`); the bones
  beyond it that we do not drive (hand, fingers, thumb; foot, toes) are turned with it;
* the trunk, clavicles, neck and head keep MPFB's rest (ours is upright too).

The posed world rotation of bone b is then ``R_b = W_node(b) @ C_b``, with ``W`` our node's
world rotation (the identity at rest) and ``C_b`` its correction, and the bone heads are
carried down the rig rigidly: ``h'_b = h'_parent + R_parent (h_b - h_parent)``. The rig's root
sits where our pelvis is (the midpoint of the hip joints), lowered or raised by the difference
between the two legs' lengths, so that a subject with legs of its own length stands on the
same floor. The vertices follow by linear blend skinning
(`tracking.body.mpfb.model.posed_vertices`).

Which of our nodes drives which bone: the pelvis the hips' bones and the lower back; the
spine node (the waist) the spine above it and the clavicles; the neck the neck and the head;
a shoulder the upper arm; an elbow the forearm, the hand and the fingers; a hip the thigh; a
knee the shank, the foot and the toes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from tracking.body.model import NODE_INDEX, BodyShape, Pose, forward_kinematics

NODE_OF_BONE: dict[str, str] = {
    "Hips": "pelvis", "LHipJoint": "pelvis", "RHipJoint": "pelvis", "LowerBack": "pelvis",
    "Spine": "spine", "Spine1": "spine", "LeftShoulder": "spine", "RightShoulder": "spine",
    "Neck": "neck", "Neck1": "neck", "Head": "neck",
    "LeftArm": "l_shoulder", "RightArm": "r_shoulder",
    "LeftForeArm": "l_elbow", "LeftHand": "l_elbow", "LeftFingerBase": "l_elbow",
    "LeftHandFinger1": "l_elbow", "LThumb": "l_elbow",
    "RightForeArm": "r_elbow", "RightHand": "r_elbow", "RightFingerBase": "r_elbow",
    "RightHandFinger1": "r_elbow", "RThumb": "r_elbow",
    "LeftUpLeg": "l_hip", "RightUpLeg": "r_hip",
    "LeftLeg": "l_knee", "LeftFoot": "l_knee", "LeftToeBase": "l_knee",
    "RightLeg": "r_knee", "RightFoot": "r_knee", "RightToeBase": "r_knee",
}  # fmt: skip
"""The node of `tracking.body.model.NODE_NAMES` whose world rotation each rig bone takes."""

LIMB_BONES: tuple[str, ...] = ("LeftArm", "LeftForeArm", "RightArm", "RightForeArm",
                               "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg")  # fmt: skip
"""The bones turned to hang along -Y at rest; every bone below one of them that is not itself
one takes the correction of the nearest above it."""


@dataclass(frozen=True)
class Rig:
    """A rig in our frame (metres, Y up, facing +Z): bone names, parents (index, -1 for the
    root; parents before children), rest heads and tails (B, 3), and the height of the floor
    the mesh stands on in our rest pose (its lowest vertex with the legs hanging straight,
    which reach a few millimetres lower than in MPFB's rest)."""

    names: tuple[str, ...]
    parents: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    floor_y: float

    def __post_init__(self) -> None:
        missing = sorted(set(NODE_OF_BONE) - set(self.names))
        unknown = sorted(set(self.names) - set(NODE_OF_BONE))
        if missing or unknown:
            raise ValueError(f"not the cmu_mb rig: missing {missing}, unknown {unknown}")
        if any(p >= i for i, p in enumerate(self.parents)):
            raise ValueError("rig bones must come after their parents")

    @cached_property
    def node_of_bone(self) -> np.ndarray:
        """(B,) the index in `NODE_NAMES` of the node each bone follows (`NODE_OF_BONE`)."""
        return np.array([NODE_INDEX[NODE_OF_BONE[name]] for name in self.names])

    def index(self, name: str) -> int:
        return self.names.index(name)

    @cached_property
    def root(self) -> int:
        """The index of the rig's root bone (the one without a parent)."""
        return int(np.flatnonzero(np.asarray(self.parents) < 0)[0])

    @cached_property
    def hip_centre(self) -> np.ndarray:
        """(3,) the midpoint of the hip joints (the thighs' heads): our pelvis node."""
        centre = (self.heads[self.index("LeftUpLeg")] + self.heads[self.index("RightUpLeg")]) / 2
        centre.flags.writeable = False
        return centre

    @property
    def hip_height_m(self) -> float:
        """Height of the hip joints above the floor the rest mesh stands on (``floor_y``)."""
        return float(self.hip_centre[1] - self.floor_y)


def smallest_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation by the smallest angle that turns direction ``a`` into ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # Opposite: half a turn about any axis normal to a.
        normal = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        normal /= np.linalg.norm(normal)
        return 2 * np.outer(normal, normal) - np.eye(3)
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def limb_corrections(rig: Rig) -> np.ndarray:
    """(B, 3, 3) each bone's rest correction ``C_b`` (module docstring)."""
    down = np.array([0.0, -1.0, 0.0])
    out = np.empty((len(rig.names), 3, 3))
    for b, name in enumerate(rig.names):
        parent = int(rig.parents[b])
        if name in LIMB_BONES:
            out[b] = smallest_rotation(rig.tails[b] - rig.heads[b], down)
        elif parent >= 0 and _below_limb(rig, parent):
            out[b] = out[parent]
        else:
            out[b] = np.eye(3)
    return out


def _below_limb(rig: Rig, b: int) -> bool:
    while b >= 0:
        if rig.names[b] in LIMB_BONES:
            return True
        b = int(rig.parents[b])
    return False


def rig_rotations(rig: Rig, pose: Pose, skeleton: BodyShape,
                  corrections: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rotations (B, 3, 3), root translation (3,)) of the rig for ``pose``, in the terms of
    `tracking.body.mpfb.model.posed_vertices`: each bone's ``parent_from_bone`` rotation (the
    root's relative to the world), from `rig_world_rotations`."""
    world, root = rig_world_rotations(rig, pose, skeleton, corrections)
    local = world.copy()
    has_parent = rig.parents >= 0
    local[has_parent] = np.einsum("bji,bjk->bik", world[rig.parents[has_parent]],
                                  world[has_parent])
    return local, root


def rig_world_rotations(rig: Rig, pose: Pose, skeleton: BodyShape,
                        corrections: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(world rotations (B, 3, 3), root translation (3,)) of the rig's bones for ``pose``:
    ``R_b = W_node(b) @ C_b`` (module docstring), and the root's displacement from its rest
    position that puts the rig's hip centre where our pelvis is. ``skeleton``: the shape the
    pose was retargeted to; its hip height and the rig's set the vertical offset."""
    corrections = limb_corrections(rig) if corrections is None else corrections
    world_from_node = forward_kinematics(pose, skeleton)
    node_rotation = world_from_node[:, :3, :3]
    world = node_rotation[rig.node_of_bone] @ corrections
    pelvis = world_from_node[NODE_INDEX["pelvis"], :3, 3].copy()
    pelvis[1] += rig.hip_height_m - skeleton.hip_height
    root = rig.root
    pelvis_rotation = node_rotation[NODE_INDEX["pelvis"]]
    root_head = pelvis + pelvis_rotation @ (rig.heads[root] - rig.hip_centre)
    return world, root_head - rig.heads[root]
