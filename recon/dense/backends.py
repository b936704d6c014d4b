"""Built-in dense backends (plugin kind ``dense``).

Registered in ``pyproject.toml`` under ``mocap.dense`` like any third-party plugin. The heavy
lifting lives in :mod:`recon.dense.stereo` and :mod:`recon.dense.fusion`; these classes adapt
them to the plugin Protocol. pycolmap, like them, is imported where it is used: `mocap plugins`
imports this module only to describe the backends.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from plugins.protocols import DenseContext, DenseResult, Plugin
from recon.errors import UserError
from recon.progress import bar


def load_views(undistorted_dir: Path) -> list[Any]:
    """The registered views of an undistorted COLMAP workspace, with their sparse points."""
    import cv2
    import pycolmap

    from recon.dense.stereo import View

    model = pycolmap.Reconstruction(undistorted_dir / "sparse")
    views = []
    for image in sorted(model.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            continue
        camera = model.cameras[image.camera_id]
        path = undistorted_dir / "images" / image.name
        pixels = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if pixels is None:
            raise UserError(f"cannot read undistorted image {path}")
        seen = [p.point3D_id for p in image.points2D if p.has_point3D()]
        points = (np.array([model.points3D[i].xyz for i in seen]) if seen
                  else np.empty((0, 3)))
        views.append(View(name=image.name, K=camera.calibration_matrix(),
                          cam_from_world=image.cam_from_world().matrix(), image_bgr=pixels,
                          points_in_world=points))
    return views


PairMap = Callable[..., list[Any]]
"""``map_fn(fn, items, *shared)`` returning ``[fn(item, *shared) for item in items]`` in input
order, however it runs them (:func:`recon.batch.map_ordered` runs them as Dask tasks)."""

# Unset (None) in a plain run: the stereo pairs run one after another in this process.
_stereo_pair_map: contextvars.ContextVar[PairMap | None] = contextvars.ContextVar(
    "stereo_pair_map", default=None)


@contextlib.contextmanager
def stereo_pairs_mapped_by(map_fn: PairMap) -> Iterator[None]:
    """Within this block, :class:`CpuStereoBackend` hands its stereo pairs to ``map_fn``.

    A context variable rather than a plugin option: the dense step creates the backend from
    its name, and how pairs are scheduled changes no result (``map_fn`` keeps pair order).
    """
    token = _stereo_pair_map.set(map_fn)
    try:
        yield
    finally:
        _stereo_pair_map.reset(token)


def stereo_pair_depths(pair: tuple[int, int], views: Sequence[Any], config: Any) -> tuple[Any, Any]:
    """Both depth maps of one stereo pair ``(ref, src)`` of ``views``: one independent task."""
    from recon.dense.stereo import depths_from_pair

    ref, src = pair
    return depths_from_pair(views[ref], views[src], config, ref_index=ref, src_index=src)


MAX_PAIRS_PER_VIEW = 8
"""Most stereo partners a view may have. Each pair keeps two float depth maps of the
undistorted size in memory until fusion (15 MB a pair at 1600x1200), and partners beyond the
nearest few see the surface at grazing angles that the fusion rejects anyway."""


class CpuStereoBackend(Plugin):
    description = ("rectified stereo on the CPU: neighbour pairs, OpenCV SGBM with a left-right "
                   "check, multi-view depth consistency, fused with normals")

    @dataclass(frozen=True, kw_only=True)
    class Options:
        max_pairs_per_view: int = field(
            default=2, metadata={"help": f"stereo partners per view, 1-{MAX_PAIRS_PER_VIEW} "
                                 "(each adds two depth maps per view, held in memory until "
                                 "fusion)"})
        min_consistent_views: int = field(
            # 1 (besides the stereo partner) was measured on the demo scene: F-score 0.906 ->
            # 0.920 at 1% of the extent, precision 1.000 and accuracy (8.5-8.7 mm) unchanged.
            default=1, metadata={"help": "views other than the stereo partner whose depth must "
                                 "agree with a point, >= 0 (lowered when there are too few "
                                 "views)"})
        rel_depth_tol: float = field(
            default=0.01, metadata={"help": "relative depth agreement between views, in (0, 1)"})

        def __post_init__(self) -> None:
            # Checked here, when the backend is made (before any work), not deep in stereo.
            if not 1 <= self.max_pairs_per_view <= MAX_PAIRS_PER_VIEW:
                raise ValueError(f"max_pairs_per_view must be in 1..{MAX_PAIRS_PER_VIEW}, got "
                                 f"{self.max_pairs_per_view}")
            if self.min_consistent_views < 0:
                raise ValueError(
                    f"min_consistent_views must be >= 0, got {self.min_consistent_views}")
            if not 0 < self.rel_depth_tol < 1:  # NaN fails too
                raise ValueError(f"rel_depth_tol must be in (0, 1), got {self.rel_depth_tol}")

    def densify(self, context: DenseContext) -> DenseResult:
        from recon.dense.fusion import FusionConfig, filter_consistent, fuse
        from recon.dense.stereo import StereoConfig, select_pairs

        views = load_views(context.undistorted_dir)
        if len(views) < 2:
            raise UserError(f"{context.undistorted_dir}: {len(views)} view(s); stereo needs 2")
        stereo = StereoConfig(max_pairs_per_view=self.options.max_pairs_per_view)
        pairs = select_pairs(views, stereo)
        if not pairs:
            raise UserError("no image pair has a usable baseline for stereo "
                            "(views too close together or too far apart)")
        depths = []
        map_pairs = _stereo_pair_map.get()
        if map_pairs is not None:
            for maps in map_pairs(stereo_pair_depths, pairs, views, stereo):
                depths += maps
        else:
            progress = bar(len(pairs), "stereo", "pair")
            for pair in pairs:
                # One rectification gives both views' depth maps.
                depths += stereo_pair_depths(pair, views, stereo)
                progress.update(1)
            progress.close()
        # Two photos have one pair, whose two depth maps agree by construction: no other view
        # can confirm a point, so only the left-right check filters them.
        needed = min(self.options.min_consistent_views, len(views) - 2)
        notes: tuple[str, ...] = ()
        if needed < self.options.min_consistent_views:
            notes = (f"only {len(views)} views: points are confirmed by {needed} other view(s)",)
        fusion = FusionConfig(min_consistent_views=needed, rel_depth_tol=self.options.rel_depth_tol)
        kept = filter_consistent(depths, views, fusion)
        cloud = fuse(kept, views, fusion)
        return DenseResult(cloud=cloud, notes=notes, stats={
            "views": len(views), "pairs": len(pairs),
            "depth_pixels": int(sum(np.isfinite(d.depth).sum() for d in depths)),
            "consistent_pixels": int(sum(np.isfinite(d.depth).sum() for d in kept)),
        })


class ColmapPatchMatchBackend(Plugin):
    description = "COLMAP's PatchMatch stereo and fusion (needs pycolmap built with CUDA)"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        pass

    def densify(self, context: DenseContext) -> DenseResult:
        import open3d as o3d
        import pycolmap

        if not pycolmap.has_cuda:
            raise UserError(
                "colmap-patchmatch needs pycolmap with CUDA (this one has none; on Linux with "
                "an NVIDIA GPU install pycolmap-cuda12); use --dense cpu-stereo, the default")
        pycolmap.patch_match_stereo(context.undistorted_dir)  # pragma: no cover - needs CUDA
        fused = context.scratch_dir / "fused.ply"  # pragma: no cover
        pycolmap.stereo_fusion(fused, context.undistorted_dir)  # pragma: no cover
        cloud = o3d.io.read_point_cloud(str(fused))  # pragma: no cover
        cloud.estimate_normals()  # pragma: no cover
        return DenseResult(cloud=cloud)  # pragma: no cover
