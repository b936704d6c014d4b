"""The body models shipped with mocap, as ``mocap.body`` plugins (`plugins.protocols`).

* ``superquadric``: the thesis' generic model (`tracking.body.model`): 29 rigid superquadric
  segments on the skeleton the pose was retargeted to, so its shape is the driving clip's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from plugins.protocols import Plugin, PosedBody

if TYPE_CHECKING:  # `mocap plugins` lists this module: the model is imported when used
    from tracking.body.model import BodyModel, BodyShape, Pose


class SuperquadricBody(Plugin):
    """The thesis' model: rigid superquadric segments on the given skeleton."""

    @dataclass(frozen=True, kw_only=True)
    class Options:
        pass

    description: ClassVar[str] = ("the thesis' generic model: 29 rigid superquadric segments "
                                  "on the clip's own skeleton")

    def __init__(self, options: Options) -> None:
        super().__init__(options)
        self._model: Any = None

    def model(self, skeleton: BodyShape) -> BodyModel:
        """The meshed body of ``skeleton`` (the last one is kept)."""
        from tracking.body.model import BodyModel

        if self._model is None or self._model.shape != skeleton:
            self._model = BodyModel(skeleton)
        return self._model

    def posed(self, pose: Pose, skeleton: BodyShape) -> PosedBody:
        model = self.model(skeleton)
        return PosedBody(vertices=model.posed_vertices(pose), faces=model.faces,
                         joints=model.joints(pose))

    def tracking_model(self, height_m: float) -> BodyModel:
        """The tracker's start: `BodyShape.default`'s proportions of this stature."""
        from tracking.body.model import BodyModel, BodyShape

        return BodyModel(BodyShape.default(height_m))

    def subject_record(self) -> dict[str, Any]:
        """The rendered subject's pose-file entry: its shape is the pose file's skeleton."""
        return {"name": "superquadric"}

    def model_from_record(self, record: dict[str, Any], skeleton: BodyShape) -> BodyModel:
        """The model of a pose file: its shape is the skeleton itself."""
        from tracking.body.model import BodyModel

        return BodyModel(skeleton)
