"""Kinematics of a tracked body: gap filling, zero-lag filtering, derivatives and joint angles.

Everything works on a `MotionSequence`: per-frame ``world_from_node`` transforms of the body
model of `tracking.body.model` (16 nodes, metres, Y up), its `BodyShape` and the frame rate, with
NaN
in frames that have no data. Pure geometry: no file, COLMAP or Rerun access.

Processing order (`compute_kinematics`), and why:

1. Gaps (runs of frames without data) no longer than ``max_gap_frames`` are filled: local joint
   rotations by spherical interpolation (SLERP), translations linearly, between the frames
   around the gap. Longer gaps, and gaps at either end (nothing to interpolate towards), stay
   gaps: their frames are NaN in every output. Every gap is reported as a `Gap`.
2. Each run of consecutive frames with data is low-pass filtered on its own, with a zero-lag
   Butterworth filter (`scipy.signal.filtfilt`: forward and backward passes). The filter acts on
   the *local* description of the skeleton: each node's offset in its parent (the root's: its
   world position) and its rotation relative to its parent, as the continuous rotation vector
   since the run's first frame; the skeleton is then recomposed, so the filtered body stays
   rigid (bone lengths do not drift). ``cutoff_hz`` is the -3 dB frequency of the whole
   two-pass filter: each pass is designed at ``cutoff / C`` with Winter's correction
   ``C = (2**0.5 - 1) ** (1 / (2 * order))`` (Winter, "Biomechanics and Motor Control of Human
   Movement", 4th ed., sec. 3.4.4.3). The quadratic trend of a run is taken out before
   filtering and put back after, and the ends are extended smoothly (`lowpass`), so uniform
   acceleration and rotation at constant speed about a fixed axis pass exactly.
3. Derivatives: velocities by second-order central differences, accelerations by the 3-point
   second difference (both exact for quadratics, also at the ends, where one-sided formulas of
   the same order take over). Angular velocity from rotation matrices,
   ``omega_k = log(R_{k+1} R_{k-1}^T) / (2 dt)`` (world axes), exact for a constant angular
   velocity; angular acceleration by central differences of that. The first and last
   ~1/cutoff seconds of a run are less accurate than the rest, as with any filter.

Joint angles (`JOINT_ANGLE_CONVENTIONS`) follow the ISB recommendations (Wu et al. 2002, J Biomech
35:543, lower limb and spine; Wu et al. 2005, J Biomech 38:981, upper limb): the rotation of the
distal segment relative to the proximal one, ``R = R_parent^T R_child``, decomposed as the
Cardan sequence flexion about the proximal medio-lateral axis (our X), then ab/adduction about
the floating antero-posterior axis (Z), then internal/external rotation about the distal
segment's long axis (Y): intrinsic X-Z-Y in our axes, which is the ISB Z-X-Y of the joint
coordinate system of Grood and Suntay (ISB axes: X forward, Y up, Z right). Exceptions:

* pelvis, relative to the world axes: intrinsic Y-Z-X (rotation, obliquity, tilt), the order
  Baker (2001, Gait & Posture 13:1) recommends, so tilt and obliquity do not depend on the
  walking direction;
* shoulders use X-Z-Y too, not ISB's Y-X-Y for the humerus, because the report needs separate
  flexion and abduction angles and Y-X-Y is singular with the arm hanging (our rest pose);
  X-Z-Y is singular at 90 degrees of abduction instead.

Signs are clinical, the same on both sides: flexion positive (hip, shoulder, elbow: the distal
segment moves forward; knee: the shank moves backward; spine, neck, pelvis: forward bending or
anterior tilt), abduction positive away from the midline, internal rotation positive. For the
pelvis, spine and neck, "abduction" is lateral bending (pelvis: obliquity) to the right and
"rotation" is axial rotation to the left, the ISB signs; the pelvis rotation is its heading in
the world. Angles are zero in the rest pose (upright, arms hanging, palms facing the body).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from recon.errors import UserError
from tracking.body.model import (
    JOINT_NAMES,
    NODE_INDEX,
    NODE_NAMES,
    NODE_PARENTS,
    POSE_LAYOUT,
    BodyShape,
    Pose,
    forward_kinematics,
)
from tracking.report.anthropometry import BodySegments

ANGLE_NAMES: tuple[str, ...] = ("flexion", "abduction", "rotation")
_N_NODES = len(NODE_NAMES)


# ---------------------------------------------------------------------------------------------
# The sequence
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionSequence:
    """A tracked body over consecutive frames ``first_frame, first_frame + 1, ...``.

    world_from_node: (T, 16, 4, 4) transforms of `NODE_NAMES` (metres, the input's world axes,
    Y up); a frame without data is NaN. frame_rate in Hz. source: a description for reports.
    """

    world_from_node: np.ndarray
    shape: BodyShape
    frame_rate: float
    first_frame: int = 0
    source: str = ""

    def __post_init__(self) -> None:
        w = np.array(self.world_from_node, dtype=float)
        if w.ndim != 4 or w.shape[1:] != (_N_NODES, 4, 4):
            raise ValueError(f"world_from_node needs shape (T, {_N_NODES}, 4, 4), got {w.shape}")
        if not (np.isfinite(self.frame_rate) and self.frame_rate > 0):
            raise UserError(f"frame rate must be positive, got {self.frame_rate}")
        # A frame is all or nothing: one bad number invalidates the whole frame.
        w[~np.isfinite(w).all(axis=(1, 2, 3))] = np.nan
        w.flags.writeable = False
        object.__setattr__(self, "world_from_node", w)

    @classmethod
    def from_poses(
        cls,
        params: np.ndarray,
        shape: BodyShape,
        frame_rate: float,
        first_frame: int = 0,
        source: str = "",
    ) -> MotionSequence:
        """From (T, 24) pose parameters; a row with any NaN is a frame without data."""
        params = np.asarray(params, dtype=float)
        world = np.full((len(params), _N_NODES, 4, 4), np.nan)
        for t, row in enumerate(params):
            if np.all(np.isfinite(row)):
                world[t] = forward_kinematics(Pose(row), shape)
        return cls(world, shape, frame_rate, first_frame, source)

    @property
    def num_frames(self) -> int:
        return int(self.world_from_node.shape[0])

    @property
    def frames(self) -> np.ndarray:
        """(T,) frame numbers."""
        return self.first_frame + np.arange(self.num_frames)

    @property
    def times_s(self) -> np.ndarray:
        """(T,) frame number / frame rate, the ``time`` timeline of the recordings."""
        return self.frames / self.frame_rate

    @property
    def valid(self) -> np.ndarray:
        """(T,) True where the frame has data."""
        return np.isfinite(self.world_from_node[:, 0, 0, 0])


# ---------------------------------------------------------------------------------------------
# Gaps
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Gap:
    """Frames ``first_frame..last_frame`` (inclusive) had no data; ``filled`` if interpolated."""

    first_frame: int
    last_frame: int
    filled: bool
    reason: str

    @property
    def num_frames(self) -> int:
        return self.last_frame - self.first_frame + 1


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges of the runs of True in a (T,) mask."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def local_from_world(world_from_node: np.ndarray) -> np.ndarray:
    """(..., 16, 4, 4) parent_from_node; the root's is world_from_pelvis."""
    local = world_from_node.copy()
    for node, parent in enumerate(NODE_PARENTS):
        if parent >= 0:
            r_parent = world_from_node[..., parent, :3, :3]
            r_t = np.swapaxes(r_parent, -1, -2)
            local[..., node, :3, :3] = r_t @ world_from_node[..., node, :3, :3]
            local[..., node, :3, 3] = np.einsum(
                "...ij,...j->...i", r_t,
                world_from_node[..., node, :3, 3] - world_from_node[..., parent, :3, 3],
            )  # fmt: skip
    return local


def world_from_local(parent_from_node: np.ndarray) -> np.ndarray:
    """Inverse of `local_from_world`: forward kinematics over the node tree."""
    world = np.empty_like(parent_from_node)
    for node, parent in enumerate(NODE_PARENTS):
        if parent < 0:
            world[..., node, :, :] = parent_from_node[..., node, :, :]
        else:
            world[..., node, :, :] = world[..., parent, :, :] @ parent_from_node[..., node, :, :]
    return world


def fill_gaps(
    seq: MotionSequence, max_gap_frames: int
) -> tuple[MotionSequence, tuple[Gap, ...]]:
    """Interpolate interior gaps of at most ``max_gap_frames`` frames; report every gap."""
    valid = seq.valid
    gaps: list[Gap] = []
    world = seq.world_from_node.copy()
    local = local_from_world(np.nan_to_num(world))
    for start, stop in runs(~valid):
        first, last = int(seq.frames[start]), int(seq.frames[stop - 1])
        length = stop - start
        if start == 0 or stop == len(valid):
            gaps.append(Gap(first, last, False, "at an end of the sequence: nothing to "
                            "interpolate towards"))
            continue
        if length > max_gap_frames:
            gaps.append(Gap(first, last, False, f"longer than {max_gap_frames} frames"))
            continue
        a, b = start - 1, stop
        u = (np.arange(start, stop) - a) / (b - a)  # (G,) interpolation fractions
        filled = np.tile(np.eye(4), (length, _N_NODES, 1, 1))
        for node in range(_N_NODES):
            key = Rotation.from_matrix(np.stack([local[a, node, :3, :3], local[b, node, :3, :3]]))
            filled[:, node, :3, :3] = Slerp([0.0, 1.0], key)(u).as_matrix()
        filled[:, :, :3, 3] = (
            (1 - u)[:, None, None] * local[a, :, :3, 3] + u[:, None, None] * local[b, :, :3, 3]
        )
        world[start:stop] = world_from_local(filled)
        gaps.append(Gap(first, last, True, f"interpolated ({length} <= {max_gap_frames} frames)"))
    out = MotionSequence(world, seq.shape, seq.frame_rate, seq.first_frame, seq.source)
    return out, tuple(gaps)


# ---------------------------------------------------------------------------------------------
# Filtering and differentiation
# ---------------------------------------------------------------------------------------------


def min_frames_to_filter(order: int) -> int:
    """Shortest run the low-pass filter accepts (scipy's filtfilt needs more than 3 (order+1))."""
    return 3 * (order + 1) + 1


def winter_correction(order: int, passes: int = 2) -> float:
    """Ratio of the -3 dB frequency of ``passes`` Butterworth passes to that of one pass."""
    return float((2.0 ** (1.0 / passes) - 1.0) ** (1.0 / (2 * order)))


def check_cutoff(frame_rate: float, cutoff_hz: float, order: int) -> None:
    """A one-line error when the filter cannot be designed at this frame rate."""
    if order < 1:
        raise UserError(f"filter order must be at least 1, got {order}")
    design = cutoff_hz / winter_correction(order)
    if design >= 0.5 * frame_rate:
        limit = 0.5 * frame_rate * winter_correction(order)
        raise UserError(
            f"cut-off {cutoff_hz:g} Hz is too high for {frame_rate:g} frames/s: it must be below "
            f"{limit:.3g} Hz (the Nyquist frequency with the two-pass correction); "
            "use --cutoff-hz 0 to skip filtering"
        )


def _extension(x: np.ndarray, pad: int) -> np.ndarray:
    """(pad, N) samples to put before x (T, N), oldest first: the quadratic fitted to
    x[:pad + 1], extrapolated, plus the odd reflection of its residual about x[0]."""
    tau = np.arange(pad + 1, dtype=float)
    basis = np.vander(tau, 3)
    coef, *_ = np.linalg.lstsq(basis, x[: pad + 1], rcond=None)
    residual = x[: pad + 1] - basis @ coef
    before = np.vander(-tau[1:], 3) @ coef + 2.0 * residual[0] - residual[1:]
    return before[::-1]


def lowpass(x: np.ndarray, frame_rate: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Zero-lag Butterworth low-pass of x (T, ...) along time; ``cutoff_hz`` is the -3 dB
    frequency of the two-pass filter. Needs ``min_frames_to_filter(order)`` frames.

    Edges: the least-squares quadratic of the whole series is taken out before filtering and
    put back after, so uniformly accelerated motion passes exactly; the rest is extended at
    each end by the quadratic fitted to the samples near that end plus the odd reflection of
    that fit's residual (value, slope and curvature continue smoothly), and filtfilt's own odd
    padding goes beyond that, so the filter's start-up transient stays outside the data.
    """
    check_cutoff(frame_rate, cutoff_hz, order)
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n < min_frames_to_filter(order):
        raise UserError(
            f"{n} frames are too few to filter; the order-{order} low-pass needs at least "
            f"{min_frames_to_filter(order)}"
        )
    flat = x.reshape(n, -1)
    tau = np.linspace(-1.0, 1.0, n)
    basis = np.vander(tau, 3)
    coef, *_ = np.linalg.lstsq(basis, flat, rcond=None)
    trend = basis @ coef
    rest = flat - trend
    pad = min(n - 1, max(3 * (order + 1), int(round(frame_rate / cutoff_hz))))
    extended = np.concatenate([_extension(rest, pad), rest, _extension(rest[::-1], pad)[::-1]])
    # Imported here: scipy.signal takes 1.8 s to import, which every `mocap` process that
    # loads the report (a refused input too) paid.
    from scipy.signal import butter, filtfilt

    b, a = butter(order, cutoff_hz / winter_correction(order) / (0.5 * frame_rate))
    out = filtfilt(b, a, extended, axis=0)[pad : pad + n] + trend
    return out.reshape(x.shape)


def unwrapped_rotation_vectors(world_from_body: np.ndarray) -> np.ndarray:
    """(T, ..., 3) rotation vectors of ``R_0^T R_t`` (rotation since the first frame, in the
    first frame's axes), continuous in time: past 180 degrees they keep growing instead of
    jumping to the opposite direction."""
    r = np.asarray(world_from_body, dtype=float)
    rel = np.swapaxes(r[0], -1, -2)[None] @ r
    rv = Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(*r.shape[:-2], 3)
    out = rv.copy()
    for t in range(1, len(rv)):
        theta = np.linalg.norm(rv[t], axis=-1, keepdims=True)
        axis = np.divide(rv[t], theta, out=np.zeros_like(rv[t]), where=theta > 1e-12)
        # Equivalent vectors are (theta + 2 pi k) axis; take the one nearest the previous frame.
        along = np.sum(out[t - 1] * axis, axis=-1, keepdims=True)
        k = np.round((along - theta) / (2 * np.pi))
        out[t] = np.where(theta > 1e-12, (theta + 2 * np.pi * k) * axis, rv[t])
    return out


def smooth_motion(
    world_from_node: np.ndarray, frame_rate: float, cutoff_hz: float, order: int = 2
) -> np.ndarray:
    """Low-pass a (T, 16, 4, 4) run of frames (no NaN), keeping the skeleton rigid.

    Filters each node's offset in its parent and its rotation relative to the parent, the
    latter as the continuous rotation vector since the run's first frame (a rotation about a
    fixed axis at constant speed is then a straight line, which the filter passes exactly).
    """
    local = local_from_world(world_from_node)
    out = np.tile(np.eye(4), (*local.shape[:2], 1, 1))
    out[..., :3, 3] = lowpass(local[..., :3, 3], frame_rate, cutoff_hz, order)
    rotvec = lowpass(unwrapped_rotation_vectors(local[..., :3, :3]), frame_rate, cutoff_hz, order)
    start = local[0, :, :3, :3]
    out[..., :3, :3] = start[None] @ Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix(
    ).reshape(rotvec.shape[:-1] + (3, 3))
    return world_from_local(out)


def derivative(x: np.ndarray, dt: float) -> np.ndarray:
    """d/dt along axis 0 by second-order differences (central inside, one-sided at the ends)."""
    return np.gradient(x, dt, axis=0, edge_order=2)


def second_derivative(x: np.ndarray, dt: float) -> np.ndarray:
    """d2/dt2 along axis 0: (x[k+1] - 2 x[k] + x[k-1]) / dt^2 inside and the second-order
    one-sided (2 x0 - 5 x1 + 4 x2 - x3) / dt^2 at the ends; exact for cubics. Needs 3 frames
    (with 3, the one value is used for all)."""
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    if len(x) < 4:
        out[:] = (x[0] - 2 * x[1] + x[2]) / dt**2
        return out
    out[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    out[0] = (2 * x[0] - 5 * x[1] + 4 * x[2] - x[3]) / dt**2
    out[-1] = (2 * x[-1] - 5 * x[-2] + 4 * x[-3] - x[-4]) / dt**2
    return out


def angular_velocity(world_from_body: np.ndarray, dt: float) -> np.ndarray:
    """(T, ..., 3) angular velocity in world axes (rad/s) of (T, ..., 3, 3) rotations.

    ``[omega]_x = dR/dt R^T``; from the relative rotation between the neighbouring frames,
    ``log(R_{k+1} R_{k-1}^T) / (2 dt)`` (forward/backward at the ends), which is exact when the
    angular velocity is constant.
    """
    r = np.asarray(world_from_body, dtype=float)
    n = len(r)
    if n < 2:
        raise UserError("angular velocity needs at least 2 frames")
    later = np.concatenate([r[1:2], r[2:], r[-1:]])
    earlier = np.concatenate([r[:1], r[:-2], r[-2:-1]])
    steps = np.full(n, 2.0)
    steps[0] = steps[-1] = 1.0
    rel = later @ np.swapaxes(earlier, -1, -2)
    rotvec = Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(*r.shape[:-2], 3)
    return rotvec / (steps * dt).reshape(-1, *([1] * (rotvec.ndim - 1)))


# ---------------------------------------------------------------------------------------------
# Joint angles
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AngleConvention:
    """How the angles of one joint are read from ``R = R_parent^T R_child``.

    sequence: intrinsic Euler axes (scipy's upper-case convention). signs: factors turning the
    angles about X, Z and Y into (flexion, abduction, rotation).
    """

    joint: str
    sequence: str
    signs: tuple[float, float, float]
    meaning: str


def _limb(joint: str, flexion_sign: float, meaning: str) -> tuple[AngleConvention, ...]:
    # Left limbs hang at +X: +Z abducts them and +Y turns their front outwards; mirrored right.
    return (
        AngleConvention(f"l_{joint}", "XZY", (flexion_sign, 1.0, -1.0), meaning),
        AngleConvention(f"r_{joint}", "XZY", (flexion_sign, -1.0, 1.0), meaning),
    )


JOINT_ANGLE_CONVENTIONS: tuple[AngleConvention, ...] = (
    AngleConvention("pelvis", "YZX", (1.0, 1.0, 1.0),
                    "pelvis vs world: anterior tilt, obliquity (right side down), heading"),
    AngleConvention("spine", "XZY", (1.0, 1.0, 1.0),
                    "thorax vs pelvis: flexion, lateral bend right, axial rotation left"),
    AngleConvention("neck", "XZY", (1.0, 1.0, 1.0),
                    "head vs thorax: flexion, lateral bend right, axial rotation left"),
    *_limb("shoulder", -1.0, "humerus vs thorax: flexion, abduction, internal rotation"),
    *_limb("elbow", -1.0, "forearm vs humerus: flexion, abduction, internal rotation"),
    *_limb("hip", -1.0, "thigh vs pelvis: flexion, abduction, internal rotation"),
    *_limb("knee", 1.0, "shank vs thigh: flexion, abduction, internal rotation"),
    # Rigid in the body model (angles always 0): used to resolve joint moments only.
    *_limb("wrist", -1.0, "hand vs forearm: forward swing, abduction, internal rotation"),
    *_limb("ankle", -1.0, "foot vs shank: dorsiflexion, abduction, internal rotation"),
)  # fmt: skip
CONVENTION_OF_JOINT: dict[str, AngleConvention] = {c.joint: c for c in JOINT_ANGLE_CONVENTIONS}
ANGLE_JOINTS: tuple[str, ...] = JOINT_NAMES  # the 11 joints with degrees of freedom
_AXIS_SLOT = {"X": 0, "Z": 1, "Y": 2}


def _model_angles() -> dict[str, tuple[str, ...]]:
    # A joint's rotation parameters turn about its parent's X, Y or Z axis (`PoseParam.axis`,
    # the elbow's about -X), the axes of the Cardan sequence: X is flexion (the pelvis' tilt),
    # Z abduction (obliquity), Y rotation (heading).
    slots: dict[str, set[int]] = {joint: set() for joint in ANGLE_JOINTS}
    for param in POSE_LAYOUT:
        if param.kind == "rotation" and param.joint in slots:
            axis = "XYZ"[int(np.argmax(np.abs(param.axis)))]
            slots[param.joint].add(_AXIS_SLOT[axis])
    return {joint: tuple(ANGLE_NAMES[k] for k in sorted(s)) for joint, s in slots.items()}


MODEL_ANGLES: dict[str, tuple[str, ...]] = _model_angles()
"""The angles (`ANGLE_NAMES`) of each joint that are degrees of freedom of the body model, read
from its own list of pose parameters (`tracking.body.model.POSE_LAYOUT`): all three for the
pelvis, spine, shoulders and hips; flexion only for the hinges (neck, elbows, knees). The other
angles of a hinge are 0 by construction (the Cardan decomposition of a rotation about X), in
every sequence of this model: the report leaves them out of its table, plots and ``.mot``
instead of printing columns of zeros. A tracked, retargeted or BVH sequence is a pose of this
model, so its list is the one to go by (zeros in the data would also drop a real degree of
freedom that happened not to move); `shown_angles` keeps any other angle that does move, which
only a sequence built in code from arbitrary transforms has."""


def shown_angles(joint_angles_rad: np.ndarray, tolerance_deg: float = 1e-3
                 ) -> dict[str, tuple[str, ...]]:  # fmt: skip
    """`MODEL_ANGLES`, plus any angle of (T, J, 3) ``joint_angles_rad`` (`ANGLE_JOINTS` order)
    that moves more than ``tolerance_deg`` away from 0 in some frame, so that nothing measured is
    hidden; in `ANGLE_NAMES` order."""
    moving = np.nanmax(np.abs(np.degrees(joint_angles_rad)), axis=0, initial=0.0) > tolerance_deg
    return {joint: tuple(name for k, name in enumerate(ANGLE_NAMES)
                         if name in MODEL_ANGLES[joint] or moving[j, k])
            for j, joint in enumerate(ANGLE_JOINTS)}  # fmt: skip


def relative_rotation(world_from_node: np.ndarray, joint: str) -> np.ndarray:
    """(T, 3, 3) parent_from_joint rotations; the pelvis' parent is the world."""
    node = NODE_INDEX[joint]
    r = world_from_node[:, node, :3, :3]
    parent = NODE_PARENTS[node]
    if parent < 0:
        return r
    return np.swapaxes(world_from_node[:, parent, :3, :3], -1, -2) @ r


def anatomical_angles(rotation: np.ndarray, convention: AngleConvention) -> np.ndarray:
    """(T, 3) (flexion, abduction, rotation) in radians of (T, 3, 3) relative rotations."""
    out = np.full((len(rotation), 3), np.nan)
    ok = np.isfinite(rotation).all(axis=(1, 2))
    if ok.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # scipy's gimbal-lock warning
            euler = Rotation.from_matrix(rotation[ok]).as_euler(convention.sequence)
        about = np.empty_like(euler)
        for k, axis in enumerate(convention.sequence):
            about[:, _AXIS_SLOT[axis]] = euler[:, k]
        out[ok] = about * np.array(convention.signs)
    return out


def _unwrap_valid(angles: np.ndarray) -> np.ndarray:
    """np.unwrap along time over the frames with data (NaN frames stay NaN)."""
    out = angles.copy()
    ok = np.isfinite(angles).all(axis=tuple(range(1, angles.ndim)))
    if ok.sum() > 1:
        out[ok] = np.unwrap(angles[ok], axis=0)
    return out


def joint_angles(world_from_node: np.ndarray, joints: tuple[str, ...] = ANGLE_JOINTS
                 ) -> np.ndarray:  # fmt: skip
    """(T, J, 3) anatomical angles (radians) of `joints`, continuous over time."""
    out = np.stack([
        anatomical_angles(relative_rotation(world_from_node, j), CONVENTION_OF_JOINT[j])
        for j in joints
    ], axis=1)  # fmt: skip
    return _unwrap_valid(out)


# ---------------------------------------------------------------------------------------------
# Segment kinematics
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Kinematics:
    """Filtered kinematics of a sequence; every array is NaN where the frame has no data.

    Shapes: T frames, S segments (`segments.names`), J = len(ANGLE_JOINTS). Positions in metres
    and world axes; rotations are world_from_segment; angular velocities/accelerations in world
    axes (rad/s, rad/s^2); joint angles in radians (`ANGLE_NAMES` order). ``differentiated``
    marks the frames whose derivatives exist (runs long enough to filter and differentiate).
    """

    frames: np.ndarray  # (T,)
    times_s: np.ndarray  # (T,)
    frame_rate: float
    valid: np.ndarray  # (T,) after gap filling
    differentiated: np.ndarray  # (T,)
    world_from_node: np.ndarray  # (T, 16, 4, 4) filtered
    segments: BodySegments
    segment_com: np.ndarray  # (T, S, 3)
    segment_displacement: np.ndarray  # (T, S, 3) from the first frame with data
    segment_velocity: np.ndarray  # (T, S, 3)
    segment_acceleration: np.ndarray  # (T, S, 3)
    segment_rotation: np.ndarray  # (T, S, 3, 3)
    segment_angular_velocity: np.ndarray  # (T, S, 3)
    segment_angular_acceleration: np.ndarray  # (T, S, 3)
    com: np.ndarray  # (T, 3) whole body
    com_displacement: np.ndarray  # (T, 3)
    com_velocity: np.ndarray  # (T, 3)
    com_acceleration: np.ndarray  # (T, 3)
    joint_angles: np.ndarray  # (T, J, 3)
    joint_angular_velocity: np.ndarray  # (T, J, 3)
    gaps: tuple[Gap, ...]
    notes: tuple[str, ...]
    cutoff_hz: float  # 0: not filtered
    filter_order: int

    @property
    def joint_centres(self) -> np.ndarray:
        """(T, 16, 3) world positions of `NODE_NAMES`."""
        return self.world_from_node[:, :, :3, 3]


def compute_kinematics(
    seq: MotionSequence,
    segments: BodySegments,
    *,
    cutoff_hz: float = 6.0,
    filter_order: int = 2,
    max_gap_frames: int = 12,
) -> Kinematics:
    """Fill short gaps, filter each run of frames, differentiate; see the module docstring.

    ``cutoff_hz`` <= 0 skips filtering. Raises `UserError` (one line) when no frame has data or
    no run of frames is long enough to filter (or, unfiltered, to differentiate).
    """
    n = seq.num_frames
    if n == 0 or not seq.valid.any():
        raise UserError(
            f"{seq.source or 'the sequence'} has no frame with data "
            f"({n} frames, all missing or NaN)"
        )
    filtering = cutoff_hz > 0
    if filtering:
        check_cutoff(seq.frame_rate, cutoff_hz, filter_order)
    need = min_frames_to_filter(filter_order) if filtering else 3
    filled, gaps = fill_gaps(seq, max_gap_frames)
    valid = filled.valid
    spans = runs(valid)
    longest = max(b - a for a, b in spans)
    if longest < need:
        what = (f"the order-{filter_order} low-pass filter needs at least {need}" if filtering
                else f"differentiation needs at least {need}")
        raise UserError(
            f"{seq.source or 'the sequence'} is too short: its longest run of frames with data "
            f"has {longest} frame(s) and {what}"
        )
    notes: list[str] = []
    dt = 1.0 / seq.frame_rate
    world = filled.world_from_node.copy()
    differentiated = np.zeros(n, bool)
    for a, b in spans:
        if b - a < need:
            notes.append(
                f"frames {seq.frames[a]}-{seq.frames[b - 1]}: only {b - a} frame(s) between "
                f"gaps, too few to {'filter' if filtering else 'differentiate'}; positions and "
                "angles are unfiltered there and derivatives are left out"
            )
            continue
        if filtering:
            world[a:b] = smooth_motion(world[a:b], seq.frame_rate, cutoff_hz, filter_order)
        differentiated[a:b] = True
    ok = world[valid]
    if len(ok) > 1 and np.allclose(ok, ok[0], atol=1e-9, rtol=0.0):
        notes.append("the motion is constant (every frame holds the same pose): velocities "
                     "and accelerations are zero")

    node = segments.node
    rot = world[:, node, :3, :3]  # (T, S, 3, 3)
    com = np.einsum("tsij,sj->tsi", rot, segments.com_in_node) + world[:, node][..., :3, 3]
    body_com = np.einsum("tsi,s->ti", com, segments.mass_kg) / segments.total_mass_kg
    first = int(np.flatnonzero(valid)[0])
    angles = joint_angles(world)

    nan3 = np.full((n, len(node), 3), np.nan)
    vel, acc, omega, alpha = nan3.copy(), nan3.copy(), nan3.copy(), nan3.copy()
    com_vel, com_acc = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    angle_vel = np.full_like(angles, np.nan)
    for a, b in spans:
        if not differentiated[a]:
            continue
        vel[a:b] = derivative(com[a:b], dt)
        acc[a:b] = second_derivative(com[a:b], dt)
        omega[a:b] = angular_velocity(rot[a:b], dt)
        alpha[a:b] = derivative(omega[a:b], dt)
        com_vel[a:b] = derivative(body_com[a:b], dt)
        com_acc[a:b] = second_derivative(body_com[a:b], dt)
        angle_vel[a:b] = derivative(angles[a:b], dt)
    return Kinematics(
        frames=seq.frames,
        times_s=seq.times_s,
        frame_rate=seq.frame_rate,
        valid=valid,
        differentiated=differentiated,
        world_from_node=world,
        segments=segments,
        segment_com=com,
        segment_displacement=com - com[first],
        segment_velocity=vel,
        segment_acceleration=acc,
        segment_rotation=rot,
        segment_angular_velocity=omega,
        segment_angular_acceleration=alpha,
        com=body_com,
        com_displacement=body_com - body_com[first],
        com_velocity=com_vel,
        com_acceleration=com_acc,
        joint_angles=angles,
        joint_angular_velocity=angle_vel,
        gaps=gaps,
        notes=tuple(notes),
        cutoff_hz=float(cutoff_hz) if filtering else 0.0,
        filter_order=filter_order,
    )
