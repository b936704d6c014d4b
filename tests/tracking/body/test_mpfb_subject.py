"""The mpfb body as the tracker's model (tracking.body.mpfb.subject): its skeleton against its
skinned joints, its weights and derivatives against finite differences, its shape pass against
a subject of another macro shape and clothing, and pose files of the other body model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from recon.errors import UserError
from tests.tracking.track.test_contour import CAMERAS, RENDER, STRIDE
from tracking.body.model import (
    NODE_INDEX,
    NODE_NAMES,
    PARAM_INDEX,
    PARAM_MOVES_NODE,
    BodyModel,
    BodyShape,
    Pose,
    forward_kinematics,
)
from tracking.body.mpfb.model import MacroShape
from tracking.body.mpfb.subject import MpfbModel
from tracking.body.synthetic import random_pose
from tracking.track.contour import ContourConfig, _Posed, refine_shape
from tracking.track.energy import SilhouetteEnergy

SUBJECT = MacroShape(gender=0.2, weight=0.7, height=0.4, age_years=40)


@pytest.fixture(scope="module")
def start() -> MpfbModel:
    return MpfbModel.of_height(1.75)


def test_the_skeleton_puts_the_limb_joints_where_the_skinned_body_has_them(start):
    pose = STRIDE
    fk = forward_kinematics(pose, start.shape)[:, :3, 3]
    skinned = start.joints(pose)
    for name in ("l_hip", "r_knee", "l_ankle", "r_shoulder", "l_elbow", "r_wrist"):
        # The rig's shoulders sit 1.5 cm in front of its hips: our layout has them in one plane.
        assert np.linalg.norm(fk[NODE_INDEX[name]] - skinned[NODE_INDEX[name]]) < 0.03, name
    assert abs(start.shape.height - 1.75) < 0.01
    assert abs(start.shape.chain_height - start.shape.height) < 1e-9
    # Standing: the lowest vertex at rest is on the floor below the pelvis by the hip height.
    rest = start.posed_vertices(Pose.neutral())
    assert abs(-rest[:, 1].min() - start.shape.hip_height) < 0.005


def test_weights_and_moving_faces(start):
    weights = start.node_weights
    assert np.allclose(weights.sum(axis=1), 1.0)
    forearm = np.zeros(len(NODE_NAMES), bool)
    forearm[[NODE_INDEX["l_elbow"], NODE_INDEX["l_wrist"]]] = True
    moving = start.faces_moved_by(forearm)
    # Every face with a vertex carried by the forearm moves; the legs do not.
    carried = (weights[start.faces][:, :, NODE_INDEX["l_elbow"]] > 0.01).any(axis=1)
    assert moving[carried].all()
    legs = (weights[start.faces][:, :, [NODE_INDEX[n] for n in ("l_knee", "r_knee")]] > 0.5)
    assert not moving[legs.any(axis=(1, 2))].any()
    # Moving only those faces reproduces the whole render of a pose change of the elbow.
    x = STRIDE.params.copy()
    y = x.copy()
    y[PARAM_INDEX["l_elbow_flex"]] += 0.4
    cam = CAMERAS[0]
    static = RENDER.render(start.posed_vertices(Pose(x)), start.faces[~moving], cam)
    parts = static | RENDER.render(start.posed_vertices(Pose(y)), start.faces[moving], cam)
    whole = RENDER.render(start.posed_vertices(Pose(y)), start.faces, cam)
    assert np.count_nonzero(parts ^ whole) <= 2


def test_the_vertices_of_a_stage_are_posed_alone_with_the_same_floats(start):
    # A stage of the tracker poses the vertices of the faces it moves alone
    # (`MpfbModel.posed_vertices` with vertex_ids): the rows of the whole body, bit for bit.
    forearm = np.zeros(len(NODE_NAMES), bool)
    forearm[[NODE_INDEX["l_elbow"], NODE_INDEX["l_wrist"]]] = True
    ids = np.unique(start.faces[start.faces_moved_by(forearm)])
    assert 0 < len(ids) < len(start.posed_vertices(STRIDE)) // 4
    rng = np.random.default_rng(3)
    for pose in (STRIDE, *(random_pose(rng) for _ in range(5))):
        whole = start.posed_vertices(pose)
        assert np.array_equal(start.posed_vertices(pose, ids), whole[ids])
        assert np.array_equal(start.posed_vertices(pose, np.arange(len(whole))), whole)
    assert start.posed_vertices(STRIDE, np.zeros(0, int)).shape == (0, 3)


def test_outline_derivatives_match_finite_differences(start):
    x = STRIDE.params.copy()
    free = np.array([PARAM_INDEX[n] for n in ("root_tx", "root_ry", "l_shoulder_rx",
                                              "l_elbow_flex", "r_knee_flex", "spine_flex")])
    posed = _Posed(start, x, free)
    verts, normals = start.posed_surface(Pose(x))
    assert np.allclose(posed.verts, verts)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    idx = np.arange(len(verts))
    analytic = posed.derivatives(idx)
    for col, k in enumerate(free):
        h = 1e-4
        bumped = x.copy()
        bumped[k] += h
        numeric = (start.posed_vertices(Pose(bumped)) - verts) / h
        moved = PARAM_MOVES_NODE[k][np.argmax(start.node_weights, axis=1)]
        err = np.linalg.norm(analytic[:, :, col] - numeric, axis=1)
        scale = np.linalg.norm(numeric, axis=1)
        # Exact for the vertices one bone carries; the blend near joints stays close.
        assert np.median(err[moved] / np.maximum(scale[moved], 1e-9)) < 0.05, NODE_NAMES
        assert np.percentile(err, 95) < 0.25 * max(np.percentile(scale, 95), 1e-9)


def test_reshaping_keeps_the_subject_and_a_bad_record_is_refused(start):
    same = start.reshaped(start.shape_parameters().values)
    assert np.allclose(same.posed_vertices(STRIDE), start.posed_vertices(STRIDE))
    record = json.loads(json.dumps(start.record()))
    again = MpfbModel.from_record(record)
    assert np.allclose(again.posed_vertices(STRIDE), start.posed_vertices(STRIDE))
    with pytest.raises(ValueError, match="not an mpfb body"):
        MpfbModel.from_record({"name": "mpfb"})
    with pytest.raises(ValueError, match="weight must be in"):
        MpfbModel.from_record({"name": "mpfb", "macro": {"weight": 3}})


def test_the_shape_pass_recovers_another_subject_in_clothes(start):
    """A heavier, shorter, mostly female subject in 2 cm of clothes: from the average start of
    the visual hull's height and the true poses, the macro shape and clothing are refined on
    the outlines of two frames until the silhouettes agree within 5% (the truth is 40 years
    old; age is not refined) and the joints within a centimetre."""
    truth = MpfbModel(SUBJECT, clothes_cm=2.0)
    poses = [STRIDE.params.copy(), STRIDE.params.copy()]
    poses[1][PARAM_INDEX["root_ry"]] += 1.2
    poses[1][PARAM_INDEX["l_elbow_flex"]] = 1.2
    for x in poses:  # the truth's feet on the floor
        x[PARAM_INDEX["root_ty"]] = truth.shape.hip_height
    masks = [[RENDER.render(truth.posed_vertices(Pose(x)), truth.faces, c) for c in CAMERAS]
             for x in poses]
    area = sum(m.sum() for frame in masks for m in frame)
    guess = MpfbModel.of_height(truth.shape.height + 0.05)

    def energy(model, xs):
        return sum(SilhouetteEnergy(model, CAMERAS, m, RENDER, levels=1)(Pose(x))
                   for m, x in zip(masks, xs, strict=True))

    before = energy(guess, poses) / area
    model, xs, best = refine_shape(guess, [(CAMERAS, m, None) for m in masks], poses, RENDER,
                                   energy, ContourConfig(iterations=15))
    assert before > 0.1
    assert best / area < 0.05, (best / area, model.macro, model.clothes_cm)
    errors = [np.linalg.norm(model.joints(Pose(x)) - truth.joints(Pose(t)), axis=1).mean()
              for x, t in zip(xs, poses, strict=True)]
    assert max(errors) < 0.01, errors
    assert abs(model.shape.height - truth.shape.height) < 0.02


def _pose_file(path, body):
    path.write_text(json.dumps({
        "frame_rate": 30.0, "shape": BodyShape.default(1.7).__dict__, "body": body,
        "frames": [{"frame": 0, "params": [0.0] * 24}]}))
    return path


def test_an_init_pose_of_the_other_body_model_is_refused_in_one_line(tmp_path, start):
    from tracking.body.motion import read_pose_file
    from tracking.track.step import _model_of_pose_file

    superquadric = _pose_file(tmp_path / "sq.json", {"name": "superquadric"})
    with pytest.raises(UserError, match="for the body model 'superquadric', not 'mpfb'"):
        _model_of_pose_file(superquadric, read_pose_file(superquadric), "mpfb")
    mpfb = _pose_file(tmp_path / "mpfb.json", start.record())
    with pytest.raises(UserError, match="--body mpfb"):
        _model_of_pose_file(mpfb, read_pose_file(mpfb), "superquadric")
    model = _model_of_pose_file(mpfb, read_pose_file(mpfb), "mpfb")
    assert np.allclose(model.posed_vertices(STRIDE), start.posed_vertices(STRIDE))
    broken = _pose_file(tmp_path / "broken.json", {"name": "mpfb"})
    with pytest.raises(UserError, match="does not describe a subject of the mpfb model"):
        _model_of_pose_file(broken, read_pose_file(broken), "mpfb")


@pytest.mark.parametrize("body", ["superquadric", "mpfb"])
def test_the_subject_glb_plays_the_tracked_poses(tmp_path, body, start):
    """tracks/subject.glb (`write_subject_glb`), skinned by glTF's own rule, is the model's
    mesh in each pose: the decimated mesh the tracker fitted is a subset of the full one."""
    from tests.tracking.body.test_gltf import _gltf_skinned
    from tracking.body.gltf import read_glb
    from tracking.body.model import BodyModel
    from tracking.track.step import write_subject_glb

    model = BodyModel(BodyShape.default(1.7)) if body == "superquadric" else start
    poses = [STRIDE, Pose(STRIDE.params + 0.1)]
    write_subject_glb(tmp_path / "subject.glb", model, poses, 25.0)
    gltf, binary = read_glb(tmp_path / "subject.glb")
    assert gltf["nodes"][0]["name"] == ("pelvis" if body == "superquadric" else "Hips")
    for k, pose in enumerate(poses):
        played = _gltf_skinned(gltf, binary, k / 25.0)
        expected = model.posed_vertices(pose)
        if body == "mpfb":
            played = played[start.assets.decimated_vertex_indices]
        assert np.abs(played - expected).max() < 1e-4


def test_the_output_skin_poses_like_the_model(start):
    """`SkinnedMesh.posed` (the glTF's forward kinematics and skinning: what Blender shows and
    what mocap track --meshes writes) driven by a model's `skin_pose` is that model's own
    posing, at full resolution."""
    rng = np.random.default_rng(5)
    full = MpfbModel(start.macro, 2.0, "full")
    decimated = MpfbModel(start.macro, 2.0)
    superquadric = BodyModel(BodyShape.default(1.7))
    for _ in range(3):
        pose = random_pose(rng, 0.5)
        np.testing.assert_allclose(decimated.skin().posed(*decimated.skin_pose(pose)),
                                   full.posed_vertices(pose), atol=1e-9)
        np.testing.assert_allclose(superquadric.skin().posed(*superquadric.skin_pose(pose)),
                                   superquadric.posed_vertices(pose), atol=1e-9)
