"""Protocols of every plugin kind, and the plain data they exchange with the pipeline.

A plugin is a class with:

- ``Options``: a keyword-only dataclass of its settings (each field documented with
  ``metadata={"help": ...}``), filled from ``-O key=value`` on the command line;
- ``description``: one line shown by ``mocap plugins``;
- a constructor taking one ``Options`` instance;
- the kind's method (for intrinsic initialisers, ``initialise``).

Plugins never write to the workspace: they return results and the pipeline applies them, so
that every plugin's output goes through the same atomic, recorded step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable


class Plugin:
    """Optional base class of plugins: keeps the parsed ``Options`` as ``self.options``.

    A plugin without options declares an empty ``Options`` dataclass.
    """

    Options: ClassVar[type]
    description: ClassVar[str]

    def __init__(self, options: Any) -> None:
        self.options = options


@dataclass(frozen=True, kw_only=True)
class CameraInfo:
    """One COLMAP camera of the database and the images that use it."""

    camera_id: int
    model: str
    width: int
    height: int
    image_names: tuple[str, ...]


@dataclass(frozen=True, kw_only=True)
class IntrinsicsContext:
    """What an intrinsic initialiser may read. It runs after matching and before mapping."""

    database_path: Path
    """COLMAP database with keypoints, matches and two-view geometries. Read it, never write."""
    images_dir: Path
    """Folder of the workspace images; names in ``cameras`` are relative to it."""
    cameras: tuple[CameraInfo, ...]


@dataclass(frozen=True, kw_only=True)
class FocalPrior:
    """Focal length to start mapping from, for one camera."""

    camera_id: int
    focal_px: float | None
    """Focal length in pixels, or None for COLMAP's default guess 1.2·max(w, h) (not a prior)."""
    source: str
    """How it was obtained, in words, for the run record and the summary."""


@dataclass(frozen=True, kw_only=True)
class IntrinsicsResult:
    priors: tuple[FocalPrior, ...]
    refine_focal: bool = True
    """Whether bundle adjustment may change the focal length."""
    notes: tuple[str, ...] = ()
    """Warnings or remarks for the user, one line each."""
    details: Mapping[str, Any] = field(default_factory=dict)
    """JSON-serialisable extra output (for example a per-pair table), stored in run.json."""


@runtime_checkable
class IntrinsicInitialiser(Protocol):
    """Sets each camera's focal prior in the database before incremental mapping."""

    Options: ClassVar[type]
    description: ClassVar[str]

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult: ...


@dataclass(frozen=True, kw_only=True)
class DenseContext:
    """What a dense backend reads: an undistorted COLMAP workspace and the run's settings."""

    undistorted_dir: Path
    """COLMAP's undistorted layout: ``images/`` and ``sparse/`` with PINHOLE cameras, possibly
    downscaled (``--max-image-size``)."""
    scratch_dir: Path
    """A folder the backend may write intermediate files to (depth maps, ...)."""
    num_threads: int = -1


@dataclass(frozen=True, kw_only=True)
class DenseResult:
    cloud: Any
    """``open3d.geometry.PointCloud`` in the sparse model's world frame, with colours and
    normals (oriented towards the cameras that saw each point)."""
    notes: tuple[str, ...] = ()
    stats: Mapping[str, Any] = field(default_factory=dict)
    """JSON-serialisable figures (pairs, points before/after filtering, seconds, ...)."""


@runtime_checkable
class DenseBackend(Protocol):
    """Turns a calibrated, undistorted image set into a dense coloured point cloud."""

    Options: ClassVar[type]
    description: ClassVar[str]

    def densify(self, context: DenseContext) -> DenseResult: ...


@runtime_checkable
class MeshBackend(Protocol):
    """Turns an oriented, coloured point cloud into a triangle mesh with vertex colours."""

    Options: ClassVar[type]
    description: ClassVar[str]

    def mesh(self, cloud: Any) -> Any:
        """``open3d.geometry.PointCloud`` in, ``open3d.geometry.TriangleMesh`` out."""
        ...


@runtime_checkable
class SilhouetteRenderer(Protocol):
    """Draws the silhouette of a closed triangle mesh as one calibrated camera sees it."""

    Options: ClassVar[type]
    description: ClassVar[str]

    def render(self, vertices_in_world: Any, faces: Any, camera: Any) -> Any:
        """vertices (V, 3) float in metres, faces (F, 3) int, ``camera`` a
        ``tracking.rig.cameras.Camera`` (typed Any: plugins must not import tracking) ->
        (camera.height, camera.width) bool mask, True where the pixel centre sees the mesh."""
        ...
