"""The ``view-graph`` intrinsic initialiser: COLMAP's own focal calibration from the view graph.

Wraps ``pycolmap.calibrate_view_graph`` (a robust iterative fit of focal lengths to all
fundamental matrices, after Fetzer et al. 2020). That call rewrites cameras and two-view
geometries in place, so, as COLMAP advises, it runs on a scratch copy of the database and only
the focal lengths come back.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from plugins.protocols import FocalPrior, IntrinsicsContext, IntrinsicsResult, Plugin


class ViewGraphInitialiser(Plugin):
    description = "COLMAP's calibrate_view_graph: focal lengths fitted to all F's (on a copy)"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        refine: bool = field(
            default=True, metadata={"help": "let bundle adjustment refine the calibrated focal"}
        )
        seed: int = field(default=0, metadata={"help": "random seed of the robust fit"})

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        focal, ok = calibrate_view_graph_copy(context.database_path, seed=self.options.seed)
        priors, notes = [], []
        for camera in context.cameras:
            value = focal.get(camera.camera_id) if ok else None
            if value is None:
                notes.append(
                    f"view-graph: camera {camera.camera_id} not calibrated; "
                    "falling back to COLMAP's default focal"
                )
            priors.append(
                FocalPrior(
                    camera_id=camera.camera_id,
                    focal_px=value,
                    source="calibrate_view_graph" if value else "1.2·max(w, h) (view-graph failed)",
                )
            )
        return IntrinsicsResult(
            priors=tuple(priors), refine_focal=self.options.refine, notes=tuple(notes)
        )


def calibrate_view_graph_copy(
    database_path: Path, *, seed: int = 0
) -> tuple[dict[int, float], bool]:
    """Focal per camera id from ``calibrate_view_graph`` run on a copy; and whether it succeeded.

    Existing focal priors are cleared on the copy first: COLMAP holds cameras with a prior fixed,
    and an initialiser must not depend on what an earlier one wrote.
    """
    # Imported here: `mocap plugins` imports this module only to describe the plugin.
    import pycolmap

    with tempfile.TemporaryDirectory(prefix="mocap-view-graph-") as tmp:
        copy = Path(tmp) / "database.db"
        shutil.copy2(database_path, copy)
        with pycolmap.Database.open(copy) as db:
            for camera in db.read_all_cameras():
                camera.focal_length = 1.2 * max(camera.width, camera.height)
                camera.has_prior_focal_length = False
                db.update_camera(camera)
        options = pycolmap.ViewGraphCalibrationOptions()
        options.random_seed = seed
        ok = bool(pycolmap.calibrate_view_graph(copy, options))
        with pycolmap.Database.open(copy) as db:
            focal = {
                c.camera_id: float(c.focal_length)
                for c in db.read_all_cameras()
                if c.has_prior_focal_length
            }
    return focal, ok
