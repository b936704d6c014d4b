"""A skinned, animated triangle mesh as a glTF 2.0 binary file (.glb), numpy, json and struct only.

`write_skinned_glb` writes one mesh (one primitive, one material), its skeleton and one
animation; Blender (File > Import > glTF 2.0) and three.js (``GLTFLoader`` and an
``AnimationMixer`` on ``gltf.animations[0]``) play it. `read_glb` and `accessor_array` read such
a file back (any GLB 2.0 whose buffer is the embedded BIN chunk), for tests and checks.

Conventions (those of our skinning code, `tracking.body.mpfb.model.posed_vertices`):

* Metres, Y up, as glTF: no conversion. Faces are counter-clockwise seen from outside.
* ``vertices_m`` (and ``normals``) are the mesh in its bind (rest) pose. In that pose every joint
  frame is parallel to the world, so joint b's bind world matrix is the translation by its head
  ``joint_heads_m[b]`` and its inverse bind matrix the translation by ``-joint_heads_m[b]``.
* ``joint_parents[b]``: the parent's index, parents before children, -1 for the single root
  (so the root is joint 0).
* ``rotations[t, b]``: joint b's ``parent_from_joint`` rotation about its head at frame t (the
  root's relative to the world); ``root_translation_m[t]``: the root's displacement from its
  bind head. Forward kinematics: the root sits at ``head_root + root_translation[t]`` turned by
  ``R_root``; a child has ``W_b = W_parent @ R_b`` and ``p_b = p_parent + W_parent @ (head_b -
  head_parent)``; a vertex goes to ``sum_b w_vb (W_b (v - head_b) + p_b)``.

In glTF terms: joint b is node b, with translation ``head_b - head_parent`` (the root's: its
head) and, per frame, the rotation quaternion of ``R_b`` (x, y, z, w; unit; each frame's of the
same sign as the previous frame's so that LINEAR interpolation takes the short way) and, for the
root, the translation ``head_root + root_translation[t]``; keyframe times are ``t /
frame_rate``. The scene has one root node (named ``name``) with two children side by side: the
mesh node (``mesh`` and ``skin``) and the root joint. The skin lists the joints in joint order,
``skeleton`` is the root joint. The nodes' own TRS are the bind pose.

Skinning weights: weights below `MIN_WEIGHT` are dropped and the rows renormalised; each vertex
keeps all its other influences, in as many JOINTS_n / WEIGHTS_n sets of 4 as the largest count
needs (padded with joint 0, weight 0), largest weights first, so the skinning is exact. Blender
reads every set; three.js reads only JOINTS_0 / WEIGHTS_0 and renormalises them, which is exact
only when no vertex has more than 4 influences.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

MIN_WEIGHT: float = 1e-6
"""Skinning weights below this are dropped (and the vertex's others renormalised)."""

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5121, 5123, 5125
_COMPONENT_DTYPES: dict[int, np.dtype] = {
    5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"),
    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4"),
}  # fmt: skip
_TYPE_SHAPES: dict[str, tuple[int, ...]] = {
    "SCALAR": (), "VEC2": (2,), "VEC3": (3,), "VEC4": (4,),
    "MAT2": (2, 2), "MAT3": (3, 3), "MAT4": (4, 4),
}  # fmt: skip
_TYPE_OF_WIDTH = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}

_ROTATION_TOLERANCE = 1e-5
_WEIGHT_SUM_TOLERANCE = 1e-3


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


class _Buffer:
    """The BIN chunk under construction: bufferViews and accessors appended in order."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.length = 0
        self.buffer_views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def add(self, array: np.ndarray, component_type: int, *, target: int | None = None,
            min_max: bool = False) -> int:
        """Append ``array`` (count,) or (count, width) as one bufferView and one accessor (its
        own, tightly packed, 4-byte aligned); the accessor's index."""
        data = np.ascontiguousarray(array, dtype=_COMPONENT_DTYPES[component_type])
        width = 1 if data.ndim == 1 else data.shape[1]
        pad = -self.length % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.length += pad
        raw = data.tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": self.length, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.parts.append(raw)
        self.length += len(raw)
        self.buffer_views.append(view)
        accessor: dict[str, Any] = {"bufferView": len(self.buffer_views) - 1, "byteOffset": 0,
                                    "componentType": component_type, "count": int(data.shape[0]),
                                    "type": _TYPE_OF_WIDTH[width]}
        if min_max:
            flat = data.reshape(data.shape[0], width)
            cast = float if component_type == FLOAT else int
            accessor["min"] = [cast(x) for x in flat.min(axis=0)]
            accessor["max"] = [cast(x) for x in flat.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.parts) + b"\0" * (-self.length % 4)


def _quaternions_xyzw(rotations: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) of (..., 3, 3) rotation matrices (Shepperd's
    method: each from its largest component, so none is divided by a small number)."""
    m = rotations.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    case = np.argmax(np.stack([m00, m11, m22, trace], axis=1), axis=1)
    q = np.empty((m.shape[0], 4))
    for k in range(4):
        s = case == k
        if not s.any():
            continue
        a = m[s]
        if k == 3:
            big = 0.5 * np.sqrt(np.maximum(1.0 + trace[s], 1e-300))
            f = 0.25 / big
            q[s] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) * f, (a[:, 0, 2] - a[:, 2, 0]) * f,
                             (a[:, 1, 0] - a[:, 0, 1]) * f, big], axis=1)
            continue
        i, j, n = k, (k + 1) % 3, (k + 2) % 3
        big = 0.5 * np.sqrt(np.maximum(1.0 + a[:, i, i] - a[:, j, j] - a[:, n, n], 1e-300))
        f = 0.25 / big
        part = np.empty((a.shape[0], 4))
        part[:, i] = big
        part[:, j] = (a[:, i, j] + a[:, j, i]) * f
        part[:, n] = (a[:, i, n] + a[:, n, i]) * f
        part[:, 3] = (a[:, n, j] - a[:, j, n]) * f
        q[s] = part
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(*rotations.shape[:-2], 4)


def _continuous(quaternions: np.ndarray) -> np.ndarray:
    """(T, B, 4) quaternions with each frame's sign flipped where needed so that consecutive
    frames' have a non-negative dot product (the first frame's w >= 0)."""
    q = quaternions.copy()
    q[0] *= np.where(q[0, :, 3:] < 0.0, -1.0, 1.0)
    if q.shape[0] > 1:
        dots = np.einsum("tbi,tbi->tb", q[1:], q[:-1])
        signs = np.cumprod(np.where(dots < 0.0, -1.0, 1.0), axis=0)
        q[1:] *= signs[..., None]
    return q


def _float_array(value: Any, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (None: any length), or ValueError."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array: {error}") from None
    if array.ndim != len(shape) or any(s is not None and s != n
                                       for s, n in zip(shape, array.shape, strict=True)):
        wanted = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {wanted}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array


def _check_skeleton(joint_names: Sequence[str], joint_parents: Sequence[int]) -> np.ndarray:
    names = list(joint_names)
    if not names:
        raise ValueError("at least one joint is needed")
    if not all(isinstance(n, str) and n for n in names):
        raise ValueError("joint_names must be non-empty strings")
    if len(set(names)) != len(names):
        raise ValueError("joint_names must be unique")
    parents = np.asarray(joint_parents)
    if parents.shape != (len(names),) or not np.issubdtype(parents.dtype, np.integer):
        raise ValueError(f"joint_parents must be {len(names)} integers (one per joint name), "
                         f"got shape {parents.shape} of {parents.dtype}")
    roots = np.flatnonzero(parents == -1)
    if roots.size != 1:
        raise ValueError(f"the skeleton must have exactly one root (parent -1), got "
                         f"{roots.size}: {[names[r] for r in roots]}")
    for b, p in enumerate(parents):
        if p != -1 and not 0 <= p < b:
            raise ValueError(f"joint {b} ({names[b]!r}) has parent {int(p)}: parents must be "
                             "-1 or a joint listed before the child")
    return parents.astype(np.int64)


def _skin_sets(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(V, 4n) joint indices and float32 weights of the kept influences, largest first, padded
    with joint 0 / weight 0, and the largest influence count."""
    w = np.where(weights >= MIN_WEIGHT, weights, 0.0)
    sums = w.sum(axis=1)
    if np.any(sums <= 0.0):
        v = int(np.flatnonzero(sums <= 0.0)[0])
        raise ValueError(f"vertex {v} has no skinning weight of at least {MIN_WEIGHT}")
    w /= sums[:, None]
    counts = np.count_nonzero(w, axis=1)
    influences = int(counts.max())
    width = 4 * -(-influences // 4)
    order = np.argsort(-w, axis=1, kind="stable")[:, :width]
    if order.shape[1] < width:  # fewer joints than slots
        order = np.pad(order, ((0, 0), (0, width - order.shape[1])))
    kept = np.take_along_axis(w, order, axis=1)
    kept[:, weights.shape[1]:] = 0.0
    joints = np.where(kept > 0.0, order, 0)
    kept32 = kept.astype(np.float32)
    # Let the largest weight absorb the float32 rounding, so that each row sums to 1 in float32.
    kept32[:, 0] = np.float32(1.0) - kept32[:, 1:].sum(axis=1, dtype=np.float32)
    return joints, kept32, influences


def write_skinned_glb(path: Path | str, *, vertices_m: np.ndarray, faces: np.ndarray,
                      joint_names: Sequence[str], joint_parents: Sequence[int],
                      joint_heads_m: np.ndarray, skin_weights: np.ndarray,
                      rotations: np.ndarray, root_translation_m: np.ndarray,
                      frame_rate: float, normals: np.ndarray | None = None,
                      colour_rgba: tuple[float, float, float, float] = (0.87, 0.72, 0.59, 1.0),
                      name: str = "subject") -> dict[str, Any]:
    """Write the skinned mesh and its animation to ``path`` as a GLB (see the module docstring
    for the conventions). vertices_m (V, 3), faces (F, 3) int, joint_heads_m (B, 3),
    skin_weights (V, B) dense, rows summing to 1, rotations (T, B, 3, 3), root_translation_m
    (T, 3), frame_rate in frames per second, normals (V, 3) of the bind pose (normalised here;
    a zero one becomes +Y). ValueError for inconsistent or non-finite inputs.

    Returns {"vertices", "faces", "joints", "frames", "influences_per_vertex" (the largest
    count of kept weights), "bytes" (the file's size)}."""
    parents = _check_skeleton(joint_names, joint_parents)
    n_joints = parents.size
    vertices = _float_array(vertices_m, "vertices_m", (None, 3))
    n_vertices = vertices.shape[0]
    if n_vertices == 0:
        raise ValueError("the mesh has no vertices")
    tri = np.asarray(faces)
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
        raise ValueError(f"faces must have shape (F, 3) with F > 0, got {tri.shape}")
    if not np.issubdtype(tri.dtype, np.integer):
        raise ValueError(f"faces must be integers, got {tri.dtype}")
    if tri.min() < 0 or tri.max() >= n_vertices:
        raise ValueError(f"faces index vertices out of range 0..{n_vertices - 1}")
    heads = _float_array(joint_heads_m, "joint_heads_m", (n_joints, 3))
    weights = _float_array(skin_weights, "skin_weights", (n_vertices, n_joints))
    if weights.min() < 0.0:
        raise ValueError("skin_weights must be non-negative")
    row_sums = weights.sum(axis=1)
    if np.any(np.abs(row_sums - 1.0) > _WEIGHT_SUM_TOLERANCE):
        v = int(np.argmax(np.abs(row_sums - 1.0)))
        raise ValueError(f"skin_weights rows must sum to 1, vertex {v}'s sum to {row_sums[v]}")
    rot = _float_array(rotations, "rotations", (None, n_joints, 3, 3))
    n_frames = rot.shape[0]
    if n_frames == 0:
        raise ValueError("at least one frame is needed")
    gram = np.einsum("tbji,tbjk->tbik", rot, rot)
    if (np.abs(gram - np.eye(3)).max() > _ROTATION_TOLERANCE
            or np.any(np.linalg.det(rot) <= 0.0)):
        raise ValueError(f"rotations must be rotation matrices (orthonormal within "
                         f"{_ROTATION_TOLERANCE}, determinant +1)")
    translation = _float_array(root_translation_m, "root_translation_m", (n_frames, 3))
    if not (np.isfinite(frame_rate) and frame_rate > 0.0):
        raise ValueError(f"frame_rate must be finite and > 0, got {frame_rate}")
    colour = _float_array(colour_rgba, "colour_rgba", (4,))
    if colour.min() < 0.0 or colour.max() > 1.0:
        raise ValueError(f"colour_rgba must be in 0..1, got {tuple(colour)}")
    unit_normals = None
    if normals is not None:
        unit_normals = _float_array(normals, "normals", (n_vertices, 3))
        length = np.linalg.norm(unit_normals, axis=1, keepdims=True)
        unit_normals = np.where(length > 1e-12, unit_normals / np.maximum(length, 1e-300),
                                np.array([0.0, 1.0, 0.0]))

    joints, kept_weights, influences = _skin_sets(weights)
    joint_type = UNSIGNED_BYTE if n_joints <= 256 else UNSIGNED_SHORT

    buf = _Buffer()
    attributes = {"POSITION": buf.add(vertices, FLOAT, target=ARRAY_BUFFER, min_max=True)}
    if unit_normals is not None:
        attributes["NORMAL"] = buf.add(unit_normals, FLOAT, target=ARRAY_BUFFER)
    for n in range(joints.shape[1] // 4):
        attributes[f"JOINTS_{n}"] = buf.add(joints[:, 4 * n:4 * n + 4], joint_type,
                                            target=ARRAY_BUFFER)
        attributes[f"WEIGHTS_{n}"] = buf.add(kept_weights[:, 4 * n:4 * n + 4], FLOAT,
                                             target=ARRAY_BUFFER)
    indices = buf.add(tri.reshape(-1), UNSIGNED_INT, target=ELEMENT_ARRAY_BUFFER)
    inverse_bind = np.tile(np.eye(4), (n_joints, 1, 1))
    inverse_bind[:, :3, 3] = -heads
    ibm = buf.add(inverse_bind.transpose(0, 2, 1).reshape(n_joints, 16), FLOAT)  # column-major

    times = buf.add(np.arange(n_frames) / float(frame_rate), FLOAT, min_max=True)
    quaternions = _continuous(_quaternions_xyzw(rot))
    samplers: list[dict[str, Any]] = []
    channels: list[dict[str, Any]] = []
    for b in range(n_joints):
        samplers.append({"input": times, "output": buf.add(quaternions[:, b], FLOAT),
                         "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": b, "path": "rotation"}})
    samplers.append({"input": times, "output": buf.add(heads[0] + translation, FLOAT),
                     "interpolation": "LINEAR"})
    channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": "translation"}})

    offsets = heads.copy()
    offsets[1:] -= heads[parents[1:]]
    nodes: list[dict[str, Any]] = []
    for b, joint_name in enumerate(joint_names):
        node: dict[str, Any] = {"name": joint_name,
                                "translation": [float(x) for x in offsets[b]]}
        children = [int(c) for c in np.flatnonzero(parents == b)]
        if children:
            node["children"] = children
        nodes.append(node)
    mesh_node, scene_root = n_joints, n_joints + 1
    nodes.append({"name": f"{name}_mesh", "mesh": 0, "skin": 0})
    nodes.append({"name": name, "children": [mesh_node, 0]})

    gltf: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "mocap"},
        "scene": 0,
        "scenes": [{"name": name, "nodes": [scene_root]}],
        "nodes": nodes,
        "meshes": [{"name": name, "primitives": [
            {"attributes": attributes, "indices": indices, "material": 0, "mode": 4}]}],
        "materials": [{"name": f"{name}_skin", "doubleSided": False, "pbrMetallicRoughness": {
            "baseColorFactor": [float(c) for c in colour], "metallicFactor": 0.0,
            "roughnessFactor": 0.8}}],
        "skins": [{"name": name, "inverseBindMatrices": ibm, "skeleton": 0,
                   "joints": list(range(n_joints))}],
        "animations": [{"name": name, "samplers": samplers, "channels": channels}],
        "buffers": [{"byteLength": buf.length}],
        "bufferViews": buf.buffer_views,
        "accessors": buf.accessors,
    }
    json_chunk = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    json_chunk += b" " * (-len(json_chunk) % 4)
    bin_chunk = buf.data()
    total = 12 + 8 + len(json_chunk) + 8 + len(bin_chunk)
    blob = b"".join([struct.pack("<4sII", GLB_MAGIC, 2, total),
                     struct.pack("<II", len(json_chunk), CHUNK_JSON), json_chunk,
                     struct.pack("<II", len(bin_chunk), CHUNK_BIN), bin_chunk])
    Path(path).write_bytes(blob)
    return {"vertices": n_vertices, "faces": int(tri.shape[0]), "joints": n_joints,
            "frames": n_frames, "influences_per_vertex": influences, "bytes": total}


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------


def read_glb(path: Path | str) -> tuple[dict[str, Any], bytes]:
    """The JSON document and the BIN chunk (b"" if none) of the GLB 2.0 file at ``path``;
    ValueError if it is not one (magic, version, lengths, chunk types)."""
    data = Path(path).read_bytes()
    if len(data) < 20:
        raise ValueError(f"{path}: too short for a GLB file ({len(data)} bytes)")
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != GLB_MAGIC:
        raise ValueError(f"{path}: not a GLB file (magic {magic!r})")
    if version != 2:
        raise ValueError(f"{path}: GLB version {version}, only 2 is read")
    if length != len(data):
        raise ValueError(f"{path}: the header gives {length} bytes, the file has {len(data)}")
    chunks: list[tuple[int, bytes]] = []
    offset = 12
    while offset < length:
        if offset + 8 > length:
            raise ValueError(f"{path}: truncated chunk header at byte {offset}")
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        offset += 8
        if offset + chunk_length > length:
            raise ValueError(f"{path}: chunk at byte {offset - 8} runs past the end")
        chunks.append((chunk_type, data[offset:offset + chunk_length]))
        offset += chunk_length
    if not chunks or chunks[0][0] != CHUNK_JSON:
        raise ValueError(f"{path}: the first chunk is not JSON")
    try:
        gltf = json.loads(chunks[0][1].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: invalid JSON chunk: {error}") from None
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == CHUNK_BIN else b""
    return gltf, binary


def accessor_array(gltf: dict[str, Any], binary: bytes, index: int) -> np.ndarray:
    """Accessor ``index`` of ``gltf`` decoded from the GLB's BIN chunk ``binary``: (count,)
    for SCALAR, (count, n) for VECn, (count, n, n) matrices for MATn (glTF stores them column
    by column; these are the matrices themselves). In the component type's dtype, or float32
    for a ``normalized`` integer accessor; honours the bufferView's byteOffset and byteStride.
    Sparse accessors and external buffers are not read (ValueError)."""
    accessor = gltf["accessors"][index]
    if "sparse" in accessor:
        raise ValueError(f"accessor {index} is sparse, which is not read")
    dtype = _COMPONENT_DTYPES[accessor["componentType"]]
    shape = _TYPE_SHAPES[accessor["type"]]
    count = int(accessor["count"])
    n_components = int(np.prod(shape, dtype=int))
    if accessor["type"] in ("MAT2", "MAT3") and dtype.itemsize < 4:
        raise ValueError(f"accessor {index}: padded {accessor['type']} columns are not read")
    if "bufferView" not in accessor:
        out = np.zeros((count, *shape), dtype=dtype)
    else:
        view = gltf["bufferViews"][accessor["bufferView"]]
        buffer = gltf["buffers"][view["buffer"]]
        if view["buffer"] != 0 or "uri" in buffer:
            raise ValueError(f"accessor {index}: only the GLB's own BIN buffer is read")
        element = dtype.itemsize * n_components
        stride = int(view.get("byteStride", element))
        start = int(view.get("byteOffset", 0)) + int(accessor.get("byteOffset", 0))
        end = start + (stride * (count - 1) + element if count else 0)
        view_end = int(view.get("byteOffset", 0)) + int(view["byteLength"])
        if end > view_end or view_end > len(binary):
            raise ValueError(f"accessor {index} runs past its bufferView or the BIN chunk")
        flat = np.ndarray((count, n_components), dtype=dtype, buffer=binary, offset=start,
                          strides=(stride, dtype.itemsize)).copy()
        out = flat.reshape(count, *shape)
        if len(shape) == 2:
            out = out.transpose(0, 2, 1).copy()
    if accessor.get("normalized") and dtype.kind in "iu":
        top = float(np.iinfo(dtype).max)
        out = np.maximum(out.astype(np.float32) / np.float32(top), np.float32(-1.0))
    return out
