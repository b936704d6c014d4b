"""Pose sequences of our body model as BVH motion, and back.

`motion_from_poses` writes the 16-node skeleton of `tracking.body.model` as a BVH hierarchy that
Blender, Maya and MotionBuilder import: the pelvis is the ROOT with
``Xposition Yposition Zposition Zrotation Xrotation Yrotation``, the other ten joints carry
``Zrotation Xrotation Yrotation`` (the model's own intrinsic ZXY order, so a 3-DOF joint's
channels are exactly its three pose parameters in degrees), and the head top, wrists and ankles
are End Sites. A hinge (spine, neck, elbow, knee) is written as a 3-channel joint whose Z and Y
channels stay 0; the X channel is the hinge angle with the sign of its axis (the elbow's axis is
-X). OFFSETs are in metres, Y up, the body faces +Z at rest: the conventions of `tracking.body.bvh`.

`poses_from_motion` is the exact inverse for a file with this skeleton: it reads the bone
lengths back from the OFFSETs and the 24 parameters from the channels. A BVH carries the
skeleton but no segment girths, so those are `BodyShape.default`'s for the skeleton's height.
Any other skeleton (the CMU one) goes through `tracking.body.retarget` instead (`poses_from_bvh`).

`read_pose_file` reads the other file format of pose sequences, ``pose.json``: `mocap track`'s
``tracks/pose.json``, `mocap synth`'s ``gt/pose.json`` and `mocap fit`'s ``fit.json`` (a single
pose, with the fit's own fields alongside) are all in it, and it is what `mocap track
--init-pose` and `mocap report` read.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

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
    NODE_NAMES,
    NODE_PARENTS,
    PARAM_INDEX,
    POSE_LAYOUT,
    BodyShape,
    Pose,
    parent_from_node_transforms,
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
        zxy = np.deg2rad(rotations_to_channels(rotations[:, k], "ZXY"))
        if len(owned) == 3:  # ball joint: its parameters are the ZXY angles themselves
            params[:, owned] = zxy
        else:  # hinge about +-X: the X angle, signed by the axis
            params[:, owned[0]] = zxy[:, 1] * POSE_LAYOUT[owned[0]].axis[0]
    return [Pose(row) for row in params], shape


PoseFrames = list[tuple[int, "np.ndarray | None"]]
"""(frame, params (24,) or None when the frame is lost), sorted by frame."""


class PoseFile(NamedTuple):
    """A pose file's contents (`read_pose_file`)."""

    frame_rate: float | None
    """Frames per second; None for a single pose without timing (`mocap fit`'s fit.json)."""
    shape: BodyShape
    frames: PoseFrames
    world_from_upright: np.ndarray
    """(3, 3) rotation from the frame of the poses (Y up) to the world frame of the cameras."""


def read_pose_file(path: Path | str) -> PoseFile:
    """Frame rate, shape, (frame, params (24,) or None when lost) sorted by frame, and frame
    of a pose file::

        {"frame_rate": 25.0,
         "shape": {<every BodyShape field>: metres, ...},
         "frames": [{"frame": 0, "params": [24 floats in POSE_LAYOUT order]},
                    {"frame": 1, "params": null}, ...],
         "world_from_upright": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}

    The poses are in an upright frame (Y up, gravity along -Y); ``world_from_upright``, a
    rotation about the origin, takes them to the world frame of the cameras (default: the
    identity, a Y-up world). ``frame_rate`` may be missing or null for a single pose
    (`mocap fit`'s fit.json, posed in its cloud's frame). Other keys are ignored, except that
    a file saying ``"success": false`` (a body fit that failed) is refused. A one-line
    `UserError` names what is wrong.
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
    try:
        if not isinstance(data, dict):
            raise TypeError("not a JSON object")
        frame_rate = None if data.get("frame_rate") is None else float(data["frame_rate"])
        shape = BodyShape(**{k: float(v) for k, v in data["shape"].items()})
        entries = sorted(data["frames"], key=lambda e: int(e["frame"]))
        rotation = np.array(data.get("world_from_upright", np.eye(3)), dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{path}: not a pose track ({exc!s}); expected shape, frames and (for "
                        "a motion) frame_rate") from None
    if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3),
                                                   atol=1e-6) or np.linalg.det(rotation) < 0:
        raise UserError(f"{path}: world_from_upright is not a 3x3 rotation")
    if not entries:
        raise UserError(f"{path} holds no frames")
    frames: list[tuple[int, np.ndarray | None]] = []
    for entry in entries:
        values = entry.get("params")
        row = None if values is None else np.asarray(values, dtype=float)
        if row is not None and row.shape != (len(POSE_LAYOUT),):
            raise UserError(f"{path}: frame {entry['frame']} has {row.size} pose parameters, "
                            f"not {len(POSE_LAYOUT)}")
        frames.append((int(entry["frame"]), row))
    return PoseFile(frame_rate, shape, frames, rotation)
