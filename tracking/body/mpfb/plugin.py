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

from plugins.protocols import Plugin, PosedBody
from plugins.registry import PluginError

if TYPE_CHECKING:  # `mocap plugins` lists this module: the model is imported when used
    from tracking.body.model import BodyShape, Pose

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
        from tracking.body.mpfb.model import MacroShape
        from tracking.body.mpfb.subject import MpfbModel

        super().__init__(options)
        macro = {f.name: getattr(options, f.name) for f in dataclasses.fields(MacroShape)}
        try:
            self.model = MpfbModel(MacroShape(**macro), options.clothes_cm, options.mesh)
        except ValueError as exc:
            raise PluginError(f"body plugin 'mpfb': {exc}") from None

    @property
    def assets(self) -> Any:
        return self.model.assets

    def posed(self, pose: Pose, skeleton: BodyShape) -> PosedBody:
        from tracking.body.mpfb.model import named_joints

        body = self.model.posed_body(pose, skeleton)
        return PosedBody(vertices=body.vertices_m, faces=self.model.faces,
                         joints=named_joints(self.model.assets, body))

    def tracking_model(self, height_m: float) -> Any:
        """The tracker's start: MakeHuman's average subject of this stature, decimated,
        unclothed (`tracking.body.mpfb.subject.MpfbModel.of_height`); this plugin's own
        options describe a subject to render, not the tracker's guess."""
        from tracking.body.mpfb.subject import MpfbModel

        return MpfbModel.of_height(height_m)

    def subject_record(self) -> dict[str, Any]:
        """The rendered subject's macro shape and clothing (`MpfbModel.record`)."""
        return self.model.record()

    def model_from_record(self, record: dict[str, Any], skeleton: BodyShape) -> Any:
        """The tracking model a pose file's ``body`` entry describes (ValueError if it does
        not); ``skeleton``, the file's shape, follows from it."""
        from tracking.body.mpfb.subject import MpfbModel

        return MpfbModel.from_record(record)

    def __getstate__(self) -> dict[str, Any]:  # the arrays reload from the package data
        return {"options": self.options}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["options"])
