"""One MPFB2 subject (a macro shape, loose clothing, a mesh resolution) as the model that the
tracker fits (`tracking.body.model.TrackedModel`) and that ``mocap synth`` renders.

A pose of the thesis' layout drives the ``cmu_mb`` rig (`tracking.body.mpfb.retarget`) and the
mesh follows by linear blend skinning (`tracking.body.mpfb.model`). What the tracker needs
besides the posed vertices:

* ``shape``: the subject's skeleton in the terms of `tracking.body.model.BodyShape`, measured on
  its own rest pose (limbs hanging straight): the lengths between the joint centres of
  `tracking.body.mpfb.model.named_joints` along Y, the shoulder and hip spacings along X; the
  shoulders sit on the neck node's level in our layout, so ``spine_to_neck`` ends at the
  shoulder joints' height and ``neck_to_head_top`` starts there; the hand, the foot and the
  girths (used for the tracker's limb clearances only) are `BodyShape.default`'s proportions
  of the stature. Our forward kinematics of that skeleton then puts the hips, knees, ankles,
  shoulders, elbows and wrists where the skinned body has them, within a few millimetres at
  rest (the rig's joints are not all in one plane); the reported joints are the skinned
  body's own (`joints`).
* ``node_weights``: each vertex's skinning weight summed per node of ours (the node that
  drives each bone, `tracking.body.mpfb.retarget.NODE_OF_BONE`), so that a stage of the
  tracker knows which triangles a parameter moves (any weight above `MOVING_WEIGHT`) and the
  outline refinement scales each vertex's derivative by the weight its parameter carries.
* ``shape_parameters``: the macro modifiers the silhouettes refine (`REFINED_MACROS`), 0..1,
  and the loose clothing's thickness in decimetres (0..1 for 0..10 cm): a clothed person's
  outline is not a naked body's of any macro shape.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cache, cached_property
from typing import Any, ClassVar

import numpy as np

from tracking.body.model import (
    NODE_INDEX,
    NODE_NAMES,
    BodyShape,
    Pose,
    ShapeParameters,
    SkinnedMesh,
)
from tracking.body.mpfb.model import (
    MacroShape,
    MpfbAssets,
    bind_vertices,
    load_assets,
    named_joints,
    posed_vertices,
    rest_body,
)
from tracking.body.mpfb.retarget import (
    NODE_OF_BONE,
    Rig,
    limb_corrections,
    rig_rotations,
    rig_world_rotations,
)

CLOTHED_BONES: tuple[str, ...] = (
    "Hips", "LHipJoint", "RHipJoint", "LowerBack", "Spine", "Spine1",
    "LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg")  # fmt: skip
"""The bones whose skin loose clothing covers: trunk, hips, thighs and shanks (not the arms,
the neck, the head, the hands or the feet)."""

REFINED_MACROS: tuple[str, ...] = ("gender", "muscle", "weight", "height", "proportions")
"""The macro modifiers a shape pass refines (age is left: its effect on an adult's stature and
girths is what height and weight already span)."""

MOVING_WEIGHT: float = 1e-3
"""A vertex moves with a node when its skinning weight on that node's bones exceeds this: a
smaller weight moves it less than 1 mm for a 1 m displacement of the bone, which the
tracker's stages may ignore (they re-render only the triangles their parameters move)."""

@cache
def shared_assets() -> MpfbAssets:
    """The packaged assets, read once per process (`load_assets`)."""
    return load_assets()


def clothed(assets: MpfbAssets, rest: Any, thickness_m: float) -> Any:
    """``rest`` (`tracking.body.mpfb.model.RestBody`) with the vertices that `CLOTHED_BONES`
    carry (by at least half of their skinning weight) pushed out along their normals by
    ``thickness_m``, fading to nothing where that weight falls from 1 to 0.5 (the waistband,
    the neckline, the cuffs)."""
    if thickness_m == 0.0:
        return rest
    from recon.mesh.normals import vertex_normals

    normals = vertex_normals(rest.vertices_m, assets.faces)
    vertices = rest.vertices_m + thickness_m * _clothing_fade(assets)[:, None] * normals
    vertices.flags.writeable = False
    return dataclasses.replace(rest, vertices_m=vertices)


@cache
def _clothing_fade(assets: MpfbAssets) -> np.ndarray:
    """(V,) how much of `clothed`'s thickness each vertex gets: 1 where `CLOTHED_BONES` carry
    it wholly, fading to 0 where their skinning weight falls to one half (the same for every
    shape: made once per assets)."""
    columns = [assets.bone(name) for name in CLOTHED_BONES]
    covered = assets.skin_weight_matrix[:, columns].sum(axis=1)
    fade = np.clip(2.0 * covered - 1.0, 0.0, 1.0)
    fade.flags.writeable = False
    return fade


def _skeleton_of(joints: np.ndarray, floor_y: float) -> BodyShape:
    """The `BodyShape` of a body whose (16, 3) joints (`NODE_NAMES` order) stand at rest, limbs
    hanging, on the floor ``floor_y`` (module docstring)."""
    j = {name: joints[i] for i, name in enumerate(NODE_NAMES)}

    def mean_y(a: str, b: str) -> float:  # a's height above b's, both sides averaged
        return float(np.mean([j[f"{s}_{a}"][1] - j[f"{s}_{b}"][1] for s in "lr"]))

    shoulder_y = float(np.mean([j["l_shoulder"][1], j["r_shoulder"][1]]))
    height = float(j["head_top"][1] - floor_y)
    thigh, shank = mean_y("hip", "knee"), mean_y("knee", "ankle")
    hip_height = float(j["pelvis"][1] - floor_y)
    default = BodyShape.default(height)
    return dataclasses.replace(
        default,
        pelvis_to_spine=float(j["spine"][1] - j["pelvis"][1]),
        spine_to_neck=shoulder_y - float(j["spine"][1]),
        neck_to_head_top=float(j["head_top"][1]) - shoulder_y,
        shoulder_half_width=float(j["l_shoulder"][0] - j["r_shoulder"][0]) / 2,
        hip_half_width=float(j["l_hip"][0] - j["r_hip"][0]) / 2,
        upper_arm=mean_y("shoulder", "elbow"), forearm=mean_y("elbow", "wrist"),
        thigh=thigh, shank=shank, ankle_height=hip_height - thigh - shank)


@dataclass(frozen=True, eq=False)
class MpfbModel:
    """One MPFB2 subject: ``macro`` its shape, ``clothes_cm`` loose clothing on the trunk and
    legs (0..10), ``mesh`` "full" (~13,400 vertices) or "decimated" (~2,500, for the tracker's
    energy)."""

    macro: MacroShape = MacroShape()
    clothes_cm: float = 0.0
    mesh: str = "decimated"
    name: ClassVar[str] = "mpfb"

    def __post_init__(self) -> None:
        if self.mesh not in ("full", "decimated"):
            raise ValueError(f"mesh must be 'full' or 'decimated', got {self.mesh!r}")
        if not 0.0 <= self.clothes_cm <= 10.0:
            raise ValueError(f"clothes_cm must be in 0..10, got {self.clothes_cm}")
        assets = shared_assets()
        rest = clothed(assets, rest_body(assets, self.macro), self.clothes_cm / 100.0)
        rig = Rig(assets.bone_names, np.asarray(assets.bone_parents), rest.bone_heads_m,
                  rest.bone_tails_m, 0.0)
        corrections = limb_corrections(rig)
        # The legs turned to hang straight reach lower than in MPFB's rest: the floor that sets
        # the hip height is the lowest vertex of our rest pose (any skeleton will do here).
        rotations, root = rig_rotations(rig, Pose.neutral(), BodyShape.default(), corrections)
        straight = posed_vertices(assets, rest, rotations, root)
        joints = named_joints(assets, straight)
        floor_y = float(straight.vertices_m[:, 1].min())
        rig = dataclasses.replace(rig, floor_y=float(
            rig.hip_centre[1] - (joints[NODE_INDEX["pelvis"]][1] - floor_y)))
        if self.mesh == "decimated":
            indices: np.ndarray | None = assets.decimated_vertex_indices
            faces = assets.decimated_faces
        else:
            indices, faces = None, assets.faces
        values = {"assets": assets, "rest": rest, "rig": rig, "corrections": corrections,
                  "vertex_indices": indices, "faces": faces,
                  "shape": _skeleton_of(joints, floor_y)}
        for key, value in values.items():
            object.__setattr__(self, key, value)

    # Set in __post_init__ (a frozen dataclass's derived fields).
    assets: MpfbAssets = dataclasses.field(init=False, repr=False)
    rest: Any = dataclasses.field(init=False, repr=False)
    rig: Rig = dataclasses.field(init=False, repr=False)
    corrections: np.ndarray = dataclasses.field(init=False, repr=False)
    vertex_indices: np.ndarray | None = dataclasses.field(init=False, repr=False)
    faces: np.ndarray = dataclasses.field(init=False, repr=False)
    shape: BodyShape = dataclasses.field(init=False, repr=False)

    @classmethod
    def of_height(cls, height_m: float, **kwargs: Any) -> MpfbModel:
        """The average subject (MakeHuman's neutral macros) of stature ``height_m``, with the
        height modifier interpolated between 0 and 1 (clipped there)."""
        assets = shared_assets()
        grid = np.linspace(0.0, 1.0, 9)
        statures = [rest_body(assets, MacroShape(height=h)).head_top_m[1] for h in grid]
        value = float(np.interp(height_m, statures, grid))
        return cls(MacroShape(height=value), **kwargs)

    # -- the tracker's model interface (`tracking.body.model.TrackedModel`) -----------------

    def _rotations(self, pose: Pose, skeleton: BodyShape | None) -> tuple[np.ndarray, np.ndarray]:
        return rig_rotations(self.rig, pose, self.shape if skeleton is None else skeleton,
                             self.corrections)

    def posed_body(self, pose: Pose, skeleton: BodyShape | None = None,
                   normals: bool = False) -> Any:
        """`tracking.body.mpfb.model.PosedBody` of ``pose``; ``skeleton``: the shape the pose
        was retargeted to, which sets only the floor (default: this subject's own)."""
        rotations, root = self._rotations(pose, skeleton)
        return posed_vertices(self.assets, self.rest, rotations, root, bound=self._bound,
                              rest_normals=self.rest_normals if normals else None)

    @cached_property
    def _bound(self) -> Any:
        """This resolution's vertices ready to skin (`bind_vertices`), made once."""
        return bind_vertices(self.assets, self.rest, self.vertex_indices)

    def posed_vertices(self, pose: Pose, vertex_ids: np.ndarray | None = None) -> np.ndarray:
        """(V, 3) world vertices in ``pose``: `posed_body`'s, with the rig's kinematics and
        the skinning in compiled code and nothing else (the energy poses the body thousands of
        times a frame). vertex_ids: (N,) only these vertices, (N, 3), the same floats: a
        stage of the tracker draws the vertices of the faces it moves alone."""
        from tracking.body.mpfb.skinning import blend_skin, blend_skin_at, skin_matrices

        world, root = rig_world_rotations(self.rig, pose, self.shape, self.corrections)
        bones, weights, vertices = self._bound
        skin = np.empty((self.assets.n_bones, 3, 4))
        skin_matrices(np.ascontiguousarray(world, dtype=np.float64), self._bone_order[0],
                      self._bone_order[1], self.rest.bone_heads_m,
                      np.asarray(root, dtype=np.float64), skin)  # fmt: skip
        if vertex_ids is not None:
            posed = np.empty((len(vertex_ids), 3))
            blend_skin_at(skin, bones, weights, vertices,
                          np.asarray(vertex_ids, dtype=np.int64), posed)
            return posed
        posed = np.empty((len(vertices), 3))
        blend_skin(skin, bones, weights, vertices, np.zeros((0, 3)), posed, np.zeros((0, 3)))
        return posed

    @cached_property
    def _bone_order(self) -> tuple[np.ndarray, np.ndarray]:
        """The rig's (B,) parent per bone and (B,) bones parents first, for `skin_matrices`."""
        return (np.ascontiguousarray(self.assets.bone_parents, dtype=np.int64),
                np.concatenate(self.assets.bone_levels).astype(np.int64))

    def posed_surface(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) world vertices and (V, 3) unit outward normals in ``pose``."""
        body = self.posed_body(pose, normals=True)
        return body.vertices_m, body.normals

    def joints(self, pose: Pose) -> np.ndarray:
        """(16, 3) the skinned body's joint centres (`named_joints`) in ``pose``."""
        rotations, root = self._rotations(pose, None)
        return named_joints(self.assets, posed_vertices(self.assets, self.rest, rotations, root,
                                                        vertex_indices=np.zeros(0, int)))

    @cached_property
    def rest_normals(self) -> np.ndarray:
        """(V, 3) unit outward normals of the rest mesh (MPFB's pose) of this resolution."""
        from recon.mesh.normals import vertex_normals

        normals = vertex_normals(self.rest.vertices_m, self.assets.faces)
        if self.vertex_indices is not None:
            normals = normals[self.vertex_indices]
        normals.flags.writeable = False
        return normals

    @cached_property
    def node_weights(self) -> np.ndarray:
        """(V, 16) each vertex's skinning weight per node of ours (module docstring)."""
        bone_node = np.zeros((self.assets.n_bones, len(NODE_NAMES)))
        for b, bone in enumerate(self.assets.bone_names):
            bone_node[b, NODE_INDEX[NODE_OF_BONE[bone]]] = 1.0
        weights = self.assets.skin_weight_matrix
        if self.vertex_indices is not None:
            weights = weights[self.vertex_indices]
        out = np.asarray(weights @ bone_node)
        out.flags.writeable = False
        return out

    @cached_property
    def _face_nodes(self) -> np.ndarray:
        """(F, 16) bool: a vertex of the face moves with the node (`MOVING_WEIGHT`)."""
        return (self.node_weights[self.faces] > MOVING_WEIGHT).any(axis=1)

    def faces_moved_by(self, moved_nodes: np.ndarray) -> np.ndarray:
        """(F,) bool: the faces that move when the nodes ``moved_nodes`` ((16,) bool) do."""
        return self._face_nodes[:, np.asarray(moved_nodes, bool)].any(axis=1)

    def shape_parameters(self) -> ShapeParameters:
        """The macro modifiers of `REFINED_MACROS` and the clothing in decimetres, each 0..1."""
        n = len(REFINED_MACROS) + 1
        values = [getattr(self.macro, k) for k in REFINED_MACROS] + [self.clothes_cm / 10.0]
        return ShapeParameters(names=(*REFINED_MACROS, "clothes_dm"), values=np.array(values),
                               lower=np.zeros(n), upper=np.ones(n), step=1e-2)

    def reshaped(self, values: np.ndarray) -> MpfbModel:
        """This subject with the `shape_parameters` ``values``."""
        values = np.clip(np.asarray(values, float), 0.0, 1.0)
        macro = dataclasses.replace(self.macro, **{
            k: float(v) for k, v in zip(REFINED_MACROS, values[:-1], strict=True)})
        return MpfbModel(macro, 10.0 * float(values[-1]), self.mesh)

    def record(self) -> dict[str, object]:
        """What a pose file stores to rebuild this subject (`from_record`)."""
        return {"name": self.name, "macro": dataclasses.asdict(self.macro),
                "clothes_cm": self.clothes_cm}

    def skin(self) -> SkinnedMesh:
        """The full CC0 body at MPFB's rest (its A pose, every bone frame world-aligned) on the
        ``cmu_mb`` rig, whatever this model's resolution."""
        full = self if self.mesh == "full" else MpfbModel(self.macro, self.clothes_cm, "full")
        return SkinnedMesh(full.rest.vertices_m, full.rest_normals, full.faces,
                           tuple(self.assets.bone_names),
                           tuple(int(p) for p in self.assets.bone_parents),
                           full.rest.bone_heads_m, self.assets.skin_weight_matrix)

    def skin_pose(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(B, 3, 3) each bone's parent_from_bone rotation and (3,) the root's displacement
        from rest: `skin`'s animation in ``pose``."""
        return self._rotations(pose, None)

    @classmethod
    def from_record(cls, record: dict[str, Any], mesh: str = "decimated") -> MpfbModel:
        """The subject a pose file's ``body`` (`record`) describes; ValueError when it does not."""
        try:
            macro = MacroShape(**{k: float(v) for k, v in dict(record["macro"]).items()})
            return cls(macro, float(record.get("clothes_cm", 0.0)), mesh)
        except (KeyError, TypeError) as exc:
            raise ValueError(f"not an mpfb body ({exc})") from None
