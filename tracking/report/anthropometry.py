"""Segment masses, centres of mass and inertia of the body model, from de Leva (1996).

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
Journal of Biomechanics 29(9):1223-1230, 1996, Table 4 (male and female values, segment
lengths between the joint centres and landmarks named there). `DE_LEVA_1996` copies the rows
used here: mass (fraction of body mass), centre of mass (fraction of the segment length from the
first endpoint) and radii of gyration (fractions of the segment length) about the sagittal
(antero-posterior), transverse (medio-lateral) and longitudinal axes, following Zatsiorsky's
axis names. For the foot, whose longitudinal axis is the heel-toe line, the "sagittal" axis is
the vertical one.

How the table maps onto the skeleton of `tracking.body.model` (one rigid segment per
node; end sites carry no segment of their own; Y up, X to the subject's left, Z forward, node
frames parallel to the world at rest):

=============  =========  ======================  ==============================================
segment        node       de Leva row(s)          endpoints in our skeleton
=============  =========  ======================  ==============================================
pelvis         pelvis     lower trunk OMPH-MIDH   spine joint (waist ~ omphalion) -> pelvis joint
                                                  (midpoint of the hip joints, MIDH)
thorax         spine      upper + middle trunk    neck joint (shoulder line ~ suprasternale) ->
                          SUPR-XYPH, XYPH-OMPH    spine joint; the two rows are lumped (masses
                                                  add, centres of mass average, inertias by the
                                                  parallel-axis theorem) with their sub-lengths
                                                  in de Leva's proportion (170.7 : 215.5 mm male)
head           neck       head VERT-CERV          head_top end site (vertex) -> neck joint (C7
                          (head and neck)         level ~ shoulder line)
upper_arm      shoulder   upper arm SJC-EJC       shoulder joint -> elbow joint
forearm        elbow      forearm EJC-WJC         elbow joint -> wrist end site
hand           wrist      hand WJC-DAC3           wrist end site -> fingertip (0, -hand, 0)
thigh          hip        thigh HJC-KJC           hip joint -> knee joint
shank          knee       shank KJC-AJC           knee joint -> ankle end site
foot           ankle      foot HEEL-TTIP          heel (0, -ankle_height, -0.2 foot_length) ->
                                                  toe tip (0, -ankle_height, 0.8 foot_length),
                                                  as in the body mesh
=============  =========  ======================  ==============================================

The foot's centre of mass lies on the heel-toe line at de Leva's fraction, raised to half the
ankle height: the table gives only its position along the segment, and the foot's mass sits
between the sole and the ankle, not on the sole. Wrists and ankles are rigid in the
model, so hand and foot move with the forearm and shank.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from tracking.body.model import NODE_INDEX, NODE_NAMES, NODE_PARENTS, BodyShape


class Sex(enum.StrEnum):
    MALE = "male"
    FEMALE = "female"


@dataclass(frozen=True)
class DeLevaRow:
    """One row of de Leva (1996) Table 4. Lengths in mm (the sample means); fractions in 0..1.

    com: distance of the centre of mass from the first endpoint over the length. r_sag, r_trans,
    r_long: radii of gyration about the sagittal, transverse and longitudinal axes over the
    length.
    """

    endpoints: str
    length_mm: float
    mass: float
    com: float
    r_sag: float
    r_trans: float
    r_long: float


DE_LEVA_1996: dict[Sex, dict[str, DeLevaRow]] = {
    Sex.MALE: {
        "head": DeLevaRow("VERT-CERV", 242.9, 0.0694, 0.5002, 0.303, 0.315, 0.261),
        "upper_trunk": DeLevaRow("SUPR-XYPH", 170.7, 0.1596, 0.2999, 0.716, 0.454, 0.659),
        "middle_trunk": DeLevaRow("XYPH-OMPH", 215.5, 0.1633, 0.4502, 0.482, 0.383, 0.468),
        "lower_trunk": DeLevaRow("OMPH-MIDH", 145.7, 0.1117, 0.6115, 0.615, 0.551, 0.587),
        "upper_arm": DeLevaRow("SJC-EJC", 281.7, 0.0271, 0.5772, 0.285, 0.269, 0.158),
        "forearm": DeLevaRow("EJC-WJC", 268.9, 0.0162, 0.4574, 0.276, 0.265, 0.121),
        "hand": DeLevaRow("WJC-DAC3", 187.9, 0.0061, 0.3624, 0.288, 0.235, 0.184),
        "thigh": DeLevaRow("HJC-KJC", 422.2, 0.1416, 0.4095, 0.329, 0.329, 0.149),
        "shank": DeLevaRow("KJC-AJC", 440.3, 0.0433, 0.4395, 0.251, 0.246, 0.102),
        "foot": DeLevaRow("HEEL-TTIP", 258.1, 0.0137, 0.4415, 0.257, 0.245, 0.124),
    },
    Sex.FEMALE: {
        "head": DeLevaRow("VERT-CERV", 243.7, 0.0668, 0.4841, 0.271, 0.295, 0.261),
        "upper_trunk": DeLevaRow("SUPR-XYPH", 142.5, 0.1545, 0.2077, 0.746, 0.502, 0.718),
        "middle_trunk": DeLevaRow("XYPH-OMPH", 205.3, 0.1465, 0.4512, 0.433, 0.354, 0.415),
        "lower_trunk": DeLevaRow("OMPH-MIDH", 181.5, 0.1247, 0.4920, 0.433, 0.402, 0.444),
        "upper_arm": DeLevaRow("SJC-EJC", 275.1, 0.0255, 0.5754, 0.278, 0.260, 0.148),
        "forearm": DeLevaRow("EJC-WJC", 264.3, 0.0138, 0.4559, 0.261, 0.257, 0.094),
        "hand": DeLevaRow("WJC-DAC3", 170.1, 0.0056, 0.3427, 0.244, 0.208, 0.154),
        "thigh": DeLevaRow("HJC-KJC", 368.5, 0.1478, 0.3612, 0.369, 0.364, 0.162),
        "shank": DeLevaRow("KJC-AJC", 438.6, 0.0481, 0.4352, 0.267, 0.263, 0.092),
        "foot": DeLevaRow("HEEL-TTIP", 228.3, 0.0129, 0.4014, 0.299, 0.279, 0.139),
    },
}
# de Leva's sample means (height m, mass kg): the default body mass keeps their body-mass index.
DE_LEVA_SUBJECT: dict[Sex, tuple[float, float]] = {
    Sex.MALE: (1.741, 73.0),
    Sex.FEMALE: (1.735, 61.9),
}

# Our segments: name -> the node it moves with. The order follows `NODE_NAMES` (parents first).
SEGMENT_NODES: dict[str, str] = {
    "pelvis": "pelvis", "thorax": "spine", "head": "neck",
    "l_upper_arm": "l_shoulder", "l_forearm": "l_elbow",
    "r_upper_arm": "r_shoulder", "r_forearm": "r_elbow",
    "l_thigh": "l_hip", "l_shank": "l_knee", "r_thigh": "r_hip", "r_shank": "r_knee",
    "l_hand": "l_wrist", "r_hand": "r_wrist", "l_foot": "l_ankle", "r_foot": "r_ankle",
}  # fmt: skip


def default_body_mass(height_m: float, sex: Sex = Sex.MALE) -> float:
    """Body mass (kg) of a subject of this height with de Leva's sample body-mass index."""
    h, m = DE_LEVA_SUBJECT[sex]
    return m / h**2 * height_m**2


@dataclass(frozen=True)
class BodySegments:
    """Inertial parameters of every segment of one subject, in the frames of its node.

    names: (S,) segment names; node: (S,) index into `NODE_NAMES` of the node each segment moves
    with (its proximal joint is that node's origin); parent: (S,) index of the parent segment
    (-1 for the pelvis); mass_kg: (S,); com_in_node: (S, 3) metres; inertia_in_node: (S, 3, 3)
    kg m^2 about the segment's centre of mass, in the node frame.
    """

    names: tuple[str, ...]
    node: np.ndarray
    parent: np.ndarray
    mass_kg: np.ndarray
    com_in_node: np.ndarray
    inertia_in_node: np.ndarray
    sex: Sex

    @property
    def total_mass_kg(self) -> float:
        return float(self.mass_kg.sum())

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The proximal joint of each segment, named after its node (pelvis: the root)."""
        return tuple(NODE_NAMES[i] for i in self.node)


def _principal_inertia(mass: float, length: float, row: DeLevaRow, long_axis: int) -> np.ndarray:
    """Diagonal inertia (3, 3) in our axes (X medio-lateral, Y up, Z forward) of one row."""
    r = np.empty(3)
    if long_axis == 1:  # vertical segments
        r[:] = (row.r_trans, row.r_long, row.r_sag)
    else:  # the foot: long axis Z, its "sagittal" axis is the vertical one
        r[:] = (row.r_trans, row.r_sag, row.r_long)
    return np.diag(mass * (r * length) ** 2)


def _lumped(parts: list[tuple[float, np.ndarray, np.ndarray]]) -> tuple[float, np.ndarray,
                                                                         np.ndarray]:
    """Combine (mass, com (3,), inertia about com (3, 3)) parts into one rigid body."""
    mass = sum(m for m, _, _ in parts)
    com = sum(m * c for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, i in parts:
        d = c - com
        inertia += i + m * (d @ d * np.eye(3) - np.outer(d, d))  # parallel-axis theorem
    return mass, com, inertia


def body_segments(shape: BodyShape, body_mass_kg: float, sex: Sex = Sex.MALE) -> BodySegments:
    """The 15 segments of `SEGMENT_NODES` scaled to `shape` and `body_mass_kg`."""
    if not (np.isfinite(body_mass_kg) and body_mass_kg > 0):
        raise ValueError(f"body mass must be positive, got {body_mass_kg}")
    table = DE_LEVA_1996[Sex(sex)]
    s = shape
    up = np.array([0.0, 1.0, 0.0])

    def along(row: DeLevaRow, start: np.ndarray, end: np.ndarray, long_axis: int = 1):
        length = float(np.linalg.norm(end - start))
        mass = row.mass * body_mass_kg
        com = start + row.com * (end - start)
        return mass, com, _principal_inertia(mass, length, row, long_axis)

    limb = {
        "upper_arm": (table["upper_arm"], s.upper_arm),
        "forearm": (table["forearm"], s.forearm),
        "hand": (table["hand"], s.hand),
        "thigh": (table["thigh"], s.thigh),
        "shank": (table["shank"], s.shank),
    }
    params: dict[str, tuple[float, np.ndarray, np.ndarray]] = {}
    # Pelvis: OMPH (the spine joint, above) to MIDH (the pelvis joint, the origin).
    params["pelvis"] = along(table["lower_trunk"], s.pelvis_to_spine * up, np.zeros(3))
    # Thorax: SUPR (neck joint) to OMPH (spine joint, the origin), split at the xiphoid.
    upper, middle = table["upper_trunk"], table["middle_trunk"]
    xyph = s.spine_to_neck * middle.length_mm / (upper.length_mm + middle.length_mm)
    params["thorax"] = _lumped([
        along(upper, s.spine_to_neck * up, xyph * up),
        along(middle, xyph * up, np.zeros(3)),
    ])  # fmt: skip
    # Head and neck: vertex (head top) down to C7 (the neck joint, the origin).
    params["head"] = along(table["head"], s.neck_to_head_top * up, np.zeros(3))
    for side in ("l", "r"):
        for name, (row, length) in limb.items():
            params[f"{side}_{name}"] = along(row, np.zeros(3), -length * up)
        heel = np.array([0.0, -s.ankle_height, -0.2 * s.foot_length])
        toe = np.array([0.0, -s.ankle_height, 0.8 * s.foot_length])
        mass, com, inertia = along(table["foot"], heel, toe, long_axis=2)
        params[f"{side}_foot"] = (mass, com + np.array([0.0, 0.5 * s.ankle_height, 0.0]),
                                  inertia)

    names = tuple(sorted(SEGMENT_NODES, key=lambda n: NODE_INDEX[SEGMENT_NODES[n]]))
    node = np.array([NODE_INDEX[SEGMENT_NODES[n]] for n in names])
    segment_of_node = {int(k): i for i, k in enumerate(node)}
    parent = np.array([segment_of_node.get(NODE_PARENTS[k], -1) for k in node])
    return BodySegments(
        names=names,
        node=node,
        parent=parent,
        mass_kg=np.array([params[n][0] for n in names]),
        com_in_node=np.array([params[n][1] for n in names]),
        inertia_in_node=np.array([params[n][2] for n in names]),
        sex=Sex(sex),
    )
