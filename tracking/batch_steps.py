"""The video workspace's batch steps (plugin kind ``step``): silhouettes → track → report.

Registered in ``pyproject.toml`` under ``mocap.steps``, as a third-party package registers its
own; `mocap batch` runs them on every workspace with cameras.json. `mocap plugins` and `mocap
batch --help` load every step, so this module imports the pipeline only inside the methods.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Mapping
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from plugins.protocols import BaseBatchStep, ItemMap, StepResult
from tracking.commands import add_silhouettes_arguments, silhouettes_config


class SilhouettesStep(BaseBatchStep):
    description = ("foreground masks of every camera's video frames; a task per camera's "
                   "background model, then per run of about 12 of its frames")
    workspace = "video"
    follows = None

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_silhouettes_arguments(parser)

    def settings(self, args: argparse.Namespace | None) -> Any:
        from tracking.silhouettes.step import SilhouettesConfig

        return SilhouettesConfig() if args is None else silhouettes_config(args)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from recon.workspace import Workspace
        from tracking.silhouettes.step import make_silhouettes

        ws = Workspace.open_video(workspace)
        before = ws.step("silhouettes")
        record = make_silhouettes(ws, settings, overwrite=overwrite)
        return StepResult(summary=record.summary, reused=before is not None and before == record)

    def skip_reason(self, workspace: Path) -> str | None:
        from recon.workspace import Workspace

        ws = Workspace(workspace)
        # `mocap synth` renders the silhouettes themselves: there are no videos to segment.
        if not ws.videos_dir.is_dir() and ws.run_json.is_file() and ws.step("synth") is not None:
            return "silhouettes given (synthetic)"
        return None

    def fan_out(self, map_fn: ItemMap) -> AbstractContextManager[None]:
        from tracking.silhouettes.step import cameras_mapped_by

        return cameras_mapped_by(map_fn)

    def figure(self, summary: Mapping[str, Any]) -> str:
        if "cameras" not in summary:
            return ""
        return f"[{len(summary['cameras'])} cameras x {summary['processed']} frames]"


class TrackStep(BaseBatchStep):
    description = ("silhouette tracking of the whole sequence, one task (sequential in time); "
                   "settings: the tracker's (`mocap track`'s frame range and start are the "
                   "defaults)")
    workspace = "video"
    follows = "silhouettes"

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.configs import add_config_arguments
        from tracking.track.tracker import TrackConfig

        # A batch task tracks on the core Dask gives it: `mocap batch --workers` is the
        # batch's, and the tracker forks no processes of its own (`TrackConfig.workers` 1).
        add_config_arguments(parser, TrackConfig, exclude=("workers",))

    def settings(self, args: argparse.Namespace | None) -> Any:
        """A `TrackConfig`, its `workers` 1."""
        from recon.configs import config_from_args
        from tracking.track.tracker import TrackConfig

        config = TrackConfig() if args is None else config_from_args(TrackConfig, args)
        return dataclasses.replace(config, workers=1)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from recon.workspace import Workspace
        from tracking.track.step import TrackStepConfig, track_workspace

        ws = Workspace.open_video(workspace)
        summary = track_workspace(ws, TrackStepConfig(), settings, overwrite=overwrite,
                                  progress=False)
        reused = bool(summary.pop("up_to_date", False))
        return StepResult(summary=summary, reused=reused)

    def figure(self, summary: Mapping[str, Any]) -> str:
        if "tracked" not in summary:
            return ""
        return f"[{summary['tracked']}/{summary['frames']} frames tracked]"


class ReportStep(BaseBatchStep):
    description = ("motion report of the tracked sequence (joint angles, centre of mass, joint "
                   "loads), one task; with silhouettes and track this is `mocap capture`'s "
                   "pipeline on every video workspace")
    workspace = "video"
    follows = "track"

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.configs import add_config_arguments
        from tracking.report.step import ReportConfig

        add_config_arguments(parser, ReportConfig, exclude=("truth", "metres_per_unit"))

    def settings(self, args: argparse.Namespace | None) -> Any:
        """A `ReportConfig`."""
        from recon.configs import config_from_args
        from tracking.report.step import ReportConfig

        return ReportConfig() if args is None else config_from_args(ReportConfig, args)

    def run(self, workspace: Path, settings: Any, *, overwrite: bool) -> StepResult:
        from tracking.report.step import report_from_workspace

        result = report_from_workspace(workspace, settings, overwrite=overwrite)
        return StepResult(summary=result.summary, reused=result.reused)

    def figure(self, summary: Mapping[str, Any]) -> str:
        if "frames" not in summary:
            return ""
        return f"[{summary['frames']} frames reported]"
