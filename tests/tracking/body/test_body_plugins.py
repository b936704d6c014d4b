"""The ``mocap.body`` plugins: registered through entry points, satisfying their Protocol, and
the superquadric one giving exactly the thesis model's surface and joints."""

from __future__ import annotations

import numpy as np
import pytest

from plugins.registry import PluginError, available, create
from tracking.body.model import BodyModel, BodyShape, Pose, forward_kinematics


def test_the_thesis_model_is_a_body_plugin_and_poses_as_the_model_does():
    assert "superquadric" in available("body")
    body = create("body", "superquadric")
    shape = BodyShape.default(1.70)
    pose = Pose.from_dict({"root_tx": 0.4, "root_ty": 0.9, "root_ry": 0.7,
                           "l_elbow_flex": 1.2, "r_hip_rx": -0.5})  # fmt: skip
    posed = body.posed(pose, shape)
    model = BodyModel(shape)
    assert np.array_equal(posed.vertices, model.posed_vertices(pose))
    assert np.array_equal(posed.faces, model.faces)
    assert np.array_equal(posed.joints, forward_kinematics(pose, shape)[:, :3, 3])
    # Another skeleton gives another body (the plugin keeps one model, not a stale one).
    taller = BodyShape.default(1.90)
    assert np.ptp(body.posed(pose, taller).vertices[:, 1]) > np.ptp(posed.vertices[:, 1]) + 0.1


def test_a_body_option_the_model_does_not_have_is_refused():
    with pytest.raises(PluginError, match="superquadric"):
        create("body", "superquadric", ["gender=1"])
