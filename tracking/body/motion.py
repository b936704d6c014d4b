"""Pose sequences of our body model as BVH motion, and back.

`motion_from_poses` writes the 16-node skeleton of `tracking.body.model` as a BVH hierarchy that
Blender, Maya and MotionBuilder import: the pelvis is the ROOT with
``Xposition Yposition Zposition Zrotation Xrotation Yrotation``, the other ten joints carry
``Zrotation Xrotation Yrotation`` (the model's own intrinsic ZXY order, so a ball joint's
channels are exactly its three pose parameters in degrees; the spine's flexion, side bend and
twist apply in XZY order, so its channels are the same rotation in ZXY), and the head top,
wrists and ankles are End Sites. A hinge (neck, elbow, knee) is written as a 3-channel joint
whose Z and Y channels stay 0; the X channel is the hinge angle with the sign of its axis (the
elbow's axis is -X). OFFSETs are in metres, Y up, the body faces +Z at rest: the conventions of
`tracking.body.bvh`.

`poses_from_motion` is the exact inverse for a file with this skeleton: it reads the bone
lengths back from the OFFSETs and the pose parameters from the channels. A BVH carries the
skeleton but no segment girths, so those are `BodyShape.default`'s for the skeleton's height.
Any other skeleton (the CMU one) goes through `tracking.body.retarget` instead (`poses_from_bvh`).

`read_pose_file` reads the other file format of pose sequences, ``pose.json``: `mocap track`'s
``tracks/pose.json``, `mocap synth`'s ``gt/pose.json`` and `mocap fit`'s ``fit.json`` (a single
pose, with the fit's own fields alongside) are all in it, and it is what `mocap track
--init-pose` and `mocap report` read.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from recon.errors import UserError
from tracking.body.bvh import (
    Joint,
    Motion,
    local_rotations,
    motion_from_rotations,
    rotations_to_channels,
)
from tracking.body.model import (
    LEGACY_POSE_PARAMS,
    LOWER_LIMITS,
    NODE_NAMES,
    NODE_PARENTS,
    PARAM_INDEX,
    POSE_LAYOUT,
    UPPER_LIMITS,
    BodyShape,
    Pose,
    parent_from_node_transforms,
    pose_params_problem,
    rest_offsets,
)

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
_JOINT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
_END_SITES = frozenset({"head_top", "l_wrist", "r_wrist", "l_ankle", "r_ankle"})


def _depth_first_order() -> list[int]:
    """Node indices in BVH (depth-first) order; `NODE_NAMES` has parents first, not depth-first."""
    children: list[list[int]] = [[] for _ in NODE_NAMES]
    for node, parent in enumerate(NODE_PARENTS):
        if parent >= 0:
            children[parent].append(node)
    order: list[int] = []

    def visit(node: int) -> None:
        order.append(node)
        for child in children[node]:
            visit(child)

    visit(0)
    return order


_BVH_ORDER: tuple[int, ...] = tuple(_depth_first_order())


def body_joints(shape: BodyShape) -> tuple[Joint, ...]:
    """The BVH skeleton of `shape`, in depth-first order (parents first)."""
    offsets = rest_offsets(shape)
    position = {node: k for k, node in enumerate(_BVH_ORDER)}
    joints = []
    for node in _BVH_ORDER:
        name, parent = NODE_NAMES[node], NODE_PARENTS[node]
        channels = () if name in _END_SITES else _ROOT_CHANNELS if parent < 0 else _JOINT_CHANNELS
        parent_in_file = position[parent] if parent >= 0 else -1
        joints.append(Joint(name, parent_in_file, offsets[node], channels))
    return tuple(joints)


def motion_from_poses(poses: list[Pose], shape: BodyShape, frame_time_s: float) -> Motion:
    """A BVH motion of `poses` (F poses) on the skeleton of `shape`; write it with `write_bvh`."""
    if not poses:
        raise ValueError("no poses to write")
    local = np.stack([parent_from_node_transforms(pose, shape) for pose in poses])  # (F, 16, 4, 4)
    order = list(_BVH_ORDER)
    return motion_from_rotations(
        body_joints(shape), local[:, order, :3, :3], local[:, 0, :3, 3], frame_time_s
    )


def is_body_skeleton(motion: Motion) -> bool:
    """Whether `motion` has this module's skeleton (joint names and channels)."""
    try:
        return all(
            (a.name == b.name or not b.channels)  # readers name End Sites after their parent
            and a.parent == b.parent and a.channels == b.channels
            for a, b in zip(motion.joints, body_joints(BodyShape.default()), strict=True)
        )
    except ValueError:  # different joint count
        return False


def shape_from_offsets(motion: Motion) -> BodyShape:
    """Bone lengths from the OFFSETs of a body-skeleton BVH; girths of `BodyShape.default`."""
    off = {NODE_NAMES[node]: j.offset for node, j in zip(_BVH_ORDER, motion.joints, strict=True)}
    lengths = {
        "pelvis_to_spine": off["spine"][1],
        "spine_to_neck": off["neck"][1],
        "neck_to_head_top": off["head_top"][1],
        "shoulder_half_width": off["l_shoulder"][0],
        "hip_half_width": off["l_hip"][0],
        "upper_arm": -off["l_elbow"][1],
        "forearm": -off["l_wrist"][1],
        "thigh": -off["l_knee"][1],
        "shank": -off["l_ankle"][1],
    }
    # The sole-to-ankle height is not a bone, so it keeps its default share of the height.
    above_ankle = sum(lengths[k] for k in ("thigh", "shank", "pelvis_to_spine", "spine_to_neck",
                                           "neck_to_head_top"))  # fmt: skip
    default = BodyShape.default(1.0)
    height = above_ankle / (1.0 - default.ankle_height)
    base = BodyShape.default(height)
    return replace(base, **{k: float(v) for k, v in lengths.items()})


def poses_from_motion(motion: Motion) -> tuple[list[Pose], BodyShape]:
    """The poses and shape stored in a body-skeleton BVH (the inverse of `motion_from_poses`)."""
    if not is_body_skeleton(motion):
        raise ValueError(
            "not a body-model skeleton (use tracking.body.retarget for other skeletons)")
    shape = shape_from_offsets(motion)
    rotations = local_rotations(motion)  # (F, J, 3, 3) in the file's joint order
    params = np.zeros((motion.num_frames, len(POSE_LAYOUT)))
    root = motion.channels[:, motion.channel_slice(0)]
    params[:, [PARAM_INDEX[n] for n in ("root_tx", "root_ty", "root_tz")]] = root[:, :3]
    for k, node in enumerate(_BVH_ORDER):
        name = NODE_NAMES[node]
        owned = [i for i, p in enumerate(POSE_LAYOUT) if p.joint == name and p.kind == "rotation"]
        if not owned:
            continue
        if len(owned) == 3:  # its parameters are the angles of its own order (ZXY, spine XZY)
            order = "".join("XYZ"[int(np.argmax(np.abs(POSE_LAYOUT[i].axis)))] for i in owned)
            params[:, owned] = _ball_angles_in_limits(
                np.deg2rad(rotations_to_channels(rotations[:, k], order)), owned)
        else:
            # Hinge about +-X: the angle of the rotation about X itself, signed by the axis.
            # (Not the X angle of a ZXY decomposition: that lies in [-90, 90] degrees, and a
            # knee bent 150 degrees would come back as 30 with Z and Y turned by 180.)
            angle = np.arctan2(rotations[:, k, 2, 1], rotations[:, k, 1, 1])
            params[:, owned[0]] = angle * POSE_LAYOUT[owned[0]].axis[0]
    return [Pose(row) for row in params], shape


def zxy_twin(zxy: np.ndarray) -> np.ndarray:
    """(..., 3) the other ZXY angle triple of the same rotations: (z + 180, 180 - x, y + 180)
    degrees, wrapped into [-180, 180). The same holds for any order of three distinct axes
    (the spine's XZY)."""
    twin = np.asarray(zxy, float) + np.array([np.pi, 0.0, np.pi])
    twin[..., 1] = np.pi - np.asarray(zxy)[..., 1]
    return np.mod(twin + np.pi, 2 * np.pi) - np.pi


def _ball_angles_in_limits(zxy: np.ndarray, owned: list[int]) -> np.ndarray:
    """Of the two angle triples (F, 3) of each rotation (ZXY, or the joint's own order),
    (z, x, y) and (z + 180, 180 - x, y + 180) degrees, the one nearer the joint's limits
    (`owned`: its three parameter indices): a shoulder lifted 120 degrees forward has x = -120
    within its range, but the decomposition returns the twin with x = -60 and its twist 180
    degrees out of range."""
    twin = zxy_twin(zxy)

    def excess(angles: np.ndarray) -> np.ndarray:
        lo, hi = LOWER_LIMITS[owned], UPPER_LIMITS[owned]
        return np.sum(np.maximum(lo - angles, 0.0) + np.maximum(angles - hi, 0.0), axis=1)

    better = excess(twin) < excess(zxy) - 1e-12
    return np.where(better[:, None], twin, zxy)


PoseFrames = list[tuple[int, "np.ndarray | None"]]
"""(frame, params (`N_POSE_PARAMS`,) or None when the frame is lost), sorted by frame."""


class PoseFile(NamedTuple):
    """A pose file's contents (`read_pose_file`)."""

    frame_rate: float | None
    """Frames per second; None for a single pose without timing (`mocap fit`'s fit.json)."""
    shape: BodyShape
    frames: PoseFrames
    world_from_upright: np.ndarray
    """(3, 3) rotation from the frame of the poses (Y up) to the world frame of the cameras."""
    body: dict[str, Any]
    """The body model of the poses: ``{"name": <mocap.body plugin>, ...}`` as its model's
    ``record()`` wrote it (``{"name": "superquadric"}`` for a file without one)."""


def read_pose_file(path: Path | str) -> PoseFile:
    """Frame rate, shape, (frame, params (`N_POSE_PARAMS`,) or None when lost) sorted by frame,
    and frame of a pose file::

        {"frame_rate": 25.0,
         "shape": {<every BodyShape field>: metres, ...},
         "frames": [{"frame": 0, "params": [26 floats in POSE_LAYOUT order]},
                    {"frame": 1, "params": null}, ...],
         "world_from_upright": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
         "body": {"name": "superquadric"}}

    The poses are in an upright frame (Y up, gravity along -Y); ``world_from_upright``, a
    rotation about the origin, takes them to the world frame of the cameras (default: the
    identity, a Y-up world). ``frame_rate`` may be missing or null for a single pose
    (`mocap fit`'s fit.json, posed in its cloud's frame). Other keys are ignored, except that
    a file saying ``"success": false`` (a body fit that failed) is refused. Params of
    `LEGACY_POSE_PARAMS` (the layout before the spine's side bend and twist) are read with
    those two at 0.

    What no writer of the format produces is refused too, so that nothing downstream computes
    with it: a frame number that is not an integer from 0 (to `MAX_FRAME_NUMBER`) or that
    appears twice (the entries may come in any order), a shape value beyond `MAX_SHAPE_M`, and
    params that `pose_params_problem` rejects (not finite, a root beyond
    `ROOT_TRANSLATION_BOUND_M`, a joint past its limits by more than `LIMIT_TOLERANCE_RAD`).
    Params of NaN only (as null) mark a lost frame. A one-line `UserError` names what is wrong:
    the file, the frame and the parameter.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise UserError(f"cannot read {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise UserError(f"{path} is not valid JSON ({exc})") from None
    if isinstance(data, dict) and data.get("success") is False:
        raise UserError(f"{path}: the body fit failed ({data.get('message', 'no message')}); "
                        "it holds no pose to use")
    if isinstance(data, dict) and data.get("model_to_cloud", 1.0) != 1.0:
        raise UserError(f"{path}: the body was fitted to a cloud of unknown scale (at "
                        f"{data['model_to_cloud']:.4g} cloud units per metre), so its pose is not "
                        "in the cloud's units; fit a metric cloud to start tracking from it")
    try:
        if not isinstance(data, dict):
            raise TypeError("not a JSON object")
        frame_rate = None if data.get("frame_rate") is None else float(data["frame_rate"])
        shape = BodyShape(**{k: float(v) for k, v in data["shape"].items()})
        entries = data["frames"]
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise TypeError("frames is not a list of objects")
        numbers = [e["frame"] for e in entries]
        rotation = np.array(data.get("world_from_upright", np.eye(3)), dtype=float)
        body = data.get("body", {"name": "superquadric"})
        if not isinstance(body, dict) or not isinstance(body.get("name"), str):
            raise TypeError("body is not an object with a name")
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{path}: not a pose track ({exc!s}); expected shape, frames and (for "
                        "a motion) frame_rate") from None
    if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3),
                                                   atol=1e-6) or np.linalg.det(rotation) < 0:
        raise UserError(f"{path}: world_from_upright is not a 3x3 rotation")
    if not entries:
        raise UserError(f"{path} holds no frames")
    if frame_rate is not None and not (np.isfinite(frame_rate) and frame_rate > 0):
        raise UserError(f"{path}: frame_rate {frame_rate:g} is not a positive number of frames "
                        "per second")
    big = next(((k, v) for k, v in dataclasses.asdict(shape).items() if v > MAX_SHAPE_M), None)
    if big is not None:
        raise UserError(f"{path}: shape {big[0]} = {big[1]:.6g} m is beyond {MAX_SHAPE_M:g} m "
                        "(not a person's body in metres)")
    frames: list[tuple[int, np.ndarray | None]] = []
    for number, entry in zip(numbers, entries, strict=True):
        if not _is_frame_number(number):
            raise UserError(f"{path}: frame {number!r} is not a frame number (an integer from "
                            f"0 to {MAX_FRAME_NUMBER})")
        frame, values = int(number), entry.get("params")
        try:
            row = None if values is None else np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise UserError(f"{path}: frame {frame}: params is not a list of numbers") from None
        if row is not None and row.size and np.isnan(row).all():
            row = None  # a lost frame written as NaN rather than null
        if row is not None and row.shape == (LEGACY_POSE_PARAMS,):
            row = np.concatenate([row, np.zeros(len(POSE_LAYOUT) - LEGACY_POSE_PARAMS)])
        if row is not None and row.shape != (len(POSE_LAYOUT),):
            raise UserError(f"{path}: frame {frame} has {row.size} pose parameters, "
                            f"not {len(POSE_LAYOUT)} (or the thesis' {LEGACY_POSE_PARAMS})")
        if row is not None and (problem := pose_params_problem(row)) is not None:
            raise UserError(f"{path}: frame {frame}: {problem}")
        frames.append((frame, row))
    frames.sort(key=lambda item: item[0])
    repeated = sorted({a for (a, _), (b, _) in itertools.pairwise(frames) if a == b})
    if repeated:
        raise UserError(f"{path}: frame {repeated[0]} appears more than once"
                        + (f" (and {len(repeated) - 1} more frames)" if len(repeated) > 1 else "")
                        + "; each frame needs one entry")
    return PoseFile(frame_rate, shape, frames, rotation, body)


MAX_FRAME_NUMBER: int = 2**31 - 1
"""Largest frame number of a pose file: video frame indices are 32-bit integers (two years of
a 30 Hz video), and anything larger is not a frame of a video."""
MAX_SHAPE_M: float = 10.0
"""Largest segment length or radius (metres) of a pose file's shape: five times the tallest
person's height; larger is not a body in metres."""


def _is_frame_number(value: object) -> bool:
    """An integer (or a float with an integer value) from 0 to `MAX_FRAME_NUMBER`; not a bool."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return bool(np.isfinite(value) and float(value).is_integer()
                and 0 <= value <= MAX_FRAME_NUMBER)
