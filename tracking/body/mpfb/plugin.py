"""``mpfb``: the MakeHuman / MPFB2 body (CC0) as a ``mocap.body`` plugin (`plugins.protocols`).

The subject's shape is its own (MakeHuman's macro modifiers, the plugin's options), not the
skeleton the pose was retargeted to: a pose of the thesis' layout is put on MPFB2's ``cmu_mb``
rig (`tracking.body.mpfb.retarget`) and the skinned mesh follows
(`tracking.body.mpfb.model`). Rendered by `mocap synth --body mpfb`, it is a subject whose shape
and surface differ from the tracker's model, as a real person's do.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from plugins.protocols import Plugin, PosedBody
from plugins.registry import PluginError

if TYPE_CHECKING:  # `mocap plugins` lists this module: the model is imported when used
    from tracking.body.model import BodyShape, Pose

CLOTHED_BONES: tuple[str, ...] = (
    "Hips", "LHipJoint", "RHipJoint", "LowerBack", "Spine", "Spine1",
    "LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg")  # fmt: skip
"""The bones whose skin loose clothing covers: trunk, hips, thighs and shanks (not the arms,
the neck, the head, the hands or the feet)."""


def clothed(assets: Any, rest: Any, thickness_m: float) -> Any:
    """``rest`` (`tracking.body.mpfb.model.RestBody`) with the vertices that `CLOTHED_BONES`
    carry (by at least half of their skinning weight) pushed out along their normals by
    ``thickness_m``, fading to nothing where that weight falls from 1 to 0.5 (the waistband,
    the neckline, the cuffs)."""
    if thickness_m == 0.0:
        return rest
    from recon.mesh.normals import vertex_normals

    columns = [assets.bone(name) for name in CLOTHED_BONES]
    covered = assets.skin_weight_matrix[:, columns].sum(axis=1)
    fade = np.clip(2.0 * covered - 1.0, 0.0, 1.0)
    normals = vertex_normals(rest.vertices_m, assets.faces)
    vertices = rest.vertices_m + thickness_m * fade[:, None] * normals
    vertices.flags.writeable = False
    return dataclasses.replace(rest, vertices_m=vertices)


class MpfbBody(Plugin):
    """MakeHuman's CC0 body, skinned on the cmu_mb rig, shaped by its macro modifiers."""

    @dataclass(frozen=True, kw_only=True)
    class Options:
        gender: float = field(default=0.5, metadata={"help": "0 female .. 1 male"})
        age_years: float = field(default=25.0, metadata={"help": "age, 1 .. 90 years"})
        muscle: float = field(default=0.5, metadata={"help": "0 min .. 0.5 average .. 1 max"})
        weight: float = field(default=0.5, metadata={
            "help": "0 min .. 0.5 average .. 1 max (body fat and girths)"})
        height: float = field(default=0.5, metadata={
            "help": "0 min .. 0.5 as the other modifiers make it .. 1 max"})
        proportions: float = field(default=0.5, metadata={
            "help": "0 uncommon .. 0.5 regular .. 1 ideal body proportions"})
        clothes_cm: float = field(default=0.0, metadata={
            "help": "loose clothing: the trunk, the hips and the legs pushed out along their "
            "normals by this many centimetres (0 .. 10)"})
        mesh: str = field(default="full", metadata={
            "help": "'full' (the CC0 body, ~13,400 vertices) or 'decimated' (~2,500, its "
            "vertices a subset of the full body's)"})

    description: ClassVar[str] = ("MakeHuman / MPFB2's CC0 body: skinned mesh on the cmu_mb "
                                  "rig, shaped by gender, age, muscle, weight, height and "
                                  "proportions")

    def __init__(self, options: Options) -> None:
        from tracking.body.model import NODE_INDEX, BodyShape, Pose
        from tracking.body.mpfb.model import (
            MacroShape,
            load_assets,
            named_joints,
            posed_vertices,
            rest_body,
        )
        from tracking.body.mpfb.retarget import Rig, limb_corrections, rig_rotations

        super().__init__(options)
        if options.mesh not in ("full", "decimated"):
            raise PluginError(f"body plugin 'mpfb': mesh must be 'full' or 'decimated', got "
                              f"{options.mesh!r}")
        macro = {f.name: getattr(options, f.name) for f in dataclasses.fields(MacroShape)}
        try:
            self.shape = MacroShape(**macro)
        except ValueError as exc:
            raise PluginError(f"body plugin 'mpfb': {exc}") from None
        if not 0.0 <= options.clothes_cm <= 10.0:
            raise PluginError(f"body plugin 'mpfb': clothes_cm must be in 0..10, got "
                              f"{options.clothes_cm}")
        self.assets = load_assets()
        self.rest = clothed(self.assets, rest_body(self.assets, self.shape),
                            options.clothes_cm / 100.0)
        rig = Rig(self.assets.bone_names, np.asarray(self.assets.bone_parents),
                  self.rest.bone_heads_m, self.rest.bone_tails_m, 0.0)
        self.corrections = limb_corrections(rig)
        # The legs turned to hang straight reach lower than in MPFB's rest: the floor that
        # sets the hip height is the lowest vertex of the rest pose of ours (any skeleton).
        rotations, root = rig_rotations(rig, Pose.neutral(), BodyShape.default(),
                                        self.corrections)
        straight = posed_vertices(self.assets, self.rest, rotations, root)
        pelvis = named_joints(self.assets, straight)[NODE_INDEX["pelvis"]]
        floor_y = rig.hip_centre[1] - (pelvis[1] - straight.vertices_m[:, 1].min())
        self.rig = dataclasses.replace(rig, floor_y=float(floor_y))
        if options.mesh == "decimated":
            self.vertex_indices: np.ndarray | None = self.assets.decimated_vertex_indices
            self.faces = self.assets.decimated_faces
        else:
            self.vertex_indices, self.faces = None, self.assets.faces

    def posed(self, pose: Pose, skeleton: BodyShape) -> PosedBody:
        from tracking.body.mpfb.model import named_joints, posed_vertices
        from tracking.body.mpfb.retarget import rig_rotations

        rotations, root = rig_rotations(self.rig, pose, skeleton, self.corrections)
        body = posed_vertices(self.assets, self.rest, rotations, root,
                              vertex_indices=self.vertex_indices)
        return PosedBody(vertices=body.vertices_m, faces=self.faces,
                         joints=named_joints(self.assets, body))

    def __getstate__(self) -> dict[str, Any]:  # the arrays reload from the package data
        return {"options": self.options}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["options"])
