"""`mocap body`: one BVH frame → posed body mesh (PLY) and joint positions (JSON)."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from tests.helpers import run_cli, shared_dataset
from tracking.body.bvh import CMU_METRES_PER_UNIT, forward_kinematics, read_bvh
from tracking.body.model import NODE_NAMES


@pytest.mark.shared_data
def test_body_of_a_cmu_frame(tmp_path):
    clip = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    result = run_cli("body", "--bvh", clip, "--frame", "30", "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    joints = {k: np.array(v) for k, v in json.loads((tmp_path / "joints.json").read_text()).items()}
    assert set(joints) == set(NODE_NAMES)
    # In the BVH's own world (metres, Y up): our knee sits on the clip's knee.
    motion = read_bvh(clip)
    positions = forward_kinematics(motion, scale=CMU_METRES_PER_UNIT)[30]
    knee = positions[motion.joint_index("LeftLeg")]
    assert np.linalg.norm(joints["l_knee"] - knee) < 0.05
    mesh = o3d.io.read_triangle_mesh(str(tmp_path / "body.ply"))
    assert len(mesh.triangles) > 5000
    vertices = np.asarray(mesh.vertices)
    assert 1.3 < np.ptp(vertices[:, 1]) < 1.9  # walking: a bit shorter than standing height


@pytest.mark.shared_data
def test_body_rejects_a_frame_out_of_range(tmp_path):
    clip = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    result = run_cli("body", "--bvh", clip, "--frame", "5000", "--out", tmp_path)
    assert result.returncode == 2 and "frames 0..342" in result.stderr
    assert not (tmp_path / "body.ply").exists()
