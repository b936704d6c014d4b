"""The photo workspace's batch steps (plugin kind ``step``): ``sfm`` → ``dense`` → ``mesh``.

Registered in ``pyproject.toml`` under ``mocap.steps`` like any third-party step. `mocap
plugins` and `mocap batch --help` load every step, so this module imports the pipeline only
inside the methods.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from plugins.protocols import BaseBatchStep, ItemMap, StepResult


class SfmStep(BaseBatchStep):
    description = "COLMAP structure from motion: features, matching, intrinsics, mapping, BA"
    workspace = "photo"
    follows = None

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.configs import add_config_arguments
        from recon.sfm.pipeline import SfMConfig

        # A batch task runs COLMAP on the threads Dask gives it, not on its own pool.
        add_config_arguments(parser, SfMConfig, exclude=("num_threads",))

    def settings(self, args: argparse.Namespace | None) -> Any:
        from recon.configs import config_from_args
        from recon.sfm.pipeline import SfMConfig

        return SfMConfig() if args is None else config_from_args(SfMConfig, args)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from recon.sfm.pipeline import STEPS
        from recon.workspace import Workspace

        ws = Workspace.open(workspace)
        # `run_sfm` without its deferred recordings: they would overlap mapping only to use a
        # core that a batch keeps busy anyway, and their read of the database, right as mapping
        # opens it, can fail with "database is locked" in a warm worker process (seen 1 in 32
        # workspaces under load; a fresh process is slowed by importing rerun).
        reused = True
        for name, sfm_step in STEPS:
            before = ws.step(name)
            record = sfm_step(ws, settings, overwrite=overwrite, recordings=None)
            reused = reused and before == record
        return StepResult(summary=record.summary, reused=reused)

    def figure(self, summary: Mapping[str, Any]) -> str:
        if "registered" not in summary:
            return ""
        return f"[{summary['registered']}/{summary['images']} images, {summary['points']} points]"


class DenseStep(BaseBatchStep):
    description = ("dense coloured point cloud from the sparse model; the cpu-stereo pairs as "
                   "tasks of their own")
    workspace = "photo"
    follows = "sfm"

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.configs import add_config_arguments
        from recon.dense.step import DenseConfig

        add_config_arguments(parser, DenseConfig)

    def settings(self, args: argparse.Namespace | None) -> Any:
        from recon.configs import config_from_args
        from recon.dense.step import DenseConfig

        return DenseConfig() if args is None else config_from_args(DenseConfig, args)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from recon.dense.step import densify
        from recon.workspace import Workspace

        ws = Workspace.open(workspace)
        before = ws.step("dense")
        record = densify(ws, settings, overwrite=overwrite)
        return StepResult(summary=record.summary, reused=before is not None and before == record)

    def fan_out(self, map_fn: ItemMap) -> AbstractContextManager[None]:
        from recon.dense.backends import stereo_pairs_mapped_by

        return stereo_pairs_mapped_by(map_fn)

    def figure(self, summary: Mapping[str, Any]) -> str:
        return f"[{summary['points']} points]" if "points" in summary else ""


class MeshStep(BaseBatchStep):
    description = "coloured mesh from the dense cloud (PLY, OBJ, GLB)"
    workspace = "photo"
    follows = "dense"

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.configs import add_config_arguments
        from recon.mesh.step import MeshConfig

        add_config_arguments(parser, MeshConfig)

    def settings(self, args: argparse.Namespace | None) -> Any:
        from recon.configs import config_from_args
        from recon.mesh.step import MeshConfig

        return MeshConfig() if args is None else config_from_args(MeshConfig, args)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from recon.mesh.step import make_mesh
        from recon.workspace import Workspace

        ws = Workspace.open(workspace)
        before = ws.step("mesh")
        record = make_mesh(ws, settings, overwrite=overwrite)
        return StepResult(summary=record.summary, reused=before is not None and before == record)

    def figure(self, summary: Mapping[str, Any]) -> str:
        return f"[{summary['faces']} faces]" if "faces" in summary else ""
