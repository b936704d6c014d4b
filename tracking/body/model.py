"""Generic articulated body model of thesis section 6.2.2: a skeleton, a 26-parameter pose, a mesh.

The thesis model is "a hierarchic arrangement of 29 body segments" (closed triangle meshes,
5,600 triangles and 2,894 vertices) driven by "a skeleton of 11 joints"; 3-DOF ball joints and
1-DOF hinge joints; "each limb, i.e. complete arm or leg, is parameterised via four degrees of
freedom"; "24 parameters are needed to completely define a body pose". Section 6.2.5 names the
optimisation order: root translation and rotation, then "head and hip" rotations, then the limbs.
It does not spell out the split of the 24 parameters, so this module chooses (and `POSE_LAYOUT`
is the one place that says so):

* root (pelvis)          6  3 translations (metres, world frame) + 3 rotations (ZXY)
* spine (waist)          1  forward/backward flexion of the chest about the pelvis' X axis
* neck                   1  nod (flexion/extension) of the head about the chest's X axis
* shoulders, hips        3 each, ball joints (ZXY: abduction, flexion, axial twist)
* elbows, knees          1 each, hinge joints (flexion, 0..150 degrees)

  6 + 1 + 1 + 4 x (3 + 1) = 24, over the 11 joints pelvis, spine, neck, 2 shoulders, 2 elbows,
  2 hips, 2 knees. Hand and foot orientation (6.2.5's last step) is not in the 24, so wrists and
  ankles are fixed end sites here.
* spine (waist)          +2 side bend and twist of the chest (issue 19: the skinned body's chest
                         turns and bends over the pelvis in gait and in most other motions);
                         appended after the 24 so that a pose file of the thesis' 24 reads as
                         this layout's first 24, with the two at 0.

Conventions (those of `tracking.body.bvh`):

* Y up, metres, the body faces +Z at rest, so its left side is +X.
* A 3-DOF joint's rotation is ``parent_from_joint = Rz(a) @ Rx(b) @ Ry(c)``: intrinsic ZXY, the
  BVH ``Zrotation Xrotation Yrotation`` order. For a hanging limb (bone along -Y) that makes the
  last angle a true twist about the bone. Every angle is right-handed about its stated axis
  (`PoseParam.axis`), so a hinge whose flexion is a negative X rotation (the elbow) has axis -X.
* Rest pose (all parameters 0): standing upright, arms hanging at the sides, palms facing the
  body; every joint frame is then parallel to the world frame and the pelvis sits at the origin
  (the root translation is the world position of the pelvis joint, the midpoint of the hips).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache
from typing import ClassVar, Protocol

import numpy as np

from recon.mesh.normals import vertex_normals
from tracking.body.bvh import rotations_to_channels

_DEG = np.pi / 180.0

# ---------------------------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------------------------

# 11 articulated joints (the thesis' count) followed by 5 end sites without degrees of freedom,
# whose positions are needed for the head, hand and foot segments and for tests.
NODE_NAMES: tuple[str, ...] = (
    "pelvis", "spine", "neck",
    "l_shoulder", "l_elbow", "r_shoulder", "r_elbow",
    "l_hip", "l_knee", "r_hip", "r_knee",
    "head_top", "l_wrist", "r_wrist", "l_ankle", "r_ankle",
)  # fmt: skip
JOINT_NAMES: tuple[str, ...] = NODE_NAMES[:11]
END_SITE_NAMES: tuple[str, ...] = NODE_NAMES[11:]
# Parents precede children, so one pass in index order is a valid forward-kinematics order.
NODE_PARENTS: tuple[int, ...] = (-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9, 2, 4, 6, 8, 10)
NODE_INDEX: dict[str, int] = {name: i for i, name in enumerate(NODE_NAMES)}
# (parent, child) node pairs: the bones, for drawing the skeleton.
BONES: tuple[tuple[int, int], ...] = tuple(
    (parent, node) for node, parent in enumerate(NODE_PARENTS) if parent >= 0
)


# ---------------------------------------------------------------------------------------------
# Pose layout
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PoseParam:
    """One pose parameter: a translation along or a rotation about `axis` of `joint`'s frame.

    axis: unit (3,) vector in the joint's parent frame (the root's: world). lower/upper: the
    anatomical range in `unit` (infinite for the free root).
    """

    name: str
    joint: str
    kind: str  # "translation" | "rotation"
    axis: tuple[float, float, float]
    unit: str  # "m" | "rad"
    lower: float
    upper: float
    meaning: str


_X = (1.0, 0.0, 0.0)
_Y = (0.0, 1.0, 0.0)
_Z = (0.0, 0.0, 1.0)
_NEG_X = (-1.0, 0.0, 0.0)
_INF = float("inf")


def _rot(name: str, joint: str, axis: tuple[float, float, float], lo: float, hi: float,
         meaning: str) -> PoseParam:  # fmt: skip
    return PoseParam(name, joint, "rotation", axis, "rad", lo * _DEG, hi * _DEG, meaning)


def _limb(side: str, root: str, hinge: str, hinge_axis: tuple[float, float, float],
          abd: tuple[float, float], flex: tuple[float, float], twist: tuple[float, float],
          hinge_meaning: str) -> tuple[PoseParam, ...]:  # fmt: skip
    # The left limb hangs at +X, so +Z rotation abducts it and the right limb mirrors that:
    # abduction is the positive Z angle on the left and the negative one on the right.
    mirror = 1.0 if side == "l" else -1.0
    abd_lo, abd_hi = sorted((mirror * abd[0], mirror * abd[1]))
    tw_lo, tw_hi = sorted((mirror * twist[0], mirror * twist[1]))
    j, h = f"{side}_{root}", f"{side}_{hinge}"
    return (
        _rot(f"{j}_rz", j, _Z, abd_lo, abd_hi, "abduction(+left/-right) / adduction"),
        _rot(f"{j}_rx", j, _X, flex[0], flex[1], "-X lifts the limb forward (flexion)"),
        _rot(f"{j}_ry", j, _Y, tw_lo, tw_hi, "axial twist about the bone (+left = external)"),
        _rot(f"{h}_flex", h, hinge_axis, 0.0, 150.0, hinge_meaning),
    )


# Limits in degrees are typical active ranges of motion (AAOS / Kapandji tables), loosened a
# little because a tracker must not be blocked by a slightly mis-scaled model.
POSE_LAYOUT: tuple[PoseParam, ...] = (
    PoseParam("root_tx", "pelvis", "translation", _X, "m", -_INF, _INF, "world X of pelvis"),
    PoseParam("root_ty", "pelvis", "translation", _Y, "m", -_INF, _INF, "world Y (up)"),
    PoseParam("root_tz", "pelvis", "translation", _Z, "m", -_INF, _INF, "world Z"),
    _rot("root_rz", "pelvis", _Z, -180.0, 180.0, "roll of the whole body (applied first)"),
    _rot("root_rx", "pelvis", _X, -180.0, 180.0, "pitch of the whole body"),
    _rot("root_ry", "pelvis", _Y, -180.0, 180.0, "yaw (heading) of the whole body"),
    _rot("spine_flex", "spine", _X, -30.0, 90.0, "+ bends the chest forward"),
    _rot("neck_flex", "neck", _X, -60.0, 70.0, "+ nods the head forward"),
    *_limb("l", "shoulder", "elbow", _NEG_X, (-30.0, 180.0), (-180.0, 60.0), (-90.0, 90.0),
           "+ brings the forearm forward (elbow flexion)"),
    *_limb("r", "shoulder", "elbow", _NEG_X, (-30.0, 180.0), (-180.0, 60.0), (-90.0, 90.0),
           "+ brings the forearm forward (elbow flexion)"),
    *_limb("l", "hip", "knee", _X, (-30.0, 45.0), (-125.0, 30.0), (-45.0, 45.0),
           "+ swings the shank backward (knee flexion)"),
    *_limb("r", "hip", "knee", _X, (-30.0, 45.0), (-125.0, 30.0), (-45.0, 45.0),
           "+ swings the shank backward (knee flexion)"),
    # The chest's side bend and twist about the waist (session 17). They come last so that a
    # file of the 24 parameters above (the layout before them) is this layout's first 24, read
    # with both 0 (`tracking.body.motion.read_pose_file`); the spine's rotations apply in layout
    # order, flexion, side bend, twist: intrinsic XZY, the order of the report's spine angles.
    _rot("spine_bend", "spine", _Z, -35.0, 35.0, "+ bends the chest to the subject's left"),
    _rot("spine_twist", "spine", _Y, -45.0, 45.0, "+ turns the chest to the subject's left"),
)  # fmt: skip
LEGACY_POSE_PARAMS: int = 24
"""Length of the layout before the spine's side bend and twist were added: pose files of that
length are read with those two at 0."""
ADDED_PARAMS: tuple[str, ...] = tuple(p.name for p in POSE_LAYOUT[LEGACY_POSE_PARAMS:])
"""The parameters beyond the thesis' 24 (the spine's side bend and twist): what the tracker
holds while it searches its start and what ``--hold`` may hold in a fit."""
N_POSE_PARAMS: int = len(POSE_LAYOUT)
PARAM_INDEX: dict[str, int] = {p.name: i for i, p in enumerate(POSE_LAYOUT)}
LOWER_LIMITS: np.ndarray = np.array([p.lower for p in POSE_LAYOUT])
UPPER_LIMITS: np.ndarray = np.array([p.upper for p in POSE_LAYOUT])
LOWER_LIMITS.flags.writeable = False
UPPER_LIMITS.flags.writeable = False
WHOLE_TURN: np.ndarray = np.array([p.kind == "rotation" and p.upper - p.lower >= 2 * np.pi - 1e-9
                                   for p in POSE_LAYOUT])
"""The rotations whose range is a whole turn (-180..180 degrees): the root's roll, pitch and
heading. Their range is where a stored angle lies, not how far the body may turn: a subject
who spins turns through 180 degrees, and a search clipped there stops at the wall (the suite's
turn_pirouette stuck at -180 for frames 36-39 and 56, then diverged; session 45). Searches
move them freely (`SEARCH_LOWER_LIMITS`, `SEARCH_UPPER_LIMITS`), and `in_limits` brings their
results back into the range."""
SEARCH_LOWER_LIMITS: np.ndarray = np.where(WHOLE_TURN, -np.inf, LOWER_LIMITS)
SEARCH_UPPER_LIMITS: np.ndarray = np.where(WHOLE_TURN, np.inf, UPPER_LIMITS)
"""The bounds of a search over the pose parameters: the joint limits, the whole turns free."""
for _array in (WHOLE_TURN, SEARCH_LOWER_LIMITS, SEARCH_UPPER_LIMITS):
    _array.flags.writeable = False


def in_limits(params: np.ndarray) -> np.ndarray:
    """`params` (..., `N_POSE_PARAMS`) as a stored pose has them: each joint angle clipped to
    its limits, each `WHOLE_TURN` angle brought into -180..180 degrees (the same rotation)."""
    params = np.asarray(params, dtype=float)
    return np.where(WHOLE_TURN, turn_difference(params, 0.0),
                    np.clip(params, LOWER_LIMITS, UPPER_LIMITS))


def turn_difference(a: np.ndarray, b: np.ndarray | float) -> np.ndarray:
    """a - b for angles in radians, brought into [-pi, pi): the shorter way round."""
    return np.mod(np.asarray(a) - b + np.pi, 2.0 * np.pi) - np.pi

_ROT_PARAMS = np.array([i for i, p in enumerate(POSE_LAYOUT) if p.kind == "rotation"])
_ROT_AXES = np.array([POSE_LAYOUT[i].axis for i in _ROT_PARAMS])
_TRANS_PARAMS = np.array([i for i, p in enumerate(POSE_LAYOUT) if p.kind == "translation"])
_TRANS_AXES = np.array([POSE_LAYOUT[i].axis for i in _TRANS_PARAMS])
# Rows of the rotation list (in layout order = application order) that belong to each node.
_ROT_ROWS_OF_NODE: tuple[tuple[int, ...], ...] = tuple(
    tuple(k for k, i in enumerate(_ROT_PARAMS) if POSE_LAYOUT[i].joint == name)
    for name in NODE_NAMES
)


LIMIT_TOLERANCE_RAD: float = 1e-3 * _DEG
"""How far past a joint limit a stored pose may lie (0.001 degree) before it is refused. The
tracker, the body fit and the retargeting clip every pose to the limits exactly, and a pose
that went through text (BVH, 8 decimals of a degree) is off by far less than this; a pose
outside by more did not come from this model."""
ROOT_TRANSLATION_BOUND_M: float = 1000.0
"""Largest |root translation| (each axis, metres) a stored pose may have: ten times the largest
capture area there is (a sports field, ~100 m), so a pelvis beyond it is garbage, not a
subject (it also keeps forward kinematics far from float overflow)."""


def pose_params_problem(params: np.ndarray, *, joint_limits: bool = True) -> str | None:
    """Why the stored parameters (`N_POSE_PARAMS`,) are not a pose of this model, or None when
    they are: a value that is not finite, a root translation beyond `ROOT_TRANSLATION_BOUND_M`,
    or (with ``joint_limits``) a value more than `LIMIT_TOLERANCE_RAD` outside its
    `POSE_LAYOUT` range.
    The text names the first such parameter, its value and its range, in its units (degrees
    for rotations)."""
    params = np.asarray(params, dtype=float)
    if params.shape != (N_POSE_PARAMS,):
        return f"{params.size} pose parameters, not {N_POSE_PARAMS}"
    for i, (p, value) in enumerate(zip(POSE_LAYOUT, params, strict=True)):
        degrees = p.unit == "rad"
        shown = f"{np.rad2deg(value):.6g} deg" if degrees else f"{value:.6g} m"
        if not np.isfinite(value):
            return f"{p.name} is {value} (not a finite number)"
        if p.kind == "translation" and abs(value) > ROOT_TRANSLATION_BOUND_M:
            return (f"{p.name} = {shown} is beyond the +-{ROOT_TRANSLATION_BOUND_M:g} m of any "
                    "capture volume")
        if joint_limits and not (LOWER_LIMITS[i] - LIMIT_TOLERANCE_RAD <= value
                                 <= UPPER_LIMITS[i] + LIMIT_TOLERANCE_RAD):
            lo, hi = np.rad2deg([LOWER_LIMITS[i], UPPER_LIMITS[i]])
            return (f"{p.name} = {shown} is outside its joint limits {lo:g}..{hi:g} deg "
                    f"(tolerance {np.rad2deg(LIMIT_TOLERANCE_RAD):g} deg)")
    return None


@dataclass(frozen=True)
class LimitViolation:
    """A parameter outside its anatomical range; `excess` = distance to the range, > 0."""

    name: str
    value: float
    lower: float
    upper: float

    @property
    def excess(self) -> float:
        return max(self.lower - self.value, self.value - self.upper)


@dataclass(frozen=True)
class Pose:
    """A body pose: params (`N_POSE_PARAMS`,) in `POSE_LAYOUT` order, metres and radians.
    Immutable."""

    params: np.ndarray

    def __post_init__(self) -> None:
        params = np.array(self.params, dtype=float)
        if params.shape != (N_POSE_PARAMS,):
            raise ValueError(f"pose needs shape ({N_POSE_PARAMS},), got {params.shape}")
        if not np.all(np.isfinite(params)):
            raise ValueError("pose parameters must be finite")
        params.flags.writeable = False
        object.__setattr__(self, "params", params)

    @classmethod
    def neutral(cls) -> Pose:
        """The rest pose: upright, arms hanging, pelvis at the world origin."""
        return cls(np.zeros(N_POSE_PARAMS))

    @classmethod
    def from_dict(cls, values: Mapping[str, float]) -> Pose:
        """Named values (see `POSE_LAYOUT`); parameters not named are 0. Unknown names raise."""
        unknown = sorted(set(values) - set(PARAM_INDEX))
        if unknown:
            raise KeyError(f"unknown pose parameters {unknown}")
        params = np.zeros(N_POSE_PARAMS)
        for name, value in values.items():
            params[PARAM_INDEX[name]] = value
        return cls(params)

    def as_dict(self) -> dict[str, float]:
        return {p.name: float(v) for p, v in zip(POSE_LAYOUT, self.params, strict=True)}

    def clamped(self) -> Pose:
        """The nearest pose inside the joint limits (per parameter; `in_limits`)."""
        return Pose(in_limits(self.params))

    def violations(self) -> tuple[LimitViolation, ...]:
        """Parameters outside their limits, in layout order (empty when the pose is valid)."""
        bad = np.flatnonzero((self.params < LOWER_LIMITS) | (self.params > UPPER_LIMITS))
        return tuple(
            LimitViolation(POSE_LAYOUT[i].name, float(self.params[i]),
                           float(LOWER_LIMITS[i]), float(UPPER_LIMITS[i]))
            for i in bad
        )  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Body shape
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BodyShape:
    """Scale parameters of one subject, metres; found at initialisation, then fixed (6.2.4).

    Lengths are between joint centres; radii are half-girths of the (elliptic) segments.
    """

    height: float
    pelvis_to_spine: float  # hip joint level to waist (spine joint)
    spine_to_neck: float  # waist to the shoulder line (neck joint)
    neck_to_head_top: float
    shoulder_half_width: float  # neck joint to each shoulder joint, along X
    hip_half_width: float  # pelvis joint to each hip joint, along X
    upper_arm: float
    forearm: float
    hand: float
    thigh: float
    shank: float
    ankle_height: float  # ankle joint to sole
    foot_length: float
    # Girths.
    pelvis_half_width: float
    trunk_half_depth: float
    chest_half_width: float
    head_half_width: float
    upper_arm_radius: float
    forearm_radius: float
    thigh_radius: float
    shank_radius: float

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"BodyShape.{name} must be positive, got {value}")
        # `height` is not a free parameter: it must agree with the chain sole-to-head-top.
        if not np.isclose(self.chain_height, self.height, rtol=0.03):
            raise ValueError(
                f"segment lengths give a height of {self.chain_height:.3f} m, not {self.height}"
            )

    @property
    def hip_height(self) -> float:
        """Floor to hip joint centre at rest (the pelvis joint's height when standing)."""
        return self.thigh + self.shank + self.ankle_height

    @property
    def chain_height(self) -> float:
        """Sole to head top along the rest skeleton."""
        return self.hip_height + self.pelvis_to_spine + self.spine_to_neck + self.neck_to_head_top

    @classmethod
    def default(cls, height_m: float = 1.75) -> BodyShape:
        """Standard proportions of height H (Drillis & Contini 1966, as tabulated by Winter,
        "Biomechanics and Motor Control of Human Movement", fig. 4.1): hip 0.530H, knee 0.285H,
        ankle 0.039H, shoulder 0.818H, upper arm 0.186H, forearm 0.146H, hand 0.108H, shoulder
        width 0.259H, foot 0.152H x 0.055H, head (chin to top) 0.130H. The waist (0.630H), the
        hip-joint spacing (0.100H, ~half the bitrochanteric 0.191H) and the girths are not in
        that table; they are round values for an average adult and are meant to be refined at
        initialisation.
        """
        h = float(height_m)
        return cls(
            height=h,
            pelvis_to_spine=0.100 * h,
            spine_to_neck=0.188 * h,
            neck_to_head_top=0.182 * h,
            shoulder_half_width=0.1295 * h,
            hip_half_width=0.050 * h,
            upper_arm=0.186 * h,
            forearm=0.146 * h,
            hand=0.108 * h,
            thigh=0.245 * h,
            shank=0.246 * h,
            ankle_height=0.039 * h,
            foot_length=0.152 * h,
            pelvis_half_width=0.0955 * h,
            trunk_half_depth=0.060 * h,
            chest_half_width=0.100 * h,
            head_half_width=0.045 * h,
            upper_arm_radius=0.026 * h,
            forearm_radius=0.021 * h,
            thigh_radius=0.050 * h,
            shank_radius=0.034 * h,
        )


SHAPE_GROUPS: tuple[tuple[str, ...], ...] = (
    ("thigh",),
    ("shank",),
    ("ankle_height",),
    ("pelvis_to_spine",),
    ("spine_to_neck",),
    ("neck_to_head_top",),
    ("upper_arm",),
    ("forearm",),
    ("hand",),
    ("foot_length",),
    ("shoulder_half_width",),
    ("hip_half_width",),
    ("pelvis_half_width", "trunk_half_depth", "chest_half_width"),
    ("head_half_width",),
    ("upper_arm_radius",),
    ("forearm_radius",),
    ("thigh_radius",),
    ("shank_radius",),
)  # fmt: skip
"""Groups of BodyShape fields scaled together when the shape is estimated from silhouettes
(`scaled_shape`): the lengths one by one, the girths by body part."""


def scaled_shape(base: BodyShape, scales: np.ndarray) -> BodyShape:
    """`base` with each group of `SHAPE_GROUPS` multiplied by its scale; the height follows
    the scaled chain of lengths (sole to head top)."""
    values = {name: getattr(base, name) * float(k)
              for group, k in zip(SHAPE_GROUPS, scales, strict=True)
              for name in group}  # fmt: skip
    lengths = {**{f: getattr(base, f) for f in ("thigh", "shank", "ankle_height",
                                                "pelvis_to_spine", "spine_to_neck",
                                                "neck_to_head_top")}, **values}  # fmt: skip
    height = sum(lengths[f] for f in ("thigh", "shank", "ankle_height", "pelvis_to_spine",
                                      "spine_to_neck", "neck_to_head_top"))  # fmt: skip
    return replace(base, **values, height=height)


def rest_offsets(shape: BodyShape) -> np.ndarray:
    """(16, 3) position of each node in its parent's frame at rest (root: 0), metres."""
    s = shape
    offsets = {
        "pelvis": (0.0, 0.0, 0.0),
        "spine": (0.0, s.pelvis_to_spine, 0.0),
        "neck": (0.0, s.spine_to_neck, 0.0),
        "l_shoulder": (s.shoulder_half_width, s.spine_to_neck, 0.0),
        "r_shoulder": (-s.shoulder_half_width, s.spine_to_neck, 0.0),
        "l_elbow": (0.0, -s.upper_arm, 0.0),
        "r_elbow": (0.0, -s.upper_arm, 0.0),
        "l_hip": (s.hip_half_width, 0.0, 0.0),
        "r_hip": (-s.hip_half_width, 0.0, 0.0),
        "l_knee": (0.0, -s.thigh, 0.0),
        "r_knee": (0.0, -s.thigh, 0.0),
        "head_top": (0.0, s.neck_to_head_top, 0.0),
        "l_wrist": (0.0, -s.forearm, 0.0),
        "r_wrist": (0.0, -s.forearm, 0.0),
        "l_ankle": (0.0, -s.shank, 0.0),
        "r_ankle": (0.0, -s.shank, 0.0),
    }
    return np.array([offsets[name] for name in NODE_NAMES], dtype=float)


# ---------------------------------------------------------------------------------------------
# Forward kinematics
# ---------------------------------------------------------------------------------------------


def axis_angle_rotations(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(K, 3, 3) right-handed rotations by angles (K,) rad about unit axes (K, 3) (Rodrigues)."""
    k = np.zeros((len(axes), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    k -= k.transpose(0, 2, 1)
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def root_rotation(pose: Pose) -> np.ndarray:
    """(3, 3) world_from_pelvis rotation of `pose`."""
    rows = list(_ROT_ROWS_OF_NODE[NODE_INDEX["pelvis"]])
    rotation = np.eye(3)
    for r in axis_angle_rotations(_ROT_AXES[rows], pose.params[_ROT_PARAMS[rows]]):
        rotation = rotation @ r
    return rotation


def pose_in_frame(pose: Pose, frame_from_world: np.ndarray) -> Pose:
    """The same posture with its root expressed in another frame, rotated about the origin
    by ``frame_from_world`` (3, 3): only the root's translation and angles change."""
    q = np.asarray(frame_from_world, dtype=float)
    params = pose.params.copy()
    params[_TRANS_PARAMS] = _TRANS_AXES @ (q @ (pose.params[_TRANS_PARAMS] @ _TRANS_AXES))
    params[_ROT_PARAMS[list(_ROT_ROWS_OF_NODE[NODE_INDEX["pelvis"]])]] = np.deg2rad(
        rotations_to_channels(q @ root_rotation(pose), "ZXY"))
    return Pose(params)


def parent_from_node_transforms(pose: Pose, shape: BodyShape) -> np.ndarray:
    """(16, 4, 4) local transforms; the root's is world_from_pelvis."""
    return _node_transforms(pose, shape)[0]


def forward_kinematics(pose: Pose, shape: BodyShape) -> np.ndarray:
    """(16, 4, 4) world_from_node for every node of `NODE_NAMES` (joints then end sites)."""
    return _node_transforms(pose, shape)[1]


_ROT_NODE = np.array([NODE_INDEX[POSE_LAYOUT[i].joint] for i in _ROT_PARAMS])
_NODE_PARENT_ARRAY = np.array(NODE_PARENTS)


def _node_transforms(pose: Pose, shape: BodyShape) -> tuple[np.ndarray, np.ndarray]:
    """(parent_from_node, world_from_node), each (16, 4, 4): the rotations of each node in
    layout order (the intrinsic application order, Z X Y), its rest offset, the root's
    translation; compiled (`tracking.body.kinematics`)."""
    from tracking.body.kinematics import node_transforms

    local, world = np.empty((2, len(NODE_NAMES), 4, 4))
    node_transforms(np.ascontiguousarray(pose.params, dtype=np.float64), _ROT_PARAMS,
                    _ROT_AXES, _ROT_NODE, _TRANS_PARAMS, _TRANS_AXES, _rest_offsets(shape),
                    _NODE_PARENT_ARRAY, local, world)  # fmt: skip
    return local, world


@lru_cache(maxsize=64)
def _rest_offsets(shape: BodyShape) -> np.ndarray:
    """`rest_offsets`, made once per shape (shapes are frozen)."""
    offsets = rest_offsets(shape)
    offsets.flags.writeable = False
    return offsets


def _subtree_mask() -> np.ndarray:
    moved = np.zeros((N_POSE_PARAMS, len(NODE_NAMES)), dtype=bool)
    for k, param in enumerate(POSE_LAYOUT):
        joint = NODE_INDEX[param.joint]
        for node in range(len(NODE_NAMES)):
            ancestor = node
            while ancestor >= 0 and ancestor != joint:
                ancestor = NODE_PARENTS[ancestor]
            moved[k, node] = ancestor == joint
    moved.flags.writeable = False
    return moved


# PARAM_MOVES_NODE[k, n]: pose parameter k moves node n (n is its joint or a descendant).
PARAM_MOVES_NODE: np.ndarray = _subtree_mask()


def pose_derivative_axes(pose: Pose, shape: BodyShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the derivatives of world points with respect to the pose parameters need.

    Returns world_from_node (16, 4, 4), axis_in_world (P, 3) and pivot_in_world (P, 3): a
    point w rigidly attached to a node moved by parameter k (`PARAM_MOVES_NODE`) changes at
    dw/dp_k = axis_k x (w - pivot_k) for a rotation and dw/dp_k = axis_k for a translation
    (pivot 0); a direction n attached to it changes at axis_k x n (rotations only).
    """
    per_param = axis_angle_rotations(_ROT_AXES, pose.params[_ROT_PARAMS])
    world = forward_kinematics(pose, shape)
    axes = np.zeros((N_POSE_PARAMS, 3))
    pivots = np.zeros((N_POSE_PARAMS, 3))
    axes[_TRANS_PARAMS] = _TRANS_AXES
    for node, rows in enumerate(_ROT_ROWS_OF_NODE):
        parent = NODE_PARENTS[node]
        # Frame in which the node's first rotation acts: the parent's, at the node's origin.
        frame = world[parent, :3, :3] if parent >= 0 else np.eye(3)
        for row in rows:
            axes[_ROT_PARAMS[row]] = frame @ _ROT_AXES[row]
            pivots[_ROT_PARAMS[row]] = world[node, :3, 3]
            frame = frame @ per_param[row]
    return world, axes, pivots


def node_positions_in_world(pose: Pose, shape: BodyShape) -> dict[str, np.ndarray]:
    """Name -> (3,) world position of each joint and end site."""
    world = forward_kinematics(pose, shape)
    return {name: world[i, :3, 3].copy() for i, name in enumerate(NODE_NAMES)}


# ---------------------------------------------------------------------------------------------
# Mesh
# ---------------------------------------------------------------------------------------------

# Resolution of every segment: 8 latitude rings of 12 vertices plus 2 poles = 98 vertices and
# 192 triangles (a closed genus-0 mesh has F = 2V - 4), so 29 segments give 2,842 vertices and
# 5,568 triangles against the thesis' 2,894 and 5,600.
N_RINGS: int = 8
N_AROUND: int = 12


def superquadric(
    semi_axes: np.ndarray, eps_lat: float = 1.0, eps_lon: float = 1.0,
    n_rings: int = N_RINGS, n_around: int = N_AROUND,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Closed superellipsoid centred at 0 with poles on +-Y: vertices (V, 3), faces (F, 3).

    semi_axes: (3,) half-extents along X, Y, Z. eps < 1 squares the section off (torso), 1 is
    an ellipsoid. V = n_rings * n_around + 2; faces are counter-clockwise seen from outside.
    """

    def spow(c: np.ndarray, e: float) -> np.ndarray:
        return np.sign(c) * np.abs(c) ** e

    lat = -np.pi / 2 + np.pi * np.arange(1, n_rings + 1) / (n_rings + 1)
    lon = 2 * np.pi * np.arange(n_around) / n_around
    cl, sl = spow(np.cos(lat), eps_lat)[:, None], spow(np.sin(lat), eps_lat)[:, None]
    ring = np.stack(
        np.broadcast_arrays(cl * spow(np.cos(lon), eps_lon), sl, cl * spow(np.sin(lon), eps_lon)),
        axis=-1,
    ).reshape(-1, 3)
    unit = np.vstack([[0.0, -1.0, 0.0], ring, [0.0, 1.0, 0.0]])
    south, north = 0, n_rings * n_around + 1
    idx = 1 + np.arange(n_rings * n_around).reshape(n_rings, n_around)
    nxt = np.roll(idx, -1, axis=1)
    # With a = (lat i, lon j), b = (i, j+1), c = (i+1, j+1), d = (i+1, j), the triangles
    # (a, d, c) and (a, c, b) have normal d_lat x d_lon, which points outward.
    a, b, c, d = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    quads = np.concatenate(
        [np.stack([a, d, c], -1).reshape(-1, 3), np.stack([a, c, b], -1).reshape(-1, 3)]
    )
    caps_s = np.stack([np.full(n_around, south), idx[0], nxt[0]], -1)
    caps_n = np.stack([idx[-1], np.full(n_around, north), nxt[-1]], -1)
    faces = np.concatenate([caps_s, quads, caps_n])
    return unit * np.asarray(semi_axes, dtype=float), faces


@dataclass(frozen=True)
class SegmentSpec:
    """A rigid body segment: a superquadric attached to `node`.

    centre_in_node: (3,) position of its centre in the node's frame; semi_axes: (3,) in that
    frame (the node frame is world-aligned at rest, so Y is along a hanging limb).
    """

    name: str
    node: str
    centre_in_node: tuple[float, float, float]
    semi_axes: tuple[float, float, float]
    eps_lat: float = 1.0
    eps_lon: float = 1.0


def segment_specs(shape: BodyShape) -> tuple[SegmentSpec, ...]:
    """The 29 segments: 5 trunk/head, 5 per arm, 7 per leg (joint spheres close the gaps)."""
    s = shape
    fl = s.foot_length
    specs = [
        SegmentSpec("pelvis", "pelvis", (0, 0.02 * s.height, 0),
                    (s.pelvis_half_width, 0.055 * s.height, s.trunk_half_depth), 0.6, 0.7),
        SegmentSpec("abdomen", "pelvis", (0, 0.75 * s.pelvis_to_spine, 0),
                    (0.85 * s.chest_half_width, 0.05 * s.height, 0.9 * s.trunk_half_depth),
                    0.7, 0.8),
        SegmentSpec("chest", "spine", (0, 0.5 * s.spine_to_neck, 0),
                    (s.chest_half_width, 0.55 * s.spine_to_neck, s.trunk_half_depth), 0.6, 0.8),
        SegmentSpec("neck", "neck", (0, 0.03 * s.height, 0),
                    (0.3 * s.head_half_width * 2, 0.035 * s.height, 0.3 * s.head_half_width * 2)),
        # Head top pole lands exactly on the head_top end site, so the model height is exact.
        SegmentSpec("head", "neck", (0, s.neck_to_head_top - 0.065 * s.height, 0),
                    (s.head_half_width, 0.065 * s.height, 1.2 * s.head_half_width)),
    ]  # fmt: skip
    for side in ("l", "r"):
        ua, fa = s.upper_arm_radius, s.forearm_radius
        th, sh = s.thigh_radius, s.shank_radius
        specs += [
            SegmentSpec(f"{side}_shoulder_ball", f"{side}_shoulder", (0, 0, 0), (1.15 * ua,) * 3),
            SegmentSpec(f"{side}_upper_arm", f"{side}_shoulder", (0, -s.upper_arm / 2, 0),
                        (ua, s.upper_arm / 2, ua)),
            SegmentSpec(f"{side}_elbow_ball", f"{side}_elbow", (0, 0, 0), (1.05 * fa,) * 3),
            SegmentSpec(f"{side}_forearm", f"{side}_elbow", (0, -s.forearm / 2, 0),
                        (fa, s.forearm / 2, fa)),
            # Palm faces the body at rest: thin along X, wide along Z.
            SegmentSpec(f"{side}_hand", f"{side}_wrist", (0, -s.hand / 2, 0),
                        (0.4 * fa, s.hand / 2, 1.2 * fa), 0.8, 0.8),
            SegmentSpec(f"{side}_hip_ball", f"{side}_hip", (0, 0, 0), (0.9 * th,) * 3),
            SegmentSpec(f"{side}_thigh", f"{side}_hip", (0, -s.thigh / 2, 0),
                        (th, s.thigh / 2, th)),
            SegmentSpec(f"{side}_knee_ball", f"{side}_knee", (0, 0, 0), (1.05 * sh,) * 3),
            SegmentSpec(f"{side}_shank", f"{side}_knee", (0, -s.shank / 2, 0),
                        (sh, s.shank / 2, sh)),
            SegmentSpec(f"{side}_ankle_ball", f"{side}_ankle", (0, 0, 0),
                        (0.55 * s.ankle_height,) * 3),
            # The ankle sits about 0.2 foot lengths in front of the heel; soles touch y = 0.
            SegmentSpec(f"{side}_foot", f"{side}_ankle", (0, -s.ankle_height / 2, 0.175 * fl),
                        (0.18 * fl, s.ankle_height / 2, 0.375 * fl), 0.8, 0.8),
            SegmentSpec(f"{side}_toes", f"{side}_ankle",
                        (0, -s.ankle_height + 0.3 * s.ankle_height, 0.65 * fl),
                        (0.17 * fl, 0.3 * s.ankle_height, 0.15 * fl), 0.8, 0.8),
        ]  # fmt: skip
    return tuple(specs)


@dataclass(frozen=True)
class ShapeParameters:
    """A body model's shape parameters as the tracker refines them: names, current values,
    bounds (arrays of one length) and the finite-difference step of their derivatives."""

    names: tuple[str, ...]
    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    step: float


@dataclass(frozen=True)
class SkinnedMesh:
    """A body model's output mesh with its skeleton, in the bind pose every joint frame of
    which is parallel to the world (`tracking.body.gltf.write_skinned_glb`'s conventions):
    vertices (V, 3) and normals (V, 3), faces (F, 3), joint names, parents (-1 for the root;
    parents first), heads (B, 3) and skinning weights (V, B)."""

    vertices_m: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    joint_names: tuple[str, ...]
    joint_parents: tuple[int, ...]
    joint_heads_m: np.ndarray
    weights: np.ndarray

    def posed(self, rotations: np.ndarray, root_translation_m: np.ndarray) -> np.ndarray:
        """(V, 3) the vertices for (B, 3, 3) local joint rotations and the (3,) root
        displacement (``TrackedModel.skin_pose``), by the forward kinematics and linear blend
        skinning of `tracking.body.gltf` (what a glTF viewer shows)."""
        world = np.empty_like(rotations)
        heads = np.empty_like(self.joint_heads_m)
        for b, parent in enumerate(self.joint_parents):
            if parent < 0:
                world[b], heads[b] = rotations[b], self.joint_heads_m[b] + root_translation_m
            else:
                world[b] = world[parent] @ rotations[b]
                heads[b] = heads[parent] + world[parent] @ (
                    self.joint_heads_m[b] - self.joint_heads_m[parent])
        # sum_b w_vb (W_b (v - head_b) + p_b), the bones with a weight only
        used = np.flatnonzero(self.weights.any(axis=0))
        out = np.zeros_like(self.vertices_m)
        for b in used:
            w = self.weights[:, b]
            rows = np.flatnonzero(w)
            out[rows] += w[rows, None] * (
                (self.vertices_m[rows] - self.joint_heads_m[b]) @ world[b].T + heads[b])
        return out


@dataclass(frozen=True)
class BodyModel:
    """The meshed body of one subject. Vertices are rigidly skinned: each follows its segment's
    node. Arrays (read-only): vertex_in_node (V, 3); rest_vertices (V, 3) world positions in the
    neutral pose; faces (F, 3) int; segment_of_vertex (V,), segment_of_face (F,) indices into
    `segments`; node_of_segment (S,) indices into `NODE_NAMES`.
    """

    shape: BodyShape
    segments: tuple[SegmentSpec, ...] = field(init=False)
    node_of_segment: np.ndarray = field(init=False, repr=False)
    vertex_in_node: np.ndarray = field(init=False, repr=False)
    rest_vertices: np.ndarray = field(init=False, repr=False)
    faces: np.ndarray = field(init=False, repr=False)
    segment_of_vertex: np.ndarray = field(init=False, repr=False)
    segment_of_face: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        specs = segment_specs(self.shape)
        verts, faces, seg_v, seg_f = [], [], [], []
        offset = 0
        for k, spec in enumerate(specs):
            v, f = superquadric(np.array(spec.semi_axes), spec.eps_lat, spec.eps_lon)
            verts.append(v + np.array(spec.centre_in_node))
            faces.append(f + offset)
            seg_v.append(np.full(len(v), k))
            seg_f.append(np.full(len(f), k))
            offset += len(v)
        arrays = {
            "node_of_segment": np.array([NODE_INDEX[s.node] for s in specs]),
            "vertex_in_node": np.concatenate(verts),
            "faces": np.concatenate(faces),
            "segment_of_vertex": np.concatenate(seg_v),
            "segment_of_face": np.concatenate(seg_f),
        }
        object.__setattr__(self, "segments", specs)
        for name, value in arrays.items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        rest = self.posed_vertices(Pose.neutral())
        rest.flags.writeable = False
        object.__setattr__(self, "rest_vertices", rest)

    @cached_property
    def vertex_normals_in_node(self) -> np.ndarray:
        """(V, 3) unit outward normals of the vertices in their node's frame (read-only)."""
        v = self.vertex_in_node
        normals = vertex_normals(v, self.faces)
        # Outwards: away from the vertex's segment centre (superquadrics are star-shaped).
        centre = np.zeros_like(v)
        for seg in np.unique(self.segment_of_vertex):
            on = self.segment_of_vertex == seg
            centre[on] = v[on].mean(axis=0)
        normals[np.sum(normals * (v - centre), axis=1) < 0] *= -1
        normals.flags.writeable = False
        return normals

    @property
    def segment_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.segments)

    # -- what the tracker asks of a body model (`TrackedModel`) -------------------------------

    name: ClassVar[str] = "superquadric"
    """The ``mocap.body`` plugin whose model this is."""

    @cached_property
    def node_weights(self) -> np.ndarray:
        """(V, 16) each vertex's skinning weight per node of `NODE_NAMES`: rigid, so one 1
        per row (its segment's node)."""
        weights = np.zeros((len(self.vertex_in_node), len(NODE_NAMES)))
        weights[np.arange(len(weights)), self.node_of_segment[self.segment_of_vertex]] = 1.0
        weights.flags.writeable = False
        return weights

    def faces_moved_by(self, moved_nodes: np.ndarray) -> np.ndarray:
        """(F,) bool: the faces that move when the nodes ``moved_nodes`` ((16,) bool) do."""
        return np.asarray(moved_nodes)[self.node_of_segment[self.segment_of_face]]

    def posed_surface(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) world vertices and (V, 3) their unit outward normals in `pose`."""
        world = self._world_from_vertex_node(pose)
        return (self._posed(world),
                np.einsum("vij,vj->vi", world[:, :3, :3], self.vertex_normals_in_node))

    def joints(self, pose: Pose) -> np.ndarray:
        """(16, 3) world positions of the nodes of `NODE_NAMES` in `pose`."""
        return forward_kinematics(pose, self.shape)[:, :3, 3].copy()

    def shape_parameters(self) -> ShapeParameters:
        """The shape the silhouettes refine: one scale per group of `SHAPE_GROUPS`."""
        n = len(SHAPE_GROUPS)
        return ShapeParameters(names=tuple("+".join(g) for g in SHAPE_GROUPS),
                               values=np.ones(n), lower=np.full(n, 0.6),
                               upper=np.full(n, 1.5), step=1e-3)

    def reshaped(self, values: np.ndarray) -> BodyModel:
        """This model with the shape parameters `values` (`shape_parameters`)."""
        return BodyModel(scaled_shape(self.shape, values))

    def record(self) -> dict[str, object]:
        """What a pose file stores to rebuild this model: the shape is the skeleton itself."""
        return {"name": self.name}

    def skin(self) -> SkinnedMesh:
        """The mesh at rest (`Pose.neutral`), rigidly bound to the nodes of `NODE_NAMES`."""
        heads = forward_kinematics(Pose.neutral(), self.shape)[:, :3, 3]
        return SkinnedMesh(self.rest_vertices, self.vertex_normals_in_node, self.faces,
                           NODE_NAMES, NODE_PARENTS, heads, self.node_weights)

    def skin_pose(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(16, 3, 3) each node's parent_from_node rotation (the root's world_from_pelvis) and
        (3,) the root's displacement from rest: `skin`'s animation in ``pose``."""
        local = parent_from_node_transforms(pose, self.shape)
        return local[:, :3, :3], local[0, :3, 3].copy()

    def posed_vertices(self, pose: Pose, vertex_ids: np.ndarray | None = None) -> np.ndarray:
        """(V, 3) world vertex positions in `pose`; vertex_ids: (N,) only these, (N, 3)."""
        if vertex_ids is not None:
            return self.posed_vertices(pose)[vertex_ids]
        return self._posed(self._world_from_vertex_node(pose))

    def _world_from_vertex_node(self, pose: Pose) -> np.ndarray:
        """(V, 4, 4) the world_from_node transform of each vertex's node in `pose`."""
        return forward_kinematics(pose, self.shape)[self.node_of_segment[self.segment_of_vertex]]

    def _posed(self, world_from_vertex_node: np.ndarray) -> np.ndarray:
        return (np.einsum("vij,vj->vi", world_from_vertex_node[:, :3, :3], self.vertex_in_node)
                + world_from_vertex_node[:, :3, 3])


class TrackedModel(Protocol):
    """What the tracker asks of a body model (a ``mocap.body`` plugin's ``tracking_model``):
    `BodyModel` (the thesis' rigid superquadrics) and
    `tracking.body.mpfb.subject.MpfbModel` (MakeHuman's skinned body) are the two."""

    name: ClassVar[str]
    """The ``mocap.body`` plugin of the model."""
    shape: BodyShape
    """The subject's skeleton: our forward kinematics of it places the joints of the pose
    layout (limb clearances, outline derivatives, the BVH)."""
    faces: np.ndarray
    """(F, 3) int: the closed surface's outward triangles."""
    node_weights: np.ndarray
    """(V, 16) each vertex's weight per node of `NODE_NAMES`."""

    def posed_vertices(self, pose: Pose, vertex_ids: np.ndarray | None = None) -> np.ndarray:
        """(V, 3) world vertices; vertex_ids: (N,) only these, (N, 3), the same floats as
        those rows of all of them."""
        ...

    def posed_surface(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) world vertices and (V, 3) unit outward normals."""
        ...

    def faces_moved_by(self, moved_nodes: np.ndarray) -> np.ndarray:
        """(F,) bool: the triangles that move when the nodes ((16,) bool) do."""
        ...

    def joints(self, pose: Pose) -> np.ndarray:
        """(16, 3) the joint centres the tracker reports, `NODE_NAMES` order."""
        ...

    def shape_parameters(self) -> ShapeParameters:
        """`ShapeParameters`: what a shape pass refines."""
        ...

    def reshaped(self, values: np.ndarray) -> TrackedModel:
        """The model with the shape parameters ``values``."""
        ...

    def record(self) -> dict[str, object]:
        """The pose file's ``body`` entry (the plugin's ``model_from_record`` reads it)."""
        ...

    def skin(self) -> SkinnedMesh:
        """The output mesh (full resolution) bound to its skeleton, at rest."""
        ...

    def skin_pose(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(B, 3, 3) local joint rotations and (3,) root displacement of `skin` in ``pose``."""
        ...
