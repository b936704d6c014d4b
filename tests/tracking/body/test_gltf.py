"""The skinned GLB writer against an independent glTF reader and skinning (`tracking.body.gltf`)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from tracking.body.gltf import accessor_array, read_glb, write_skinned_glb

# ---------------------------------------------------------------------------------------------
# An independent glTF player: node TRS + LINEAR samplers, forward kinematics, glTF skinning
# ---------------------------------------------------------------------------------------------


def _quaternion_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])  # fmt: skip


def _local_matrix(node: dict, overrides: dict[str, np.ndarray]) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], float).reshape(4, 4).T
    t = overrides.get("translation", np.asarray(node.get("translation", [0, 0, 0]), float))
    r = overrides.get("rotation", np.asarray(node.get("rotation", [0, 0, 0, 1]), float))
    s = overrides.get("scale", np.asarray(node.get("scale", [1, 1, 1]), float))
    translate, rotate, scale = np.eye(4), np.eye(4), np.diag([*s, 1.0])
    translate[:3, 3] = t
    rotate[:3, :3] = _quaternion_matrix(r)
    return translate @ rotate @ scale


def _sample(gltf: dict, binary: bytes, sampler: dict, time: float) -> np.ndarray:
    times = accessor_array(gltf, binary, sampler["input"]).astype(float)
    values = accessor_array(gltf, binary, sampler["output"]).astype(float)
    assert sampler.get("interpolation", "LINEAR") == "LINEAR"
    if time <= times[0] or len(times) == 1:
        return values[0]
    if time >= times[-1]:
        return values[-1]
    k = int(np.searchsorted(times, time, side="right")) - 1
    u = (time - times[k]) / (times[k + 1] - times[k])
    return (1 - u) * values[k] + u * values[k + 1]  # (quaternions renormalised on use)


def _world_matrices(gltf: dict, binary: bytes, time: float) -> list[np.ndarray]:
    """Every node's world matrix at ``time`` (the scene's roots at the identity)."""
    overrides: dict[int, dict[str, np.ndarray]] = {}
    for channel in gltf["animations"][0]["channels"]:
        sampler = gltf["animations"][0]["samplers"][channel["sampler"]]
        target = channel["target"]
        overrides.setdefault(target["node"], {})[target["path"]] = _sample(
            gltf, binary, sampler, time)
    nodes = gltf["nodes"]
    world: list[np.ndarray | None] = [None] * len(nodes)

    def visit(index: int, parent: np.ndarray) -> None:
        assert world[index] is None, "a node is reached twice"
        world[index] = parent @ _local_matrix(nodes[index], overrides.get(index, {}))
        for child in nodes[index].get("children", []):
            visit(child, world[index])

    for root in gltf["scenes"][gltf.get("scene", 0)]["nodes"]:
        visit(root, np.eye(4))
    assert all(w is not None for w in world)
    return world  # type: ignore[return-value]


def _gltf_skinned(gltf: dict, binary: bytes, time: float) -> np.ndarray:
    """The mesh's vertices at ``time`` by glTF's skinning: sum_i w_i jointWorld_i IBM_i v."""
    (mesh_node,) = [n for n in gltf["nodes"] if "skin" in n]
    skin = gltf["skins"][mesh_node["skin"]]
    (primitive,) = gltf["meshes"][mesh_node["mesh"]]["primitives"]
    attributes = primitive["attributes"]
    world = _world_matrices(gltf, binary, time)
    ibm = accessor_array(gltf, binary, skin["inverseBindMatrices"]).astype(float)
    joint_matrices = np.stack([world[j] for j in skin["joints"]]) @ ibm
    positions = accessor_array(gltf, binary, attributes["POSITION"]).astype(float)
    homogeneous = np.concatenate([positions, np.ones((len(positions), 1))], axis=1)
    out = np.zeros_like(homogeneous)
    n = 0
    while f"JOINTS_{n}" in attributes:
        joints = accessor_array(gltf, binary, attributes[f"JOINTS_{n}"]).astype(int)
        weights = accessor_array(gltf, binary, attributes[f"WEIGHTS_{n}"]).astype(float)
        for i in range(4):
            moved = np.einsum("vij,vj->vi", joint_matrices[joints[:, i]], homogeneous)
            out += weights[:, i, None] * moved
        n += 1
    return out[:, :3]


def _reference_lbs(vertices, parents, heads, weights, rotations, root_translation):
    """The writer's input convention, directly: W_b = W_parent R_b, p_b = p_parent +
    W_parent (head_b - head_parent), v -> sum_b w_vb (W_b (v - head_b) + p_b)."""
    n = len(parents)
    world, posed = np.empty((n, 3, 3)), np.empty((n, 3))
    for b, p in enumerate(parents):
        if p < 0:
            world[b], posed[b] = rotations[b], heads[b] + root_translation
        else:
            world[b] = world[p] @ rotations[b]
            posed[b] = posed[p] + world[p] @ (heads[b] - heads[p])
    per_joint = np.einsum("bij,vbj->vbi", world, vertices[:, None, :] - heads[None]) + posed
    return np.einsum("vb,vbi->vi", weights, per_joint)


# ---------------------------------------------------------------------------------------------
# A small synthetic rig: a chain with a branch, a tube around it, up to 5 influences per vertex
# ---------------------------------------------------------------------------------------------


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _tube_rig(n_frames: int = 3, n_joints: int = 6, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    parents = [-1, 0, 1, 2, 1, 4] if n_joints == 6 else [-1] + list(range(n_joints - 1))
    heads = np.zeros((n_joints, 3))
    step = 1.25 / n_joints  # the chain ~1.25 m long
    for b, p in enumerate(parents):
        if p >= 0:
            heads[b] = heads[p] + step * np.array([rng.uniform(-0.2, 0.2), 1.0,
                                                   rng.uniform(-0.2, 0.2)])
    heads += [0.1, 0.9, -0.2]
    rings, around, radius = 20, 12, 0.06
    y = np.linspace(heads[:, 1].min() - 0.05, heads[:, 1].max() + 0.05, rings)
    phi = np.arange(around) * 2 * np.pi / around
    vertices = np.stack(np.broadcast_arrays(
        0.1 + radius * np.cos(phi)[None], y[:, None], -0.2 + radius * np.sin(phi)[None]),
        axis=-1).reshape(-1, 3)  # fmt: skip
    faces = []
    for r in range(rings - 1):
        for a in range(around):
            i, j = r * around + a, r * around + (a + 1) % around
            faces += [[i, j + around, j], [i, i + around, j + around]]
    # Weights: random positive values on 1..5 joints per vertex (5 at least once), a stray
    # weight below the writer's threshold on one vertex.
    n_vertices = len(vertices)
    weights = np.zeros((n_vertices, n_joints))
    for v in range(n_vertices):
        k = 5 if v == 7 else int(rng.integers(1, min(5, n_joints) + 1))
        chosen = rng.choice(n_joints, size=min(k, n_joints), replace=False)
        weights[v, chosen] = rng.uniform(0.1, 1.0, size=len(chosen))
    weights[3] *= 0.0
    weights[3, [1, 2]] = [1.0 - 1e-8, 1e-8]
    weights /= weights.sum(axis=1, keepdims=True)
    rotations = np.stack([[_rotation(rng.normal(size=3), rng.uniform(-2.5, 2.5))
                           for _ in range(n_joints)] for _ in range(n_frames)])
    root = rng.normal(scale=0.3, size=(n_frames, 3))
    return {"vertices_m": vertices, "faces": np.asarray(faces, dtype=np.int64),
            "joint_names": [f"joint{b}" for b in range(n_joints)], "joint_parents": parents,
            "joint_heads_m": heads, "skin_weights": weights, "rotations": rotations,
            "root_translation_m": root, "frame_rate": 30.0}


def _max_skinning_error(path: Path, rig: dict) -> float:
    gltf, binary = read_glb(path)
    worst = 0.0
    for t in range(len(rig["rotations"])):
        ours = _gltf_skinned(gltf, binary, t / rig["frame_rate"])
        reference = _reference_lbs(rig["vertices_m"], rig["joint_parents"],
                                   rig["joint_heads_m"], rig["skin_weights"],
                                   rig["rotations"][t], rig["root_translation_m"][t])
        worst = max(worst, float(np.abs(ours - reference).max()))
    return worst


# ---------------------------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("n_frames", "n_joints"), [(3, 6), (1, 6), (2, 300)])
def test_round_trip_skinning_matches_the_reference(tmp_path, n_frames, n_joints):
    rig = _tube_rig(n_frames, n_joints)
    path = tmp_path / "rig.glb"
    summary = write_skinned_glb(path, **rig, normals=np.tile([1.0, 0.0, 0.0], (240, 1)))
    assert summary == {"vertices": 240, "faces": 456, "joints": n_joints, "frames": n_frames,
                       "influences_per_vertex": 5, "bytes": path.stat().st_size}
    assert _max_skinning_error(path, rig) < 1e-5
    gltf, binary = read_glb(path)
    attributes = gltf["meshes"][0]["primitives"][0]["attributes"]
    assert sorted(attributes) == ["JOINTS_0", "JOINTS_1", "NORMAL", "POSITION", "WEIGHTS_0",
                                  "WEIGHTS_1"]
    joint_type = gltf["accessors"][attributes["JOINTS_0"]]["componentType"]
    assert joint_type == (5121 if n_joints <= 256 else 5123)
    weights = np.concatenate([accessor_array(gltf, binary, attributes[f"WEIGHTS_{n}"])
                              for n in (0, 1)], axis=1)
    assert np.all(np.diff(weights, axis=1)[:, :4] <= 0)  # largest first (three.js reads set 0)
    assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-6)
    assert np.count_nonzero(weights[3]) == 1  # the 1e-8 weight is dropped


def test_structure_of_the_file(tmp_path):
    rig = _tube_rig()
    path = tmp_path / "rig.glb"
    write_skinned_glb(path, **rig, colour_rgba=(0.5, 0.4, 0.3, 1.0), name="tube")
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<II", data, 12)
    bin_length, bin_type = struct.unpack_from("<II", data, 20 + json_length)
    assert (json_type, bin_type) == (0x4E4F534A, 0x004E4942)
    assert json_length % 4 == 0 and bin_length % 4 == 0
    assert 28 + json_length + bin_length == len(data)
    raw_json = data[20:20 + json_length]
    assert len(raw_json) - len(raw_json.rstrip(b" ")) < 4  # padded with (at most 3) spaces
    gltf, binary = read_glb(path)
    assert gltf == json.loads(data[20:20 + json_length])
    assert gltf["asset"] == {"version": "2.0", "generator": "mocap"}
    (buffer,) = gltf["buffers"]
    assert buffer["byteLength"] <= len(binary) < buffer["byteLength"] + 4

    sizes = {5121: 1, 5123: 2, 5125: 4, 5126: 4}
    for accessor in gltf["accessors"]:
        view = gltf["bufferViews"][accessor["bufferView"]]
        assert view["byteOffset"] % 4 == 0
        assert (view["byteOffset"] + accessor.get("byteOffset", 0)) % sizes[
            accessor["componentType"]] == 0
        assert view["byteOffset"] + view["byteLength"] <= len(binary)

    (primitive,) = gltf["meshes"][0]["primitives"]
    assert gltf["meshes"][0]["name"] == "tube"
    position = gltf["accessors"][primitive["attributes"]["POSITION"]]
    vertices32 = rig["vertices_m"].astype(np.float32)
    assert position["min"] == vertices32.min(axis=0).tolist()
    assert position["max"] == vertices32.max(axis=0).tolist()
    indices = gltf["accessors"][primitive["indices"]]
    assert (indices["componentType"], indices["type"]) == (5125, "SCALAR")
    assert gltf["bufferViews"][indices["bufferView"]]["target"] == 34963
    for name in primitive["attributes"]:
        accessor = gltf["accessors"][primitive["attributes"][name]]
        assert gltf["bufferViews"][accessor["bufferView"]]["target"] == 34962
    assert np.array_equal(accessor_array(gltf, binary, primitive["indices"]).reshape(-1, 3),
                          rig["faces"])
    material = gltf["materials"][primitive["material"]]
    assert material["pbrMetallicRoughness"] == {"baseColorFactor": [0.5, 0.4, 0.3, 1.0],
                                                "metallicFactor": 0.0, "roughnessFactor": 0.8}
    assert material["doubleSided"] is False

    # Scene graph: one scene root with the mesh node and the root joint side by side.
    nodes = gltf["nodes"]
    (scene_root,) = gltf["scenes"][gltf["scene"]]["nodes"]
    mesh_nodes = [i for i, n in enumerate(nodes) if "mesh" in n]
    skin = gltf["skins"][0]
    assert len(mesh_nodes) == 1 and nodes[mesh_nodes[0]]["skin"] == 0
    assert sorted(nodes[scene_root]["children"]) == sorted([mesh_nodes[0], skin["skeleton"]])
    assert [nodes[j]["name"] for j in skin["joints"]] == rig["joint_names"]
    for b, p in enumerate(rig["joint_parents"]):
        joint = skin["joints"][b]
        if p >= 0:
            assert joint in nodes[skin["joints"][p]]["children"]
        assert "mesh" not in nodes[joint]
    ibm = accessor_array(gltf, binary, skin["inverseBindMatrices"])
    expected = np.tile(np.eye(4), (6, 1, 1))
    expected[:, :3, 3] = -rig["joint_heads_m"]
    assert np.allclose(ibm, expected, atol=1e-6)
    raw = np.frombuffer(binary, np.float32, 16, gltf["bufferViews"][gltf["accessors"][
        skin["inverseBindMatrices"]]["bufferView"]]["byteOffset"])
    assert np.allclose(raw[12:15], -rig["joint_heads_m"][0], atol=1e-6)  # column-major
    for index in [*(i for n in nodes for i in n.get("children", [])), skin["skeleton"]]:
        assert 0 <= index < len(nodes)

    # Animation: times with min/max, unit quaternions, consecutive dots >= 0.
    animation = gltf["animations"][0]
    paths = sorted((c["target"]["node"], c["target"]["path"]) for c in animation["channels"])
    assert paths == sorted([(j, "rotation") for j in skin["joints"]]
                           + [(skin["skeleton"], "translation")])
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        assert sampler["interpolation"] == "LINEAR"
        times_accessor = gltf["accessors"][sampler["input"]]
        times = accessor_array(gltf, binary, sampler["input"])
        assert times_accessor["min"] == [float(times.min())] == [0.0]
        assert times_accessor["max"] == [float(times.max())]
        assert np.allclose(times, np.arange(3) / 30.0)
        values = accessor_array(gltf, binary, sampler["output"])
        if channel["target"]["path"] == "rotation":
            assert np.allclose(np.linalg.norm(values, axis=1), 1.0, atol=1e-6)
            assert np.all(np.einsum("ti,ti->t", values[1:], values[:-1]) >= 0.0)
        else:
            assert np.allclose(values, rig["joint_heads_m"][0] + rig["root_translation_m"],
                               atol=1e-6)


def test_read_glb_refuses_other_files(tmp_path):
    path = tmp_path / "not.glb"
    path.write_bytes(b"PK\x03\x04" + bytes(40))
    with pytest.raises(ValueError, match="not a GLB"):
        read_glb(path)
    path.write_bytes(struct.pack("<4sII", b"glTF", 1, 20) + bytes(8))
    with pytest.raises(ValueError, match="version 1"):
        read_glb(path)


@pytest.mark.parametrize(("change", "message"), [
    ({"skin_weights": np.ones((240, 5)) / 5}, "skin_weights must have shape"),
    ({"joint_parents": [-1, 0, 1, -1, 1, 4]}, "exactly one root"),
    ({"joint_parents": [-1, 0, 3, 1, 1, 4]}, "parents must be"),
    ({"frame_rate": 0.0}, "frame_rate"),
    ({"root_translation_m": np.zeros((2, 3))}, "root_translation_m must have shape"),
    ({"vertices_m": np.full((240, 3), np.nan)}, "vertices_m must be finite"),
    ({"faces": np.array([[0, 1, 240]])}, "out of range"),
    ({"rotations": np.full((3, 6, 3, 3), 2.0)}, "rotation matrices"),
    ({"joint_names": ["a", "b", "c", "d", "e", "e"]}, "unique"),
])  # fmt: skip
def test_bad_input_is_refused(tmp_path, change, message):
    rig = _tube_rig() | change
    path = tmp_path / "bad.glb"
    with pytest.raises(ValueError, match=message):
        write_skinned_glb(path, **rig)
    assert not path.exists()


def test_mpfb_body_round_trip(tmp_path):
    from tracking.body.model import Pose
    from tracking.body.mpfb.model import posed_vertices
    from tracking.body.mpfb.retarget import rig_rotations
    from tracking.body.mpfb.subject import MpfbModel

    m = MpfbModel(mesh="full")
    weights = m.assets.skin_weight_matrix
    weights = np.asarray(weights.todense()) if hasattr(weights, "todense") else weights
    rotations, root = rig_rotations(m.rig, Pose.neutral(), m.shape, m.corrections)
    bent = rotations.copy()
    b = m.assets.bone("LeftForeArm")
    bent[b] = bent[b] @ _rotation(np.array([1.0, 0.2, 0.0]), 1.2)
    frames = np.stack([rotations, bent])
    path = tmp_path / "body.glb"
    summary = write_skinned_glb(
        path, vertices_m=m.rest.vertices_m, faces=m.assets.faces,
        joint_names=m.assets.bone_names, joint_parents=m.assets.bone_parents,
        joint_heads_m=m.rest.bone_heads_m, skin_weights=weights, rotations=frames,
        root_translation_m=np.stack([root, root + [0.0, 0.0, 0.3]]), frame_rate=25.0,
        normals=m.rest_normals)
    assert summary["bytes"] == path.stat().st_size < 3_000_000
    assert summary["influences_per_vertex"] <= 4
    gltf, binary = read_glb(path)
    for t, (frame, shift) in enumerate([(rotations, 0.0), (bent, 0.3)]):
        reference = posed_vertices(m.assets, m.rest, frame, root + [0.0, 0.0, shift]).vertices_m
        ours = _gltf_skinned(gltf, binary, t / 25.0)
        assert np.abs(ours - reference).max() < 1e-4
