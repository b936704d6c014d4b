"""Tests of tracking.report.opensim: Pose2Sim's marker names, the nominal rate, the TRC and MOT
layouts (the report's own files are tested in test_report.py, with OpenSim's readers when the
opensim package is there)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracking.body.model import NODE_NAMES
from tracking.report.opensim import (
    POSE2SIM_MARKER_OF_NODE,
    POSE2SIM_MARKERS_WITHOUT_NODE,
    MarkerSet,
    format_rate,
    nominal_rate_hz,
    trc_markers,
    write_mot,
    write_trc,
)

HALPE_26_MODEL_MARKERS = (
    "Nose", "Head", "Neck", "LShoulder", "RShoulder", "LElbow", "RElbow", "LWrist", "RWrist",
    "Hip", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LBigToe", "LSmallToe",
    "LHeel", "RBigToe", "RSmallToe", "RHeel",
)  # fmt: skip
"""The markers of Pose2Sim's OpenSim model for its default pose model (Pose2Sim/OpenSim_Setup/
Markers_Halpe26.xml, on Model_Pose2Sim.osim), in that file's order."""
COCO_17_MODEL_MARKERS = (
    "Nose", "Neck", "LShoulder", "RShoulder", "LElbow", "RElbow", "LWrist", "RWrist", "LHip",
    "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle",
)  # fmt: skip
"""Markers_Coco17.xml's: the same names for the same joints, without Hip and Head."""


def test_pose2sim_names_are_those_of_its_models() -> None:
    names = [name for _, name in trc_markers(MarkerSet.POSE2SIM)]
    assert len(names) == len(set(names)) == 15
    assert set(names) <= set(HALPE_26_MODEL_MARKERS)
    assert set(HALPE_26_MODEL_MARKERS) - set(names) == set(POSE2SIM_MARKERS_WITHOUT_NODE)
    assert set(COCO_17_MODEL_MARKERS) - {"Nose"} <= set(names)
    assert set(POSE2SIM_MARKER_OF_NODE) == set(NODE_NAMES)
    assert [n for n, m in POSE2SIM_MARKER_OF_NODE.items() if m is None] == ["spine"]
    assert POSE2SIM_MARKER_OF_NODE["pelvis"] == "Hip"
    assert POSE2SIM_MARKER_OF_NODE["head_top"] == "Head"
    assert [name for _, name in trc_markers(MarkerSet.OURS)] == list(NODE_NAMES)


@pytest.mark.parametrize(("rate_hz", "expected"), [
    (1 / 0.008333, 120.0),  # CMU's 02_01 walk: 120.0048 Hz
    (1 / 0.0083333, 120.0),  # most CMU clips
    (1 / 0.00833333, 120.0),
    (1 / 0.004167, 240.0),  # 239.98: a 240 Hz clip with 6 decimals
    (30.0012, 30.0),  # `mocap synth`: CMU's 120.0048 Hz subsampled by 4
    (29.97, 30000 / 1001),  # NTSC video, 1e-3 from 30 Hz: never taken for 30
    (30000 / 1001, 30000 / 1001),
    (59.94, 60000 / 1001),
    (23.976, 24000 / 1001),  # not 23.98, as rounding to 2 decimals would have it
    (1 / 0.0333, 1 / 0.0333),  # 30.03: 1e-3 from 30 Hz, nothing says it is 30: kept
    (100.5, 100.5),
    (37.123456, 37.123456),
])  # fmt: skip
def test_nominal_rate_is_an_integer_or_ntsc_rate_within_the_frame_times_rounding(
    rate_hz: float, expected: float
) -> None:  # fmt: skip
    assert nominal_rate_hz(rate_hz) == pytest.approx(expected, rel=1e-12)


def test_rates_are_written_as_users_write_them() -> None:
    rates = (120.0, 30000 / 1001, 60000 / 1001, 24000 / 1001, 100.5, 37.123456)
    assert [format_rate(r) for r in rates] == [
        "120", "29.97", "59.94", "23.976", "100.5", "37.1235"]


def test_trc_times_follow_the_nominal_rate(tmp_path: Path) -> None:
    frames = np.arange(10, 13)  # a sequence that starts at frame 10
    points = np.random.default_rng(0).normal(size=(3, len(NODE_NAMES), 3))
    points[1] = np.nan
    path = tmp_path / "m.trc"
    write_trc(path, frames, 1 / 0.008333, points, MarkerSet.OURS)
    lines = path.read_text().splitlines()
    assert lines[2].split("\t") == ["120", "120", "3", "16", "m", "120", "11", "3"]
    rows = [line.split("\t") for line in lines[6:]]
    assert [r[:2] for r in rows] == [["1", f"{10 / 120:.6f}"], ["2", f"{11 / 120:.6f}"],
                                     ["3", f"{12 / 120:.6f}"]]  # fmt: skip
    assert all(len(r) == 2 + 3 * len(NODE_NAMES) for r in rows)  # missing: NaN, not empty
    assert rows[1][2:] == ["NaN"] * 48
    np.testing.assert_allclose(np.array(rows[2][2:], float), points[2].ravel(), atol=5e-7)


def test_mot_header_and_rows(tmp_path: Path) -> None:
    values = np.array([[10.0, -5.0], [np.nan, 1.0], [12.5, -0.00001]])
    path = tmp_path / "angles.mot"
    write_mot(path, np.arange(3), 30.0, ["l_knee_flexion", "neck_flexion"], values)
    assert path.read_text().splitlines() == [
        "angles", "version=1", "nRows=2", "nColumns=3", "inDegrees=yes", "endheader",
        "time\tl_knee_flexion\tneck_flexion",
        "0.000000\t10.0000\t-5.0000",
        "0.066667\t12.5000\t0.0000",  # no "-0.0000"
    ]
    with pytest.raises(ValueError, match="shape"):
        write_mot(path, np.arange(2), 30.0, ["a"], values)
