"""Retarget BVH motion capture (CMU skeleton) onto our 26-parameter body model
(`tracking.body.model`).

Two steps:

1. `shape_from_motion` measures the subject: bone lengths of the BVH skeleton (medians over the
   frames, so one bad frame cannot bias them) become the `BodyShape` lengths; the height is the
   sole-to-head-top chain of those lengths (so `BodyShape`'s own consistency check holds by
   construction); girths are `BodyShape.default(height)`'s, i.e. scaled with the height.
2. `fit_pose` finds, per frame, the in-limits pose whose node positions are closest (least
   squares, `scipy.optimize.least_squares` with the joint limits as bounds) to the positions of
   the corresponding BVH joints; `retarget` runs it over the frames, warm-starting every frame
   from the previous one. Residuals are RMS distances over the fitted nodes, in metres.

Three namings of the CMU skeleton are read (`NAMINGS`): the CMU BVH export's, the ASF bone
names' (`CMU_ASF_TO_BODY`) and the Daz-style one's (`DAZ_TO_BODY`), each with its length
unit (`bvh_metres_per_unit`).

Correspondence (`CMU_TO_BODY`; "A+B" means the midpoint of joints A and B):

* pelvis     LeftUpLeg+RightUpLeg  our pelvis joint is defined as the midpoint of the hip joints;
                                   the CMU root (Hips, = LowerBack) sits ~10 cm above that.
* spine      Spine                 the waist joint; LowerBack coincides with Hips (zero offset),
                                   so Spine (top of the lower back bone) is the first waist point.
* neck       Neck1                 our neck sits on the shoulder line (the shoulders hang off the
                                   chest at the neck's height). CMU Neck (= top of Spine1) lies
                                   ~7 cm below the shoulder joints, Neck1 ~3 cm above; Neck1 also
                                   gives the head nod its proper pivot.
* head_top   Head_end              when the End Site has zero length (as in the CMU clips
                                   converted to BVH, which lost the head bone), the head top is
                                   extrapolated from Head along Neck1->Head by that bone's length
                                   (`BvhNaming.head_extension`); see `cmu_node_positions`.
* l/r_shoulder  Left/RightArm      glenohumeral joint (Left/RightShoulder are clavicle roots).
* l/r_elbow     Left/RightForeArm
* l/r_wrist     Left/RightHand
* l/r_hip       Left/RightUpLeg    (L/RHipJoint coincide with Hips)
* l/r_knee      Left/RightLeg
* l/r_ankle     Left/RightFoot

Known model limits: the neck only nods, and the shoulders are rigid on the chest (no
clavicle), so shoulder shrug shows up as residuals of a few centimetres. The spine's side bend
and twist (session 17) lowered the mean RMS residual of 30 frames of each of five clips from
20.8 to 19.6 mm (walk), 17.3 to 14.5 (run), 29.1 to 25.3 (dance), 17.6 to 15.5 (boxing) and
21.1 to 17.7 (bend and pick up).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np
from scipy.optimize import least_squares

from tracking.body.bvh import CMU_METRES_PER_UNIT, Motion, rotations_to_channels
from tracking.body.bvh import forward_kinematics as bvh_forward_kinematics
from tracking.body.model import (
    LOWER_LIMITS,
    NODE_INDEX,
    NODE_NAMES,
    PARAM_INDEX,
    UPPER_LIMITS,
    BodyShape,
    Pose,
    forward_kinematics,
)

CMU_TO_BODY: dict[str, str] = {
    "pelvis": "LeftUpLeg+RightUpLeg",
    "spine": "Spine",
    "neck": "Neck1",
    "head_top": "Head_end",
    "l_shoulder": "LeftArm",
    "r_shoulder": "RightArm",
    "l_elbow": "LeftForeArm",
    "r_elbow": "RightForeArm",
    "l_wrist": "LeftHand",
    "r_wrist": "RightHand",
    "l_hip": "LeftUpLeg",
    "r_hip": "RightUpLeg",
    "l_knee": "LeftLeg",
    "r_knee": "RightLeg",
    "l_ankle": "LeftFoot",
    "r_ankle": "RightFoot",
}
# The same points in the other CMU export, with the ASF bone names (e.g. the bvh11 clips):
# LeftHip/LeftKnee/LeftAnkle start the femur/tibia/foot bones, the first "Chest" is the top of
# the lower back (our spine), "Neck" starts the upper neck (CMU_TO_BODY's Neck1).
CMU_ASF_TO_BODY: dict[str, str] = {
    "pelvis": "LeftHip+RightHip",
    "spine": "Chest",
    "neck": "Neck",
    "head_top": "Head_end",
    "l_shoulder": "LeftShoulder",
    "r_shoulder": "RightShoulder",
    "l_elbow": "LeftElbow",
    "r_elbow": "RightElbow",
    "l_wrist": "LeftWrist",
    "r_wrist": "RightWrist",
    "l_hip": "LeftHip",
    "r_hip": "RightHip",
    "l_knee": "LeftKnee",
    "r_knee": "RightKnee",
    "l_ankle": "LeftAnkle",
    "r_ankle": "RightAnkle",
}
DAZ_TO_BODY: dict[str, str] = {
    "pelvis": "lThigh+rThigh",
    "spine": "abdomen",
    "neck": "neck",
    "head_top": "head_end",
    "l_shoulder": "lShldr",
    "r_shoulder": "rShldr",
    "l_elbow": "lForeArm",
    "r_elbow": "rForeArm",
    "l_wrist": "lHand",
    "r_wrist": "rHand",
    "l_hip": "lThigh",
    "r_hip": "rThigh",
    "l_knee": "lShin",
    "r_knee": "rShin",
    "l_ankle": "lFoot",
    "r_ankle": "rFoot",
}
"""The same points in the Daz-style conversion of the CMU clips (hip, abdomen, chest, neck, head,
lCollar, lShldr, ..., lButtock, lThigh, lShin, lFoot; the shared data's kick, sit-stand and
climb): lShldr/lForeArm/lHand and lThigh/lShin/lFoot start the upper arm/forearm/hand and
thigh/shank/foot bones, abdomen is the waist joint and neck sits about 5 cm above the shoulder
line. The head has no End Site (only the eyes'): its top is extrapolated (`BvhNaming`)."""


@dataclass(frozen=True)
class BvhNaming:
    """How one BVH naming of the CMU skeleton gives our nodes.

    nodes: node name -> BVH joint ("A+B": the midpoint); below_head: the joint below the head;
    ankle, toe_tip: each side's ankle and toe-tip joints ("{side}" in `sides`), for the floor
    and the foot length; head_extension: when the head top's End Site is absent or has zero
    length, head top = head + head_extension * (head - below_head); metres_per_unit: the
    clips' length unit."""

    nodes: dict[str, str]
    below_head: str
    ankle: str
    toe_tip: str
    sides: tuple[str, str]
    head_extension: float
    metres_per_unit: float


NAMINGS: tuple[BvhNaming, ...] = (
    BvhNaming(CMU_TO_BODY, "Neck1", "{side}Foot", "{side}ToeBase_end", ("Left", "Right"),
              1.0, CMU_METRES_PER_UNIT),
    BvhNaming(CMU_ASF_TO_BODY, "Neck", "{side}Ankle", "{side}Toe_end", ("Left", "Right"),
              1.0, CMU_METRES_PER_UNIT),
    # Daz: head - neck is 7 cm, and the neck joint 5 cm above the shoulders; 1.8 puts the
    # head top 20 cm above the neck joint (CMU walk: 26 cm above Neck1; an adult's ear-to-
    # vertex is 13 cm). The clips are in centimetres: 0.01 gives the kick's subject a
    # sole-to-eye span of 1.46 m.
    BvhNaming(DAZ_TO_BODY, "neck", "{side}Foot", "{side}Foot_end", ("l", "r"), 1.8, 0.01),
)
"""The namings `retarget` reads, tried in this order."""


def cmu_naming(motion: Motion) -> BvhNaming:
    """The naming `motion` uses (see `NAMINGS`); ValueError when it is none of them."""
    names = set(motion.joint_names)
    for naming in NAMINGS:
        needed = {p for spec in naming.nodes.values() for p in spec.split("+")}
        needed.discard(naming.nodes["head_top"])  # extrapolated when absent
        if needed <= names:
            return naming
    missing = sorted({p for spec in CMU_TO_BODY.values() for p in spec.split("+")} - names)
    raise ValueError(f"not a CMU skeleton (no joint {', '.join(missing[:3])}, ...)")


def bvh_metres_per_unit(motion: Motion) -> float:
    """The length unit, in metres, of `motion`'s naming (CMU: 0.0254/0.45, Daz-style: 0.01)."""
    return cmu_naming(motion).metres_per_unit


_GIRTHS: tuple[str, ...] = (
    "pelvis_half_width", "trunk_half_depth", "chest_half_width", "head_half_width",
    "upper_arm_radius", "forearm_radius", "thigh_radius", "shank_radius",
)  # fmt: skip
_ROOT_ROT = [PARAM_INDEX[n] for n in ("root_rz", "root_rx", "root_ry")]
_ROOT_TRANS = [PARAM_INDEX[n] for n in ("root_tx", "root_ty", "root_tz")]


def cmu_node_positions(motion: Motion, metres_per_unit: float) -> dict[str, np.ndarray]:
    """Node name -> (F, 3) world positions in metres of the CMU points of `CMU_TO_BODY`."""
    pos = np.asarray(bvh_forward_kinematics(motion, scale=metres_per_unit))
    names = motion.joint_names
    naming = cmu_naming(motion)

    def joint(name: str) -> np.ndarray:
        if name == naming.nodes["head_top"] and (name not in names or np.linalg.norm(
                motion.joints[motion.joint_index(name)].offset) == 0.0):
            head = pos[:, names.index(name.removesuffix("_end"))]
            below = pos[:, names.index(naming.below_head)]
            return head + naming.head_extension * (head - below)
        return pos[:, names.index(name)]

    out = {}
    for node, spec in naming.nodes.items():
        parts = spec.split("+")
        out[node] = np.mean([joint(p) for p in parts], axis=0)
    return out


def _median_distance(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(a - b, axis=-1)))


def shape_from_motion(motion: Motion, metres_per_unit: float) -> BodyShape:
    """The subject's `BodyShape` measured from the BVH skeleton (lengths in metres).

    Bone lengths are medians over all frames (rigid bones make them the rest lengths; the
    median ignores glitches). Left and right are averaged (our model is symmetric). The ankle
    height is the lowest ankle height over the clip above the lowest toe tip (the floor); the
    foot length is the ankle to toe-tip distance over 0.8 (our foot mesh puts the toe tip 0.8
    foot lengths ahead of the ankle). The hand length (the CMU hand bones end at the finger
    bases) and all girths are the standard proportions of the resulting height.
    """
    p = cmu_node_positions(motion, metres_per_unit)
    pos = np.asarray(bvh_forward_kinematics(motion, scale=metres_per_unit))
    names = motion.joint_names

    def both(a: str, b: str) -> float:
        return 0.5 * (_median_distance(p["l_" + a], p["l_" + b])
                      + _median_distance(p["r_" + a], p["r_" + b]))  # fmt: skip

    naming = cmu_naming(motion)
    ankle, toe_tip, sides = naming.ankle, naming.toe_tip, naming.sides
    floor = min(pos[:, names.index(toe_tip.format(side=s)), 1].min() for s in sides)
    ankle_height = float(min(p["l_ankle"][:, 1].min(), p["r_ankle"][:, 1].min()) - floor)
    toe = 0.5 * sum(_median_distance(pos[:, names.index(ankle.format(side=s))],
                                     pos[:, names.index(toe_tip.format(side=s))])
                    for s in sides)  # fmt: skip
    lengths = {
        "pelvis_to_spine": _median_distance(p["pelvis"], p["spine"]),
        "spine_to_neck": _median_distance(p["spine"], p["neck"]),
        "neck_to_head_top": _median_distance(p["neck"], p["head_top"]),
        "shoulder_half_width": 0.5 * _median_distance(p["l_shoulder"], p["r_shoulder"]),
        "hip_half_width": 0.5 * _median_distance(p["l_hip"], p["r_hip"]),
        "upper_arm": both("shoulder", "elbow"),
        "forearm": both("elbow", "wrist"),
        "thigh": both("hip", "knee"),
        "shank": both("knee", "ankle"),
        "ankle_height": max(ankle_height, 0.01),
        "foot_length": toe / 0.8,
    }
    height = (lengths["thigh"] + lengths["shank"] + lengths["ankle_height"]
              + lengths["pelvis_to_spine"] + lengths["spine_to_neck"]
              + lengths["neck_to_head_top"])  # fmt: skip
    default = BodyShape.default(height)
    values = {f.name: getattr(default, f.name) for f in fields(BodyShape)}
    values.update(lengths)
    values["height"] = height
    return BodyShape(**values)


# ---------------------------------------------------------------------------------------------
# Pose fitting
# ---------------------------------------------------------------------------------------------


def _root_from_targets(targets: Mapping[str, np.ndarray], shape: BodyShape) -> np.ndarray | None:
    """Root (tx, ty, tz, rz, rx, ry) aligning the pelvis-frame nodes to targets (Kabsch)."""
    local = {
        "pelvis": (0.0, 0.0, 0.0),
        "l_hip": (shape.hip_half_width, 0.0, 0.0),
        "r_hip": (-shape.hip_half_width, 0.0, 0.0),
        "spine": (0.0, shape.pelvis_to_spine, 0.0),
    }
    have = [n for n in local if n in targets]
    if len(have) < 3:
        return None
    a = np.array([local[n] for n in have])
    b = np.array([targets[n] for n in have], dtype=float)
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T  # world_from_pelvis
    return np.concatenate([cb - r @ ca, np.deg2rad(rotations_to_channels(r, "ZXY"))])


def _residual_fn(names: Sequence[str], target: np.ndarray, shape: BodyShape):
    idx = np.array([NODE_INDEX[n] for n in names])

    def fun(x: np.ndarray) -> np.ndarray:
        world = forward_kinematics(Pose(x), shape)
        return (world[idx, :3, 3] - target).ravel()

    return fun


def _solve(fun, x0: np.ndarray) -> tuple[np.ndarray, float]:
    x0 = np.clip(x0, LOWER_LIMITS, UPPER_LIMITS)
    sol = least_squares(fun, x0, bounds=(LOWER_LIMITS, UPPER_LIMITS), method="trf",
                        x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)  # fmt: skip
    x = np.clip(sol.x, LOWER_LIMITS, UPPER_LIMITS)
    return x, float(np.sqrt(np.mean(np.sum(fun(x).reshape(-1, 3) ** 2, axis=1))))


def fit_pose(
    targets: Mapping[str, np.ndarray],
    shape: BodyShape,
    init: Pose | None = None,
    restarts: int = 6,
    seed: int = 0,
) -> tuple[Pose, float]:
    """Least-squares pose whose nodes best match `targets` (node name -> (3,) world, metres).

    Returns the pose (always within the joint limits) and the RMS node distance in metres.
    The root translation and rotation are always initialised from the pelvis, hips and spine
    targets (Kabsch), which avoids the +-180 degree wrap of the root angles; the limbs start
    from `init` (warm start) or, without one, from neutral plus `restarts` random in-limits
    starts, keeping the best (a cold start can fall into a local minimum, e.g. a limb bent the
    wrong way round).
    """
    names = [n for n in NODE_NAMES if n in targets]
    unknown = sorted(set(targets) - set(NODE_NAMES))
    if unknown:
        raise KeyError(f"unknown nodes {unknown}")
    if not names:
        raise ValueError("no targets")
    target = np.array([np.asarray(targets[n], dtype=float).reshape(3) for n in names])
    fun = _residual_fn(names, target, shape)
    x0 = init.params.copy() if init is not None else Pose.neutral().params.copy()
    root = _root_from_targets(targets, shape)
    if root is not None:
        x0[_ROOT_TRANS + _ROOT_ROT] = root
    elif "pelvis" in targets and init is None:
        x0[_ROOT_TRANS] = targets["pelvis"]
    best_x, best_rms = _solve(fun, x0)
    if init is None:
        rng = np.random.default_rng(seed)
        lo = np.where(np.isfinite(LOWER_LIMITS), LOWER_LIMITS, 0.0)
        hi = np.where(np.isfinite(UPPER_LIMITS), UPPER_LIMITS, 0.0)
        fixed = _ROOT_TRANS + _ROOT_ROT
        for _ in range(restarts):
            if best_rms < 1e-5:
                break
            x = rng.uniform(lo, hi)
            x[fixed] = x0[fixed]
            x, rms = _solve(fun, x)
            if rms < best_rms:
                best_x, best_rms = x, rms
    return Pose(best_x), best_rms


@dataclass(frozen=True)
class RetargetResult:
    """Per-frame poses of our model following a BVH clip.

    frames: (F,) indices into the clip; residual_rms_m: (F,) RMS node distance per frame.
    """

    shape: BodyShape
    frames: np.ndarray
    poses: list[Pose]
    residual_rms_m: np.ndarray

    @property
    def summary(self) -> dict[str, float]:
        r = self.residual_rms_m * 1000.0
        return {
            "frames": float(len(r)),
            "mean_residual_mm": float(r.mean()) if len(r) else float("nan"),
            "max_residual_mm": float(r.max()) if len(r) else float("nan"),
            "height_m": self.shape.height,
        }


def retarget(
    motion: Motion, metres_per_unit: float | None = None, frames: Sequence[int] | None = None
) -> RetargetResult:
    """Fit our model to every frame in `frames` (default all), warm-starting from the previous
    fitted frame (cold start for the first). metres_per_unit: the clip's length unit (default
    its naming's, `bvh_metres_per_unit`)."""
    if metres_per_unit is None:
        metres_per_unit = bvh_metres_per_unit(motion)
    shape = shape_from_motion(motion, metres_per_unit)
    pos = cmu_node_positions(motion, metres_per_unit)
    idx = np.arange(motion.num_frames) if frames is None else np.asarray(list(frames), int)
    poses: list[Pose] = []
    rms = np.empty(len(idx))
    prev: Pose | None = None
    for k, f in enumerate(idx):
        prev, rms[k] = fit_pose({n: p[f] for n, p in pos.items()}, shape, prev)
        poses.append(prev)
    return RetargetResult(shape, idx, poses, rms)
