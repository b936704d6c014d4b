"""Protocols of every plugin kind, and the plain data they exchange with the pipeline.

A plugin of the pipeline's kinds (intrinsics, dense, mesh, renderer, body) is a class with:

- ``Options``: a keyword-only dataclass of its settings (each field documented with
  ``metadata={"help": ...}``), filled from ``-O key=value`` on the command line;
- ``description``: one line shown by ``mocap plugins``;
- a constructor taking one ``Options`` instance;
- the kind's method (for intrinsic initialisers, ``initialise``).

Plugins never write to the workspace: they return results and the pipeline applies them, so
that every plugin's output goes through the same atomic, recorded step.

Two kinds drive the pipeline instead, and are built without options: a :class:`Command` is a
``mocap`` subcommand, a :class:`BatchStep` one step of ``mocap batch``. Both are loaded to list
them (``mocap --help``, ``mocap plugins``), so their modules import only light things at top
level and the pipeline code inside their methods.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
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
    principal_point_px: tuple[float, float] | None = None
    """``(cx, cy)`` in pixels (COLMAP's convention, pixel centres at +0.5), or None to keep the
    camera's (COLMAP's default: the image centre). Held fixed by bundle adjustment."""


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
        ``tracking.rig.cameras.Camera`` (typed Any: plugins never depend on the tracking
        package) ->
        (camera.height, camera.width) bool mask, True where the pixel centre sees the mesh."""
        ...


@dataclass(frozen=True, kw_only=True)
class PosedBody:
    """A body model's surface and joints in one pose (world frame, metres, Y up)."""

    vertices: Any
    """(V, 3) float: a closed triangle mesh's vertices."""
    faces: Any
    """(F, 3) int: its triangles, outward-facing."""
    joints: Any
    """(16, 3) float: the joint centres, in the order of ``tracking.body.model.NODE_NAMES``
    (pelvis, spine, neck, shoulders, elbows, hips, knees, head_top, wrists, ankles)."""


@runtime_checkable
class BodyModelPlugin(Protocol):
    """A human body model that a pose of the thesis' layout drives (``tracking.body.model``:
    root translation and rotation, spine and neck flexion, shoulders and hips as ball joints,
    elbows and knees as hinges; the rest pose upright, arms hanging, facing +Z)."""

    Options: ClassVar[type]
    description: ClassVar[str]

    def posed(self, pose: Any, skeleton: Any) -> PosedBody:
        """``pose`` a ``tracking.body.model.Pose``; ``skeleton`` the
        ``tracking.body.model.BodyShape`` the pose was retargeted to (a model of its own shape
        uses it only to stand the subject on the same floor) -> the posed body."""
        ...

    def tracking_model(self, height_m: float) -> Any:
        """The model the silhouette tracker starts from for a subject of this stature: an
        object with the interface of ``tracking.body.model.TrackedModel``."""
        ...

    def subject_record(self) -> dict[str, Any]:
        """The pose file's ``body`` entry of the subject this plugin renders (``mocap synth``'s
        gt/pose.json), which ``model_from_record`` reads: ``--init-pose gt/pose.json``."""
        ...

    def model_from_record(self, record: Mapping[str, Any], skeleton: Any) -> Any:
        """The tracking model that a pose file describes: ``record`` its ``body`` entry (the
        model's ``record()``), ``skeleton`` its ``shape`` (a ``BodyShape``). ValueError when
        the record does not describe one of this plugin's models."""
        ...


@runtime_checkable
class Command(Protocol):
    """One ``mocap`` subcommand; its name is its entry point's name (group ``mocap.commands``).

    ``mocap --help`` imports every command's module to list its ``help``, so a command imports
    what it runs inside ``add_arguments`` and ``run``, never at module level.
    """

    help: ClassVar[str]
    """One line, listed by ``mocap --help``."""
    description: ClassVar[str]
    """The paragraph of ``mocap NAME --help`` ("" for none)."""
    # Optional: ``writes_workspace: ClassVar[bool] = False`` for a command whose ``workspace``
    # argument it only reads. Otherwise `mocap` holds that workspace's lock while it runs
    # (:func:`recon.workspace.workspace_lock`), and a second writer is refused.

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Add the command's flags to its own parser (built only when it is invoked)."""
        ...

    def run(self, args: argparse.Namespace) -> None:
        """Do the work and print the outcome; raise ``UserError`` or ``PluginError`` for a
        one-line error (exit code 2)."""
        ...


@dataclass(frozen=True, kw_only=True)
class StepResult:
    summary: Mapping[str, Any]
    """JSON-serialisable figures of the step (as its run record stores them)."""
    reused: bool = False
    """Whether the workspace already held the step's up-to-date outputs."""


ItemMap = Callable[..., list[Any]]
"""``map_fn(fn, items, *shared) -> [fn(item, *shared) for item in items]``, in input order,
however it runs them (``mocap batch`` runs them as Dask tasks)."""


@runtime_checkable
class BatchStep(Protocol):
    """One step of ``mocap batch``; its name is its entry point's name (group ``mocap.steps``).

    A workspace kind's pipeline is the chain of the steps of that kind, each after the one it
    ``follows``: registering steps of a kind, or one following the last step of a pipeline,
    extends ``mocap batch`` with no change to it. Instances travel to the workers with their
    tasks, so they are small and picklable.
    """

    description: ClassVar[str]
    workspace: ClassVar[str]
    """The kind of workspace it applies to, as the workspace contract names them ("photo":
    made with ``mocap init``; "video": has cameras.json); skipped with a reason on others."""
    follows: ClassVar[str | None]
    """The step it runs after in its kind's pipeline, or None for the first."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Add the flags of its settings to ``mocap batch``'s parser."""
        ...

    def settings(self, args: argparse.Namespace | None) -> Any:
        """Its settings (picklable) from ``mocap batch``'s flags; None: the defaults."""
        ...

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        """Run on one workspace through its run record: idempotent, reusing up-to-date
        outputs unless ``overwrite``. Raises ``UserError`` for the workspace's own failures."""
        ...

    def skip_reason(self, workspace: Path) -> str | None:
        """Why it does not apply to this workspace of its kind (nothing fails), or None."""
        ...

    def fan_out(self, map_fn: ItemMap) -> AbstractContextManager[None]:
        """A block within which ``run`` hands its independent items (stereo pairs, cameras)
        to ``map_fn``; results must not depend on it."""
        ...

    def figure(self, summary: Mapping[str, Any]) -> str:
        """A short figure of its result for the batch report (``"[120 faces]"``), or ""."""
        ...


class BaseBatchStep:
    """Optional base class of batch steps: no flags, default settings None, always applies,
    nothing to fan out, no figure."""

    description: ClassVar[str]
    workspace: ClassVar[str]
    follows: ClassVar[str | None] = None

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        return None

    def settings(self, args: argparse.Namespace | None) -> Any:
        return None

    def skip_reason(self, workspace: Path) -> str | None:
        return None

    def fan_out(self, map_fn: ItemMap) -> AbstractContextManager[None]:
        return contextlib.nullcontext()

    def figure(self, summary: Mapping[str, Any]) -> str:
        return ""
