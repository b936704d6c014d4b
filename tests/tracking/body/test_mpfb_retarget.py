"""A pose of the thesis' layout on the MPFB body (`tracking.body.mpfb.retarget`, the ``mpfb``
body plugin): its limbs point where our model's do, it stands on the same floor, and its shape
is its own."""

from __future__ import annotations

import numpy as np
import pytest

from plugins.registry import PluginError, create
from tracking.body.model import (
    LOWER_LIMITS,
    NODE_INDEX,
    UPPER_LIMITS,
    BodyShape,
    Pose,
    forward_kinematics,
)

SKELETON = BodyShape.default(1.75)
LIMBS = (("l_shoulder", "l_elbow"), ("l_elbow", "l_wrist"), ("r_shoulder", "r_elbow"),
         ("r_elbow", "r_wrist"), ("l_hip", "l_knee"), ("l_knee", "l_ankle"),
         ("r_hip", "r_knee"), ("r_knee", "r_ankle"))  # fmt: skip


@pytest.fixture(scope="module")
def body():
    return create("body", "mpfb", ["gender=0.2", "weight=0.7"])


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = float(a @ b / np.linalg.norm(a) / np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def test_limbs_point_where_the_thesis_model_points(body):
    """For random poses over the joint ranges, each limb segment of the MPFB body (between our
    joints taken from its rig) is parallel to our model's; the trunk keeps MPFB's own curve."""
    rng = np.random.default_rng(7)
    worst_limb, worst_trunk = 0.0, 0.0
    for _ in range(20):
        x = rng.uniform(np.maximum(LOWER_LIMITS, -2.5), np.minimum(UPPER_LIMITS, 2.5))
        x[:3] = rng.uniform(-1, 1, 3)
        pose = Pose(x)
        ours = forward_kinematics(pose, SKELETON)[:, :3, 3]
        theirs = body.posed(pose, SKELETON).joints
        for a, b in LIMBS:
            i, j = NODE_INDEX[a], NODE_INDEX[b]
            worst_limb = max(worst_limb, _angle_deg(ours[j] - ours[i], theirs[j] - theirs[i]))
        i, j = NODE_INDEX["pelvis"], NODE_INDEX["neck"]
        worst_trunk = max(worst_trunk, _angle_deg(ours[j] - ours[i], theirs[j] - theirs[i]))
    assert worst_limb < 1.0, worst_limb
    assert worst_trunk < 10.0, worst_trunk


def test_at_rest_the_arms_hang_and_the_feet_are_on_the_skeletons_floor(body):
    posed = body.posed(Pose.neutral(), SKELETON)
    j = posed.joints
    for side in "lr":
        shoulder, wrist = j[NODE_INDEX[f"{side}_shoulder"]], j[NODE_INDEX[f"{side}_wrist"]]
        assert wrist[1] < shoulder[1] - 0.4
        assert np.hypot(*(wrist - shoulder)[[0, 2]]) < 0.02  # straight down
    # Our pelvis is at the origin at rest, the floor hip_height below it.
    assert posed.vertices[:, 1].min() == pytest.approx(-SKELETON.hip_height, abs=0.005)
    # The subject is its own: not the skeleton's stature.
    stature = posed.vertices[:, 1].max() - posed.vertices[:, 1].min()
    assert abs(stature - SKELETON.height) > 0.03


def test_the_decimated_mesh_is_the_full_one_subset(body):
    small = create("body", "mpfb", ["gender=0.2", "weight=0.7", "mesh=decimated"])
    pose = Pose.from_dict({"root_ry": 0.8, "l_elbow_flex": 1.0, "r_hip_rx": -0.6})
    full, part = body.posed(pose, SKELETON), small.posed(pose, SKELETON)
    assert len(part.vertices) < len(full.vertices) / 3
    assert np.allclose(part.vertices, full.vertices[small.assets.decimated_vertex_indices])
    assert np.allclose(part.joints, full.joints)
    assert part.faces.max() < len(part.vertices)


@pytest.mark.parametrize(("option", "message"), [
    ("weight=1.5", "weight must be in 0..1"),
    ("age_years=200", "age_years must be in 1..90"),
    ("mesh=coarse", "mesh must be 'full' or 'decimated'"),
])  # fmt: skip
def test_a_shape_out_of_range_is_refused_in_one_line(option, message):
    with pytest.raises(PluginError, match=message) as caught:
        create("body", "mpfb", [option])
    assert "\n" not in str(caught.value)


def test_loose_clothing_thickens_the_trunk_and_legs_but_not_the_arms(body):
    dressed = create("body", "mpfb", ["gender=0.2", "weight=0.7", "clothes_cm=3"])
    pose = Pose.neutral()
    bare, worn = body.posed(pose, SKELETON), dressed.posed(pose, SKELETON)
    moved = np.linalg.norm(worn.vertices - bare.vertices, axis=1)
    thigh = body.assets.skin_weight_matrix[:, body.assets.bone("LeftUpLeg")] > 0.9
    forearm = body.assets.skin_weight_matrix[:, body.assets.bone("LeftForeArm")] > 0.9
    assert np.median(moved[thigh]) == pytest.approx(0.03, abs=0.003)
    assert forearm.sum() > 50 and moved[forearm].max() < 1e-9
    # Outwards: the thigh's girth grows (its vertices move away from the thigh's axis).
    j = bare.joints
    axis = j[NODE_INDEX["l_knee"]] - j[NODE_INDEX["l_hip"]]
    axis /= np.linalg.norm(axis)

    def radius(v):
        d = v[thigh] - j[NODE_INDEX["l_hip"]]
        return np.linalg.norm(d - np.outer(d @ axis, axis), axis=1).mean()

    assert radius(worn.vertices) > radius(bare.vertices) + 0.02


def test_the_shipped_assets_are_a_skinned_cc0_body(body, tmp_path):
    from recon.errors import UserError
    from tracking.body.mpfb.model import MacroShape, load_assets, rest_vertices

    assets = body.assets
    assert np.allclose(assets.skin_weights.sum(axis=1), 1.0)
    assert "CC0" in str(assets.provenance)
    neutral = rest_vertices(assets)
    assert 1.55 < np.ptp(neutral[:, 1]) < 1.95
    taller = rest_vertices(assets, MacroShape(height=0.9))
    assert np.ptp(taller[:, 1]) > np.ptp(neutral[:, 1]) + 0.05
    missing = tmp_path / "none.npz"
    with pytest.raises(UserError, match="tracking.body.mpfb.convert") as caught:
        load_assets(missing)
    assert "\n" not in str(caught.value)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"not a zip")
    with pytest.raises(UserError, match="tracking.body.mpfb.convert"):
        load_assets(broken)
