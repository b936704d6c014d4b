"""BVH (Biovision hierarchy) motion files: read, write, forward kinematics, Euler conversion.

Conventions (those of the BVH format as Blender, MotionBuilder and the CMU clips use it):

* A joint's rotation channels are applied in the listed order as *intrinsic* rotations, so
  ``CHANNELS 3 Zrotation Yrotation Xrotation`` means ``parent_from_joint = Rz @ Ry @ Rx``.
  Angles are in degrees in the file and in `Motion.channels`.
* A joint sits at ``parent position + world_from_parent @ offset``; position channels (the root's,
  and any other joint's) are added to the joint's OFFSET.
* ``End Site`` blocks are kept as joints without channels named ``"<parent>_end"`` so that the
  lengths of the terminal bones (head top, finger and toe tips) are known.
* Lengths stay in file units; `CMU_METRES_PER_UNIT` converts the CMU clips to metres (Y is up).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# The CMU skeletons are stored in units of about 1/0.45 inch.
CMU_METRES_PER_UNIT: float = 0.0254 / 0.45
metres_per_unit = CMU_METRES_PER_UNIT

ROTATION_CHANNELS: tuple[str, ...] = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS: tuple[str, ...] = ("Xposition", "Yposition", "Zposition")
_AXIS_OF_CHANNEL: dict[str, int] = {
    "Xposition": 0, "Yposition": 1, "Zposition": 2,
    "Xrotation": 0, "Yrotation": 1, "Zrotation": 2,
}  # fmt: skip
_AXIS_LETTERS = "XYZ"


@dataclass(frozen=True, eq=False)
class Joint:
    """One node of the skeleton; an End Site is a joint with no channels and no children.

    offset: (3,) position of the joint in its parent's frame at rest, file units.
    """

    name: str
    parent: int  # index into Motion.joints, -1 for the root
    offset: np.ndarray
    channels: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        offset = np.array(self.offset, dtype=float).reshape(3)
        offset.flags.writeable = False
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "channels", tuple(self.channels))
        for name in self.channels:
            if name not in _AXIS_OF_CHANNEL:
                raise ValueError(f"joint {self.name!r}: unknown channel {name!r}")


@dataclass(frozen=True, eq=False)
class Motion:
    """A skeleton and its per-frame channel values exactly as stored in a BVH file.

    joints: in file (depth-first) order, each parent before its children.
    channels: (F, C) values in the file's channel order; degrees and file units.
    """

    joints: tuple[Joint, ...]
    frame_time_s: float
    channels: np.ndarray
    _first_channel: tuple[int, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        joints = tuple(self.joints)
        object.__setattr__(self, "joints", joints)
        if not joints:
            raise ValueError("a motion needs at least one joint")
        for index, joint in enumerate(joints):
            if (index == 0) != (joint.parent == -1) or joint.parent >= index:
                raise ValueError(
                    f"joint {index} {joint.name!r}: parent {joint.parent} is not an earlier joint"
                )
        if not self.frame_time_s > 0:
            raise ValueError(f"frame time must be positive, got {self.frame_time_s}")
        counts = [len(j.channels) for j in joints]
        first = np.concatenate([[0], np.cumsum(counts)]).astype(int)
        object.__setattr__(self, "_first_channel", tuple(int(v) for v in first))
        channels = np.array(self.channels, dtype=float)
        if channels.ndim != 2 or channels.shape[1] != first[-1]:
            raise ValueError(
                f"channels have shape {channels.shape}, the skeleton needs (F, {first[-1]})"
            )
        channels.flags.writeable = False
        object.__setattr__(self, "channels", channels)

    @property
    def num_frames(self) -> int:
        return int(self.channels.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.joints)

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time_s

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def offsets(self) -> np.ndarray:
        """(J, 3) rest offsets of every joint in its parent's frame, file units."""
        return np.stack([j.offset for j in self.joints])

    @property
    def parents(self) -> np.ndarray:
        """(J,) parent index of every joint, -1 for the root."""
        return np.array([j.parent for j in self.joints], dtype=int)

    def joint_index(self, name: str) -> int:
        for index, joint in enumerate(self.joints):
            if joint.name == name:
                return index
        raise KeyError(f"no joint named {name!r}")

    def channel_slice(self, joint: int | str) -> slice:
        """Columns of `channels` that belong to `joint` (an index or a name)."""
        index = self.joint_index(joint) if isinstance(joint, str) else joint
        return slice(self._first_channel[index], self._first_channel[index + 1])


# ----------------------------------------------------------------------------- parsing


def read_bvh(path: str | os.PathLike[str]) -> Motion:
    """Read a BVH file; malformed files raise ValueError naming the file and line."""
    path = Path(path)
    return parse_bvh(path.read_text(encoding="utf-8", errors="replace"), source=str(path))


def _tokens_with_lines(lines: Sequence[str]) -> list[tuple[str, int]]:
    return [(tok, n + 1) for n, line in enumerate(lines) for tok in line.split()]


def _float(token: str, source: str, line: int) -> float:
    try:
        value = float(token)
    except ValueError:
        raise ValueError(f"{source}:{line}: bad number {token!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{source}:{line}: non-finite number {token!r}")
    return value


def parse_bvh(text: str, source: str = "<string>") -> Motion:
    """Parse the text of a BVH file; `source` names it in error messages."""
    lines = text.splitlines()
    motion_line = next((n for n, line in enumerate(lines) if line.strip() == "MOTION"), None)
    if motion_line is None:
        raise ValueError(f"{source}:{len(lines)}: no MOTION section")
    joints = _parse_hierarchy(_tokens_with_lines(lines[:motion_line]), source, motion_line + 1)
    num_channels = sum(len(j.channels) for j in joints)
    frame_time_s, channels = _parse_motion(lines, motion_line, num_channels, source)
    names = [(j.name, c) for j in joints for c in j.channels]
    rotation = np.array([c in ROTATION_CHANNELS for _, c in names], dtype=bool)
    wild = np.abs(channels[:, rotation]) > MAX_ROTATION_DEG
    if wild.any():
        frame, column = np.argwhere(wild)[0]
        joint, channel = np.array(names, dtype=object)[rotation][column]
        raise ValueError(f"{source}: frame {frame}: {channel} of {joint} is "
                         f"{channels[frame, rotation][column]:g} degrees, beyond the "
                         f"+-{MAX_ROTATION_DEG:g} of any joint angle")
    return Motion(joints=tuple(joints), frame_time_s=frame_time_s, channels=channels)


MAX_ROTATION_DEG: float = 1e6
"""Largest |rotation channel| of a BVH frame, degrees: almost 2,800 turns, more than any
unwrapped angle of a real clip, where float64 still resolves 1e-10 degrees; beyond it a value
is garbage whose rotation (its remainder modulo 360) means nothing."""


def _parse_hierarchy(tokens: list[tuple[str, int]], source: str, end_line: int) -> list[Joint]:
    pos = 0

    def take(expected: str | None = None) -> tuple[str, int]:
        nonlocal pos
        if pos >= len(tokens):
            want = f"{expected!r}" if expected else "more"
            raise ValueError(f"{source}:{end_line}: hierarchy ends early, expected {want}")
        tok, line = tokens[pos]
        pos += 1
        if expected is not None and tok != expected:
            raise ValueError(f"{source}:{line}: expected {expected!r}, found {tok!r}")
        return tok, line

    take("HIERARCHY")
    _, line = take("ROOT")
    joints: list[Joint] = []
    # A joint is appended once its OFFSET and CHANNELS are read, before any child, so parents
    # always precede their children (depth-first file order).
    names: set[str] = set()

    def unique(name: str) -> str:
        candidate, k = name, 1
        while candidate in names:
            k += 1
            candidate = f"{name}{k}"
        names.add(candidate)
        return candidate

    def parse_joint(name: str, parent: int, end_site: bool) -> None:
        take("{")
        _, line = take("OFFSET")
        offset = [_float(take()[0], source, line) for _ in range(3)]
        channels: tuple[str, ...] = ()
        if not end_site:
            _, line = take("CHANNELS")
            count_tok, line = take()
            if not count_tok.isdigit():
                raise ValueError(f"{source}:{line}: bad channel count {count_tok!r}")
            names_and_lines = [take() for _ in range(int(count_tok))]
            for tok, tok_line in names_and_lines:
                if tok not in _AXIS_OF_CHANNEL:
                    raise ValueError(f"{source}:{tok_line}: unknown channel {tok!r}")
            channels = tuple(tok for tok, _ in names_and_lines)
            if len(set(channels)) != len(channels):
                raise ValueError(f"{source}:{line}: repeated channel in {channels}")
        index = len(joints)
        joints.append(Joint(name=name, parent=parent, offset=np.array(offset), channels=channels))
        while True:
            tok, line = take()
            if tok == "}":
                return
            if end_site:
                raise ValueError(f"{source}:{line}: End Site has a child {tok!r}")
            if tok == "JOINT":
                parse_joint(unique(take()[0]), index, end_site=False)
            elif tok == "End":
                take("Site")
                parse_joint(unique(f"{name}_end"), index, end_site=True)
            else:
                raise ValueError(
                    f"{source}:{line}: expected JOINT, End Site or '}}', found {tok!r}"
                )

    parse_joint(unique(take()[0]), -1, end_site=False)
    if pos != len(tokens):
        tok, line = tokens[pos]
        raise ValueError(f"{source}:{line}: unexpected {tok!r} after the root joint")
    return joints


def _parse_motion(
    lines: list[str], motion_line: int, num_channels: int, source: str
) -> tuple[float, np.ndarray]:
    # Header lines: "Frames: N" and "Frame Time: T" (0-based index n is file line n + 1).
    rest = [(n, lines[n]) for n in range(motion_line + 1, len(lines)) if lines[n].strip()]
    if len(rest) < 2:
        raise ValueError(f"{source}:{len(lines)}: MOTION section lacks Frames/Frame Time")
    (n_frames_line, frames_text), (n_time_line, time_text) = rest[0], rest[1]
    parts = frames_text.split()
    if len(parts) != 2 or parts[0] != "Frames:" or not parts[1].isdigit():
        raise ValueError(f"{source}:{n_frames_line + 1}: expected 'Frames: <count>'")
    num_frames = int(parts[1])
    parts = time_text.split()
    if len(parts) != 3 or parts[:2] != ["Frame", "Time:"]:
        raise ValueError(f"{source}:{n_time_line + 1}: expected 'Frame Time: <seconds>'")
    frame_time_s = _float(parts[2], source, n_time_line + 1)
    if frame_time_s <= 0:
        raise ValueError(f"{source}:{n_time_line + 1}: frame time must be positive")

    data = rest[2:]
    if len(data) < num_frames:
        raise ValueError(
            f"{source}:{len(lines)}: truncated MOTION, {len(data)} of {num_frames} frames"
        )
    if len(data) > num_frames:
        raise ValueError(
            f"{source}:{data[num_frames][0] + 1}: more frame lines than 'Frames: {num_frames}'"
        )
    channels = np.empty((num_frames, num_channels))
    for row, (n, line) in enumerate(data):
        values = line.split()
        if len(values) != num_channels:
            raise ValueError(
                f"{source}:{n + 1}: frame has {len(values)} values, skeleton has "
                f"{num_channels} channels"
            )
        try:
            channels[row] = np.array(values, dtype=float)
        except ValueError:
            for tok in values:
                _float(tok, source, n + 1)  # raises, naming the bad token
            raise
        if not np.all(np.isfinite(channels[row])):
            raise ValueError(f"{source}:{n + 1}: non-finite number in frame")
    return frame_time_s, channels


# ----------------------------------------------------------------------------- writing


def _number(value: float) -> str:
    # Fixed point with 8 decimals: exact to 5e-9 (lossless for 1e-6 round trips) and no
    # exponent notation, which some importers do not accept.
    text = f"{value:.8f}".rstrip("0")
    text = text + "0" if text.endswith(".") else text
    return "0.0" if text == "-0.0" else text


def format_bvh(motion: Motion) -> str:
    """The text of `motion` as a standard BVH file (tabs, one frame a line)."""
    out: list[str] = ["HIERARCHY"]
    children: list[list[int]] = [[] for _ in motion.joints]
    for index, joint in enumerate(motion.joints):
        if joint.parent >= 0:
            children[joint.parent].append(index)

    def emit(index: int, depth: int) -> None:
        joint, pad = motion.joints[index], "\t" * depth
        offset = " ".join(_number(v) for v in joint.offset)
        if not joint.channels and not children[index] and joint.parent >= 0:
            out.extend([f"{pad}End Site", f"{pad}{{", f"{pad}\tOFFSET {offset}", f"{pad}}}"])
            return
        keyword = "ROOT" if joint.parent < 0 else "JOINT"
        out.extend([f"{pad}{keyword} {joint.name}", f"{pad}{{", f"{pad}\tOFFSET {offset}"])
        out.append(f"{pad}\tCHANNELS {len(joint.channels)} {' '.join(joint.channels)}".rstrip())
        for child in children[index]:
            emit(child, depth + 1)
        out.append(f"{pad}}}")

    emit(0, 0)
    out.extend(
        ["MOTION", f"Frames: {motion.num_frames}", f"Frame Time: {repr(motion.frame_time_s)}"]
    )
    out.extend(" ".join(_number(v) for v in row) for row in motion.channels.tolist())
    return "\n".join(out) + "\n"


def write_bvh(motion: Motion, path: str | os.PathLike[str]) -> None:
    """Write `motion` to `path` atomically, with the mode of any new output
    (`recon.workspace.atomic_output`: a temporary sibling, then rename)."""
    from recon.workspace import atomic_output

    path = Path(path)
    text = format_bvh(motion)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8", newline="\n")


# ----------------------------------------------------------------------------- rotations


def axis_rotations(axis: int, angles_deg: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations by `angles_deg` (...) about axis 0=X, 1=Y, 2=Z (right-handed)."""
    angles = np.deg2rad(np.asarray(angles_deg, dtype=float))
    c, s = np.cos(angles), np.sin(angles)
    rot = np.zeros((*angles.shape, 3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    rot[..., axis, axis] = 1.0
    rot[..., i, i] = c
    rot[..., j, j] = c
    rot[..., i, j] = -s
    rot[..., j, i] = s
    return rot


def _order_axes(order: str | Sequence[str]) -> tuple[int, int, int]:
    """Axis indices of an order given as "ZYX" or as ("Zrotation", "Yrotation", "Xrotation")."""
    letters = order if isinstance(order, str) else "".join(c[0] for c in order)
    letters = letters.upper()
    if len(letters) != 3 or sorted(letters) != ["X", "Y", "Z"]:
        raise ValueError(f"rotation order must be a permutation of XYZ, got {order!r}")
    a, b, c = (_AXIS_LETTERS.index(ch) for ch in letters)
    return a, b, c


def euler_to_rotations(angles_deg: np.ndarray, order: str | Sequence[str]) -> np.ndarray:
    """(..., 3, 3) = R_first @ R_second @ R_third for angles (..., 3) in degrees, listed order."""
    angles_deg = np.asarray(angles_deg, dtype=float)
    first, second, third = _order_axes(order)
    return (
        axis_rotations(first, angles_deg[..., 0])
        @ axis_rotations(second, angles_deg[..., 1])
        @ axis_rotations(third, angles_deg[..., 2])
    )


def rotations_to_channels(rotations: np.ndarray, order: str | Sequence[str]) -> np.ndarray:
    """Euler angles (..., 3) in degrees, in the listed order, with R = R_a @ R_b @ R_c.

    rotations: (..., 3, 3) proper rotation matrices. The middle angle is in [-90, 90]; at gimbal
    lock (middle angle ±90) the third angle is set to 0 and the first absorbs the rest.
    """
    rot = np.asarray(rotations, dtype=float)
    i, j, k = _order_axes(order)
    # sign = +1 for the cyclic orders XYZ, YZX, ZXY; -1 for the others.
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    middle = np.arcsin(np.clip(sign * rot[..., i, k], -1.0, 1.0))
    first = np.arctan2(-sign * rot[..., j, k], rot[..., k, k])
    third = np.arctan2(-sign * rot[..., i, j], rot[..., i, i])
    # At gimbal lock the first and third axes coincide; the formulas above divide 0 by 0.
    # With third = 0, R = R_i(first) @ R_j(middle) keeps column j = R_i(first) e_j.
    locked = np.hypot(rot[..., k, k], rot[..., j, k]) < 1e-9
    first = np.where(locked, np.arctan2(sign * rot[..., k, j], rot[..., j, j]), first)
    third = np.where(locked, 0.0, third)
    return np.rad2deg(np.stack([first, middle, third], axis=-1))


def local_rotations(motion: Motion) -> np.ndarray:
    """(F, J, 3, 3) parent_from_joint rotations; identity for joints without rotation channels."""
    rot = np.broadcast_to(np.eye(3), (motion.num_frames, motion.num_joints, 3, 3)).copy()
    for index, joint in enumerate(motion.joints):
        columns = motion.channel_slice(index)
        values = motion.channels[:, columns]
        for channel, column in zip(joint.channels, values.T, strict=True):
            if channel in ROTATION_CHANNELS:
                # Intrinsic order: each later channel multiplies on the right.
                rot[:, index] = rot[:, index] @ axis_rotations(_AXIS_OF_CHANNEL[channel], column)
    return rot


REFERENCE_TURN_DEG = 20.0
"""A joint "jumps" between two frames when its local rotation turns by more than this."""
REFERENCE_MIN_JOINTS = 4
"""Frame 0 is a reference pose when at least this many joints jump into frame 1 ..."""
REFERENCE_REST_DEG = 15.0
"""... or when every joint but the root is within this of its rest rotation in frame 0 (the
skeleton's own T-pose) and more joints jump into frame 1 than in any later step."""


def rotation_angles_deg(rotations: np.ndarray) -> np.ndarray:
    """(...) the geodesic angle of each (..., 3, 3) rotation from the identity, in degrees."""
    cos = np.clip((np.trace(rotations, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def joint_turns_deg(motion: Motion) -> np.ndarray:
    """(F-1, J) each joint's turn (geodesic angle of its local rotation) from each frame to the
    next, in degrees; an Euler wrap-around (179 to -179) counts as the 2 degrees it is."""
    rot = local_rotations(motion)
    return rotation_angles_deg(np.einsum("fjba,fjbc->fjac", rot[:-1], rot[1:]))  # R_k^T R_k+1


def leading_reference_frames(motion: Motion) -> int:
    """The frames before the capture: 0 when frame 0 is already motion; else the reference pose
    in frame 0 and the blend out of it, the frames after it that turn a joint faster than any
    later step of the clip does (`blend_frames`).

    Many BVH conversions of the CMU database put the skeleton's T-pose in frame 0 and the
    capture from frame 1; played as motion, that frame is a teleport no body makes. Of the 12
    clips with CMU names in ``shared/data/mocap_bvh``, 9 turn 9-16 joints by more than
    `REFERENCE_TURN_DEG` from frame 0 to 1, where no later step of any clip (120 Hz) turns more
    than 2 joints that far (a wrist or toe glitch); the other 3 (walk, start-walk-stop, wave)
    start moving at once (no joint jumps). Frame 0 is a reference pose when at least
    `REFERENCE_MIN_JOINTS` joints jump into frame 1, more than twice as many as in any later
    step. The 3 clips with Daz names jump only 3 joints there (the shoulders drop the arms from
    horizontal), against at most 2 in a later step; their frame 0 is their skeleton's rest
    pose (no joint but the root turned more than 10.3 degrees from it; in their frame 1, 22.6-23.4;
    the 3 CMU-named clips that move from frame 0 turn joints 90-96 degrees there), so a rest
    pose in frame 0 that more joints jump out of than in any later step is a reference pose
    too (`REFERENCE_REST_DEG`).
    """
    if motion.num_frames < 3:
        return 0
    turns = joint_turns_deg(motion)
    jumps = (turns > REFERENCE_TURN_DEG).sum(axis=1)
    reference = jumps[0] >= max(REFERENCE_MIN_JOINTS, 2 * jumps[1:].max() + 1)
    if not reference:
        rest = rotation_angles_deg(local_rotations(motion)[0, 1:]).max() <= REFERENCE_REST_DEG
        reference = rest and jumps[0] > jumps[1:].max()
    if not reference:
        return 0
    return 1 + blend_frames(turns.max(axis=1)[1:], int(BLEND_MAX_S * motion.fps))


BLEND_MAX_S = 0.1
"""A blend out of a reference pose lasts at most this long (a bound, not a fit: the clips' blends
last 4 frames at 120 Hz, 33 ms), so that a clip that slows down from its first step on is not
taken for one."""


def blend_frames(fastest_deg: np.ndarray, most: int) -> int:
    """How many of the frames that follow a reference pose still blend out of it: the leading
    steps of `fastest_deg` (each step's largest joint turn, degrees, from the frame after the
    reference on) that turn faster than every step after them. The 3 Daz-named clips of
    ``shared/data/mocap_bvh`` ease the arms down from the rest pose over their frames 1-5
    (largest turns 24, 21, 15 and 6 degrees per 120 Hz step, then 0.6-0.8), where no later step
    turns more than 3.5 (climb_steps), 3.8 (sit_stand) or 10.1 (kick, a kick): 4 blend frames, 3
    for the kick, whose own kick is faster than the blend's last step. At most `most` frames.
    Without this, a synthetic sequence's first frame had the arms 70 degrees up and its second
    had them down, both wrists 400 mm apart in 1/30 s. In the 9 CMU-named clips with a T-pose
    the first step of the capture turns no faster than later ones (at most 18.3 degrees, dance,
    where later steps reach 38.6 and more): no blend."""
    count = 0
    while (count < min(most, len(fastest_deg) - 1)
           and fastest_deg[count] > fastest_deg[count + 1:].max()):
        count += 1
    return count


def local_translations(motion: Motion) -> np.ndarray:
    """(F, J, 3) joint positions in the parent frame: OFFSET plus any position channels."""
    translation = np.broadcast_to(motion.offsets, (motion.num_frames, motion.num_joints, 3)).copy()
    for index, joint in enumerate(motion.joints):
        values = motion.channels[:, motion.channel_slice(index)]
        for channel, column in zip(joint.channels, values.T, strict=True):
            if channel in POSITION_CHANNELS:
                translation[:, index, _AXIS_OF_CHANNEL[channel]] += column
    return translation


def forward_kinematics(
    motion: Motion, scale: float = 1.0, return_rotations: bool = False
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """(F, J, 3) joint_in_world positions, times `scale` (e.g. CMU_METRES_PER_UNIT).

    With return_rotations, also the (F, J, 3, 3) world_from_joint rotations.
    """
    parent_from_joint = local_rotations(motion)
    joint_in_parent = local_translations(motion)
    world_from_joint = np.empty_like(parent_from_joint)
    joint_in_world = np.empty_like(joint_in_parent)
    for index, joint in enumerate(motion.joints):
        if joint.parent < 0:
            world_from_joint[:, index] = parent_from_joint[:, index]
            joint_in_world[:, index] = joint_in_parent[:, index]
            continue
        world_from_parent = world_from_joint[:, joint.parent]
        world_from_joint[:, index] = world_from_parent @ parent_from_joint[:, index]
        joint_in_world[:, index] = joint_in_world[:, joint.parent] + np.einsum(
            "fij,fj->fi", world_from_parent, joint_in_parent[:, index]
        )
    joint_in_world = joint_in_world * scale
    return (joint_in_world, world_from_joint) if return_rotations else joint_in_world


def motion_from_rotations(
    joints: Sequence[Joint],
    parent_from_joint: np.ndarray,
    root_in_world: np.ndarray,
    frame_time_s: float,
) -> Motion:
    """Build a Motion from poses, e.g. of our body model, to write them as BVH.

    parent_from_joint: (F, J, 3, 3) local rotations (ignored for joints without rotation
    channels); root_in_world: (F, 3) root position in world; the root's position channels are
    written relative to its OFFSET so that forward_kinematics gives back root_in_world.
    Each joint's rotation channels must be three (any order); position channels other than the
    root's are written as 0.
    """
    joints = tuple(joints)
    parent_from_joint = np.asarray(parent_from_joint, dtype=float)
    root_in_world = np.asarray(root_in_world, dtype=float)
    num_frames = parent_from_joint.shape[0]
    if parent_from_joint.shape != (num_frames, len(joints), 3, 3):
        raise ValueError(f"rotations have shape {parent_from_joint.shape}, need (F, J, 3, 3)")
    if root_in_world.shape != (num_frames, 3):
        raise ValueError(f"root translations have shape {root_in_world.shape}, need (F, 3)")
    columns: list[np.ndarray] = []
    for index, joint in enumerate(joints):
        rotation_channels = [c for c in joint.channels if c in ROTATION_CHANNELS]
        if rotation_channels and len(rotation_channels) != 3:
            raise ValueError(f"joint {joint.name!r} needs 0 or 3 rotation channels")
        angles = (
            rotations_to_channels(parent_from_joint[:, index], rotation_channels)
            if rotation_channels
            else np.zeros((num_frames, 0))
        )
        used = 0
        for channel in joint.channels:
            if channel in ROTATION_CHANNELS:
                columns.append(angles[:, used])
                used += 1
            elif index == 0:
                axis = _AXIS_OF_CHANNEL[channel]
                columns.append(root_in_world[:, axis] - joint.offset[axis])
            else:
                columns.append(np.zeros(num_frames))
    channels = np.stack(columns, axis=1) if columns else np.zeros((num_frames, 0))
    return Motion(joints=joints, frame_time_s=frame_time_s, channels=channels)
