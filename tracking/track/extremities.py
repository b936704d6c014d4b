"""Start hypotheses from the ends of the visual hull (issue 20, item 1): a start that assumes
no stance.

A body's hull is a trunk with five branches: the head, two hands and two feet end where the
geodesic distance over the hull's surface, from the trunk, has its local maxima
(`hull_extremities`). Which end is which, the hull does not say: `extremity_assignments`
enumerates the head, the feet and the hands among them, ranked by how well the geodesic
distances between them agree with the subject's segment lengths; `pose_from_extremities`
then solves for the pose whose end sites reach them (inverse kinematics, least squares within
the joint limits). The tracker scores these poses by their XOR energy and refines the best
against the silhouettes (`SilhouetteTracker._initialise_from_hull`), beside the hull fit and
the upright starts, winning only by a clear lead (`tracker._EXTREMITY_LEAD`). An upside-down
body (a cartwheel, a handstand) is then a hypothesis like any other.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tracking.body.bvh import rotations_to_channels
from tracking.body.model import (
    N_POSE_PARAMS,
    NODE_INDEX,
    PARAM_INDEX,
    PARAM_MOVES_NODE,
    SEARCH_LOWER_LIMITS,
    SEARCH_UPPER_LIMITS,
    BodyShape,
    Pose,
    forward_kinematics,
    in_limits,
    pose_derivative_axes,
)

END_SITES = ("head_top", "l_wrist", "r_wrist", "l_ankle", "r_ankle")
"""The end sites an assignment puts on the hull's extremities, in `Assignment.ends` order."""

_PELVIS_WEIGHT = 0.3
"""Weight of the pelvis' pull towards the hull's centroid, against 1 for an end site."""
_TRANSLATIONS = [PARAM_INDEX[n] for n in ("root_tx", "root_ty", "root_tz")]


@dataclass(frozen=True)
class HullExtremities:
    """The ends of the hull's branches: their points (K, 3), world frame, the geodesic
    distance of each from the trunk (K,) and between them (K, K), metres."""

    points: np.ndarray
    reach_m: np.ndarray
    between_m: np.ndarray


@dataclass(frozen=True)
class Assignment:
    """Which extremity (index) each of `END_SITES` is on, -1 for an end not on any (a hand
    against the body); `cost` ranks the assignments (lower: the geodesic distances agree
    better with the segment lengths)."""

    ends: tuple[int, int, int, int, int]
    cost: float


def hull_extremities(points: np.ndarray, voxel_m: float, radius_m: float = 0.15,
                     min_reach_m: float = 0.25, max_count: int = 7) -> HullExtremities:  # fmt: skip
    """The local maxima of the geodesic distance over the hull's surface voxels `points`
    (N, 3), from the voxel nearest their centroid (in the trunk): no voxel within `radius_m`
    reaches further. Those `min_reach_m` or more from it, at most `max_count`, furthest
    first. The surface is a graph of the voxels 26-adjacent (edges under 1.8 voxels)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=float)
    empty = HullExtremities(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 0)))
    if len(points) < 10:
        return empty
    tree = cKDTree(points)
    pairs = tree.query_pairs(1.8 * voxel_m, output_type="ndarray")
    if len(pairs) == 0:
        return empty
    length = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    graph = coo_matrix((length, (pairs[:, 0], pairs[:, 1])),
                       shape=(len(points), len(points))).tocsr()  # fmt: skip
    source = int(np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    reach = dijkstra(graph, directed=False, indices=source)
    reach = np.where(np.isfinite(reach), reach, -np.inf)  # other parts: never an end
    # A voxel is an end when nothing within `radius_m` reaches further (ties: the lowest
    # index of a plateau, so that one plateau gives one end).
    order = np.argsort(-reach, kind="stable")
    taken = np.zeros(len(points), bool)
    ends: list[int] = []
    for i in order:
        if reach[i] < min_reach_m or len(ends) >= max_count:
            break
        if taken[i]:
            continue
        near = tree.query_ball_point(points[i], radius_m)
        taken[near] = True
        if reach[near].max() <= reach[i]:
            ends.append(int(i))
    if not ends:
        return empty
    between = dijkstra(graph, directed=False, indices=ends)[:, ends]
    return HullExtremities(points[ends], reach[ends], between)


def _geodesic_lengths(shape: BodyShape) -> dict[str, float]:
    """Surface-path lengths the hull's geodesics should roughly have, metres."""
    trunk = shape.pelvis_to_spine + shape.spine_to_neck
    head = shape.neck_to_head_top
    arm = shape.shoulder_half_width + shape.upper_arm + shape.forearm + shape.hand
    leg = shape.hip_half_width + shape.thigh + shape.shank + shape.ankle_height
    return {
        "head_foot": head + trunk + leg,
        "head_hand": head + arm,
        "foot_foot": 2 * leg,
        "hand_hand": 2 * arm,
        "hand_foot": arm + trunk + leg,
    }


def extremity_assignments(ends: HullExtremities, shape: BodyShape,
                          max_count: int = 8) -> list[Assignment]:  # fmt: skip
    """The `max_count` assignments of head, hands and feet to the extremities whose geodesic
    distances agree best with `shape`'s lengths (relative squared differences; distances the
    hull's folds and touching limbs shorten count half when shorter). Every assignment has
    a head and two feet; a hand may be on no extremity (a fixed cost). Left and right are
    both orders: the pose's facing follows from them."""
    k = len(ends.points)
    if k < 3:
        return []
    lengths = _geodesic_lengths(shape)
    between = ends.between_m

    def term(a: int, b: int, kind: str) -> float:
        expected = lengths[kind]
        d = between[a, b]
        if not np.isfinite(d):
            return 4.0
        r = (d - expected) / expected
        return float(r * r if r > 0 else 0.5 * r * r)

    missing_hand = 0.15
    scored: list[Assignment] = []
    for head in range(k):
        others = [i for i in range(k) if i != head]
        for lf, rf in itertools.permutations(others, 2):
            base = (term(head, lf, "head_foot") + term(head, rf, "head_foot")
                    + term(lf, rf, "foot_foot"))  # fmt: skip
            rest = [i for i in others if i not in (lf, rf)]
            for lh, rh in itertools.permutations([-1, -2, *rest], 2):
                cost = base
                hands = [h for h in (lh, rh) if h >= 0]
                cost += missing_hand * (2 - len(hands))
                for h in hands:
                    cost += (term(head, h, "head_hand") + term(lf, h, "hand_foot")
                             + term(rf, h, "hand_foot"))  # fmt: skip
                if len(hands) == 2:
                    cost += term(lh, rh, "hand_hand")
                scored.append(Assignment((head, max(lh, -1), max(rh, -1), lf, rf), cost))
    scored.sort(key=lambda a: a.cost)
    unique: dict[tuple[int, ...], Assignment] = {}  # each at its lowest cost, in cost order
    for a in scored:
        unique.setdefault(a.ends, a)
        if len(unique) >= max_count:
            break
    return list(unique.values())


def pose_from_extremities(ends: HullExtremities, assignment: Assignment, shape: BodyShape,
                          free: np.ndarray, centre: np.ndarray) -> tuple[Pose, float]:  # fmt: skip
    """The pose (parameters `free` solved, the rest 0) whose end sites reach the extremities of
    `assignment`, its pelvis pulled weakly towards `centre` (the hull's centroid): least
    squares with a soft-L1 loss (an extremity is a fingertip or a toe, a few centimetres past
    the end site) within the joint limits, from the root that puts the head over the feet
    (two facings). Returns the pose and its RMS end-site distance, metres."""
    from scipy.optimize import least_squares

    sites = [NODE_INDEX[n] for n, e in zip(END_SITES, assignment.ends, strict=True) if e >= 0]
    targets = np.array([ends.points[e] for e in assignment.ends if e >= 0])
    head, feet = targets[0], targets[-2:]
    pelvis_index = NODE_INDEX["pelvis"]
    free = np.asarray(free)
    lower, upper = SEARCH_LOWER_LIMITS[free], SEARCH_UPPER_LIMITS[free]

    def params(values: np.ndarray) -> np.ndarray:
        x = np.zeros(N_POSE_PARAMS)
        x[free] = values
        return x

    nodes = [*sites, pelvis_index]
    weights = np.r_[np.ones(len(sites)), _PELVIS_WEIGHT][:, None, None]
    moves = PARAM_MOVES_NODE[free][:, nodes].T[:, None, :]  # (nodes, 1, free)
    translation = np.isin(free, _TRANSLATIONS)

    def residuals(values: np.ndarray) -> np.ndarray:
        world = forward_kinematics(Pose(params(values)), shape)
        return (weights[:, :, 0] * (world[nodes, :3, 3] - np.r_[targets, [centre]])).ravel()

    def jacobian(values: np.ndarray) -> np.ndarray:
        world, axes, pivots = pose_derivative_axes(Pose(params(values)), shape)
        w = world[nodes, :3, 3]  # (nodes, 3)
        axes, pivots = axes[free], pivots[free]  # (free, 3)
        d = np.cross(axes[None], w[:, None] - pivots[None])  # (nodes, free, 3)
        d[:, translation] = axes[translation][None]
        return (weights * moves * d.transpose(0, 2, 1)).reshape(-1, len(free))

    up = head - feet.mean(axis=0)
    up /= max(np.linalg.norm(up), 1e-9)
    side = feet[0] - feet[1]  # the left foot is on the body's +x
    side -= (side @ up) * up
    if np.linalg.norm(side) < 0.1:
        side = np.linalg.svd(up[None])[2][-1]
    side /= np.linalg.norm(side)
    best: tuple[float, np.ndarray] | None = None
    for x_axis in (side, np.cross(up, side)):
        x0 = np.zeros(N_POSE_PARAMS)
        x0[:3] = feet.mean(axis=0) + shape.hip_height * up
        rotation = np.stack([x_axis, up, np.cross(x_axis, up)], axis=1)
        x0[3:6] = np.deg2rad(rotations_to_channels(rotation, "ZXY"))
        start = np.clip(x0[free], lower, upper)
        solution = least_squares(residuals, start, jac=jacobian, bounds=(lower, upper),
                                 loss="soft_l1", f_scale=0.08, max_nfev=60)  # fmt: skip
        if best is None or solution.cost < best[0]:
            best = (float(solution.cost), solution.x)
    assert best is not None
    x = in_limits(params(best[1]))
    world = forward_kinematics(Pose(x), shape)
    rms = float(np.sqrt(np.mean(np.sum((world[sites, :3, 3] - targets) ** 2, axis=1))))
    return Pose(x), rms
