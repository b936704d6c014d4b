"""The report's files for OpenSim and Pose2Sim: markers (``motion.trc``) and joint angles
(``motion.mot``).

Marker names (`MarkerSet`). Pose2Sim's OpenSim models (``Model_Pose2Sim.osim`` with the marker
files ``Markers_Halpe26.xml``, ``Markers_Body25b.xml``, ``Markers_Coco17.xml``, ...) place one
marker per keypoint of the 2D pose estimator, at the joint centre the estimator finds, and its
scaling and inverse kinematics use the markers whose names the TRC shares with the model (the
others are ignored). Its default pose model, HALPE_26, names them ``Hip`` (midpoint of the hip
joints), ``LHip``/``RHip``, ``LKnee``/``RKnee``, ``LAnkle``/``RAnkle``, ``Neck``, ``Head`` (top
of the head), ``LShoulder``/``RShoulder``, ``LElbow``/``RElbow``, ``LWrist``/``RWrist``, plus
``Nose``, ``LBigToe``, ``LSmallToe``, ``LHeel`` and the right ones (names checked against
pose2sim 0.10.49). The other sets use the same names for the same joints (BODY_25B lacks
``Hip``, COCO_17 ``Hip`` and ``Head``), so `POSE2SIM_MARKER_OF_NODE` fits all of them. Our
joints map one to one (`tracking.body.model.NODE_NAMES`); our ``spine`` (the waist joint) has
no Pose2Sim counterpart and is left out of a Pose2Sim TRC; Pose2Sim's nose, toe and heel
markers have none of ours (the body model ends at the ankles and the top of the head) and are
absent, so the feet's orientation is not constrained by the file.

Rates. A BVH stores its frame time rounded (CMU: ``0.008333`` s, whose inverse is 120.0048
Hz), and that rate reaches the report. The files carry the nominal rate (`nominal_rate_hz`:
120 Hz), and their times are frame / nominal rate, so that rate and time column agree; the CSVs
and the recording keep the input's own times (those of the tracking recording's timeline,
4e-5 apart in relative terms for CMU's clips: 0.4 ms after 10 s).

Pure formatting and file writing; no OpenSim needed (the tests read the files with OpenSim's
own adapters when the ``opensim`` package is there).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tracking.body.model import NODE_NAMES


class MarkerSet(enum.StrEnum):
    """Names of the markers in ``motion.trc``."""

    POSE2SIM = "pose2sim"  # Pose2Sim's names (HALPE_26 and the others); joints without: left out
    OURS = "ours"  # the body model's node names, all 16


POSE2SIM_MARKER_OF_NODE: dict[str, str | None] = {
    "pelvis": "Hip",  # our pelvis joint is the midpoint of the hip joints, as Pose2Sim's Hip
    "spine": None,  # the waist joint: no marker in any Pose2Sim model
    "neck": "Neck",
    "l_shoulder": "LShoulder",
    "l_elbow": "LElbow",
    "r_shoulder": "RShoulder",
    "r_elbow": "RElbow",
    "l_hip": "LHip",
    "l_knee": "LKnee",
    "r_hip": "RHip",
    "r_knee": "RKnee",
    "head_top": "Head",  # HALPE_26's Head keypoint is the top of the head
    "l_wrist": "LWrist",
    "r_wrist": "RWrist",
    "l_ankle": "LAnkle",
    "r_ankle": "RAnkle",
}
"""Pose2Sim marker name of each of our nodes (`NODE_NAMES`), None where there is none."""

POSE2SIM_MARKERS_WITHOUT_NODE: tuple[str, ...] = (
    "Nose", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel")  # fmt: skip
"""Markers of Pose2Sim's HALPE_26 model that no joint of ours gives."""


def trc_markers(marker_set: MarkerSet) -> list[tuple[int, str]]:
    """(node index, marker name) of the markers written, in `NODE_NAMES` order."""
    if MarkerSet(marker_set) is MarkerSet.OURS:
        return list(enumerate(NODE_NAMES))
    return [(i, POSE2SIM_MARKER_OF_NODE[name]) for i, name in enumerate(NODE_NAMES)
            if POSE2SIM_MARKER_OF_NODE[name] is not None]  # fmt: skip


NOMINAL_RATE_TOLERANCE = 2e-4
"""Largest relative difference between a frame rate and the nominal rate written for it. A frame
time written with 6 decimals (CMU's 0.008333 s) is off by up to 5e-7 s: 6e-5 of 120 Hz, 1.2e-4
of 240 Hz. The closest pairs of real rates (29.97 and 30 Hz, 23.976 and 24 Hz) differ by 1e-3,
so no rate is taken for its neighbour."""
_NTSC = 1.001
"""NTSC's rates are n * 1000 / 1001 Hz (29.97, 59.94, 23.976 Hz)."""


def nominal_rate_hz(rate_hz: float, rel_tol: float = NOMINAL_RATE_TOLERANCE) -> float:
    """The rate the capture ran at: the integer rate, or NTSC's n * 1000 / 1001 Hz, within
    ``rel_tol`` of ``rate_hz``; else ``rate_hz`` as it is (nothing says what it should be).

    120.0048 -> 120 (CMU's 0.008333 s), 30.0012 -> 30, 29.97 -> 30000/1001, 100.5 -> 100.5.
    Capture systems and cameras run at integer rates or at NTSC's; rounding to decimals instead
    would turn 23.976 into 23.98.
    """
    for candidate in (round(rate_hz), round(rate_hz * _NTSC) / _NTSC):
        if candidate > 0 and abs(candidate - rate_hz) <= rel_tol * rate_hz:
            return float(candidate)
    return float(rate_hz)


def format_rate(rate_hz: float) -> str:
    """A rate as users write it: ``120``, ``29.97`` and ``23.976`` for NTSC's, else up to 6
    significant digits (``100.5``)."""
    rate_hz = float(rate_hz)
    if rate_hz.is_integer():
        return str(int(rate_hz))
    if math.isclose(rate_hz, round(rate_hz * _NTSC) / _NTSC, rel_tol=1e-12):
        return f"{round(rate_hz, 3):g}"
    return f"{rate_hz:.6g}"


def write_trc(path: Path, frames: np.ndarray, rate_hz: float, points_in_world: np.ndarray,
              marker_set: MarkerSet = MarkerSet.POSE2SIM) -> None:  # fmt: skip
    """Joint centres as TRC markers (OpenSim's and Pose2Sim's format, version 4).

    frames: (T,) frame numbers; points_in_world: (T, 16, 3) `NODE_NAMES` positions in metres
    in the input's world axes (Y up, as OpenSim expects), NaN where the frame has no data: its
    marker fields are written ``NaN``, which OpenSim and pandas read as missing (empty fields, the
    other convention, lose the row's last field in OpenSim's reader, which then refuses the
    file). Tab-separated; ``Frame#`` counts from 1, ``Time`` is frame / `nominal_rate_hz`
    (``rate_hz``).
    """
    markers = trc_markers(marker_set)
    names = [name for _, name in markers]
    nodes = [node for node, _ in markers]
    rate = nominal_rate_hz(rate_hz)
    shown = format_rate(rate)
    n = len(frames)
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{shown}\t{shown}\t{n}\t{len(names)}\tm\t{shown}\t{int(frames[0]) + 1}\t{n}",
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, len(names) + 1)),
        "",
    ]
    points = np.asarray(points_in_world, dtype=float)[:, nodes]
    for t in range(n):
        if np.isfinite(points[t]).all():
            values = "\t".join(f"{v:.6f}" for v in points[t].ravel())
        else:
            values = "\t".join(["NaN"] * (3 * len(names)))
        lines.append(f"{t + 1}\t{frames[t] / rate:.6f}\t{values}")
    path.write_text("\n".join(lines) + "\n")


def write_mot(path: Path, frames: np.ndarray, rate_hz: float, columns: Sequence[str],
              values_deg: np.ndarray) -> None:  # fmt: skip
    """Joint angles as an OpenSim motion file (``.mot``, Storage version 1, in degrees).

    columns: C names; values_deg: (T, C). Rows are the frames with every value finite (as in
    the CSVs, a frame without data has no row); times are frame / `nominal_rate_hz`. The
    header is OpenSim's: the file's name, ``version=1``, ``nRows``, ``nColumns`` (time
    included), ``inDegrees=yes``, ``endheader``, then the column labels.
    """
    values = np.asarray(values_deg, dtype=float)
    if values.shape != (len(frames), len(columns)):
        raise ValueError(f"values need shape ({len(frames)}, {len(columns)}), got {values.shape}")
    rate = nominal_rate_hz(rate_hz)
    rows = [f"{frames[t] / rate:.6f}\t" + "\t".join(f"{round(v, 4) + 0.0:.4f}" for v in values[t])
            for t in range(len(frames)) if np.isfinite(values[t]).all()]
    header = [path.stem, "version=1", f"nRows={len(rows)}", f"nColumns={len(columns) + 1}",
              "inDegrees=yes", "endheader", "\t".join(["time", *columns])]
    path.write_text("\n".join(header + rows) + "\n")

