"""Fitting MakeHuman's skinned body (``--body mpfb``) to point clouds of another mpfb subject."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from tests.helpers import run_cli
from tracking.body.model import NODE_NAMES, Pose, pose_in_frame
from tracking.body.motion import read_pose_file
from tracking.body.mpfb.model import MacroShape
from tracking.body.mpfb.subject import MpfbModel
from tracking.body.synthetic import body_cloud, walking_poses
from tracking.fit.body_fit import FitConfig, fit_body
from tracking.fit.step import fit_summary
from tracking.track.step import _model_of_pose_file

# benchmarks/body_fit.py's mismatched subject: not the fit's start (MakeHuman's average).
MISMATCHED = MpfbModel(MacroShape(gender=0.2, weight=0.7, height=0.4, age_years=40.0),
                       clothes_cm=2.0, mesh="full")  # fmt: skip


@pytest.fixture(scope="module")
def walking_fit():
    """A mid-stride walking pose (legs apart, arms swinging, elbows bent) at a heading of
    130 degrees, its cloud (5 mm noise, 30% hidden) and the mpfb fit of it."""
    rng = np.random.default_rng(3)
    pose = walking_poses(12, 30.0, MISMATCHED.shape, phase_deg=90.0)[8]
    c, s = np.cos(np.deg2rad(130.0)), np.sin(np.deg2rad(130.0))
    pose = pose_in_frame(pose, np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]))
    points, _ = body_cloud(MISMATCHED, pose, rng)
    return pose, points, fit_body(points, FitConfig(body="mpfb"))


def test_mpfb_fit_recovers_the_joints_of_another_mpfb_subject(walking_fit):
    pose, _, result = walking_fit
    truth = MISMATCHED.joints(pose)
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    errors = np.linalg.norm(fitted - truth, axis=1)
    assert result.success, result.message
    assert result.model.name == "mpfb"
    # Measured: mean 2.9 mm, max 5.1 mm.
    assert errors.mean() < 0.010
    assert errors.max() < 0.020
    assert result.shape.height == pytest.approx(MISMATCHED.shape.height, abs=0.02)
    # The clothing is found: the trunk is 2 cm out, not MakeHuman's bare average.
    assert result.model.record()["clothes_cm"] == pytest.approx(2.0, abs=1.0)
    assert result.residual_median < 0.005  # 5 mm noise: |N(0, 5 mm)| has median 3.4 mm


def test_the_fit_file_starts_mpfb_tracking_with_the_fitted_subject(walking_fit, tmp_path):
    pose, _, result = walking_fit
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit_summary(result)))
    given = read_pose_file(path)
    model = _model_of_pose_file(path, given, "mpfb")  # what `mocap track --init-pose` builds
    assert given.body == result.model.record()
    start = Pose(given.frames[0][1])
    # The tracker's (decimated) subject puts the joints where the fit did.
    fitted = np.array([result.joints[n] for n in NODE_NAMES])
    assert np.abs(model.joints(start) - fitted).max() < 1e-6
    assert np.allclose(json.loads(path.read_text())["joints"]["pelvis"], fitted[0])


def test_cli_mpfb_fit_of_a_box_fails_and_still_writes_the_body(tmp_path):
    rng = np.random.default_rng(0)
    # A 0.5 x 1.7 x 0.3 m box's surface: body-sized, but no body.
    box = rng.uniform(-1.0, 1.0, size=(4000, 3))
    side = rng.integers(0, 3, size=len(box))
    box[np.arange(len(box)), side] = np.sign(box[np.arange(len(box)), side])
    box *= np.array([0.25, 0.85, 0.15])
    cloud = tmp_path / "box.ply"
    o3d.io.write_point_cloud(str(cloud), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(box)))
    out = tmp_path / "fit"
    done = run_cli("fit", "--cloud", cloud, "--out", out, "--body", "mpfb", "--no-isolate",
                   "--max-orientations", "4")  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "does not look like one human body" in done.stderr
    data = json.loads((out / "fit.json").read_text())
    assert data["success"] is False
    assert data["body"]["name"] == "mpfb" and set(data["body"]) >= {"macro", "clothes_cm"}
    mesh = o3d.io.read_triangle_mesh(str(out / "fit.ply"))
    assert len(mesh.vertices) == len(MISMATCHED.node_weights)  # the full mesh, 13,380
