"""recon's `mocap` subcommands (plugin kind ``command``): init, sfm, dense, mesh, run, batch,
compare, experiment, view, plugins.

Registered in ``pyproject.toml`` under ``mocap.commands`` like any third-party command. Each
parses its flags and calls one library function. `mocap --help` imports this module to list the
commands, so it imports the pipeline only inside the methods.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from recon.configs import add_config_arguments, config_from_args
from recon.errors import UserError

if TYPE_CHECKING:
    from recon.workspace import Workspace


def add_workspace_arguments(parser: argparse.ArgumentParser, *, images: bool = False) -> None:
    """The arguments of a command that works on a workspace: WS, optionally --images, and
    --overwrite."""
    parser.add_argument("workspace", type=Path, metavar="WS", help="workspace folder")
    if images:
        parser.add_argument(
            "--images",
            type=Path,
            metavar="DIR",
            help="create the workspace from this photo folder first (as `mocap init`)",
        )
    parser.add_argument("--overwrite", action="store_true", help="recompute every step")


def create_workspace(root: Path, images: Path, *, copy: bool = False,
                     overwrite: bool = False) -> Workspace:
    """`Workspace.create`, with its notes on skipped files on stderr."""
    from recon.workspace import Workspace

    ws, notes = Workspace.create(root, images, copy=copy, overwrite=overwrite)
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    return ws


def _workspace_of(args: argparse.Namespace) -> Workspace:
    """WS, made from --images first when given."""
    from recon.workspace import Workspace

    if args.images is not None:
        return create_workspace(args.workspace, args.images)
    return Workspace.open(args.workspace)


class InitCommand:
    help = "make a workspace from a folder of photos"
    description = ("Make a workspace: photos are hard-linked (or copied) into WS/images, never "
                   "modified. Non-image files are skipped.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("workspace", type=Path, metavar="WS", help="workspace folder to create")
        parser.add_argument("--images", type=Path, required=True, metavar="DIR",
                            help="folder of photos (searched recursively)")
        parser.add_argument("--copy", action="store_true", help="copy instead of hard-linking")
        parser.add_argument(
            "--overwrite",
            action="store_true",
            help="replace the images of an existing workspace (derived files are removed)",
        )

    def run(self, args: argparse.Namespace) -> None:
        ws = create_workspace(args.workspace, args.images, copy=args.copy,
                              overwrite=args.overwrite)
        print(f"workspace {ws.root}: {len(ws.image_names())} images in {ws.images_dir}")


class SfmCommand:
    help = "sparse reconstruction: features, matching, mapping, BA"
    description = ("COLMAP structure from motion on the workspace photos. Writes "
                   "WS/database.db, WS/sparse/0 and WS/logs/*.rrd; finished steps are reused "
                   "unless their settings change or --overwrite is given.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.sfm.pipeline import SfMConfig

        add_workspace_arguments(parser, images=True)
        add_config_arguments(parser, SfMConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.sfm.pipeline import SfMConfig, run_sfm

        config = config_from_args(SfMConfig, args)
        summary = run_sfm(_workspace_of(args), config, overwrite=args.overwrite)
        print("\n".join(summary.lines()))


class DenseCommand:
    help = "dense coloured point cloud from the sparse model (CPU)"
    description = ("Undistort the registered photos (downscaled to --dense-max-image-size), run "
                   "the dense backend (default cpu-stereo: rectified stereo on neighbour pairs, "
                   "left-right and multi-view depth checks) and fuse into WS/dense/fused.ply, "
                   "with normals and colours.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.dense.step import DenseConfig

        add_workspace_arguments(parser)
        add_config_arguments(parser, DenseConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.dense.step import DenseConfig, densify
        from recon.workspace import Workspace

        ws = Workspace.open(args.workspace)
        record = densify(ws, config_from_args(DenseConfig, args), overwrite=args.overwrite)
        print(
            f"dense cloud  {ws.dense_cloud_path}  ({record.summary['points']} points, "
            f"{record.seconds:.1f} s)"
        )
        for note in record.summary.get("notes", []):
            print(f"note         {note}")


class MeshCommand:
    help = "coloured mesh from the dense cloud (PLY, OBJ, GLB)"
    description = ("Mesh WS/dense/fused.ply (default: screened Poisson, trimmed to the cloud), "
                   "clean it with pymeshlab and write WS/mesh/mesh.ply, mesh.obj (Blender) and "
                   "mesh.glb (web).")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.mesh.step import MeshConfig

        add_workspace_arguments(parser)
        add_config_arguments(parser, MeshConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.mesh.step import MeshConfig, make_mesh, mesh_paths
        from recon.workspace import Workspace

        ws = Workspace.open(args.workspace)
        record = make_mesh(ws, config_from_args(MeshConfig, args), overwrite=args.overwrite)
        print(
            f"mesh         {record.summary['vertices']} vertices, {record.summary['faces']} faces"
            f" ({record.seconds:.1f} s)"
        )
        for path in mesh_paths(ws).values():
            print(f"             {path}")


class RunCommand:
    help = "photos → sparse model → dense cloud → mesh, in one go"
    description = ("`mocap sfm`, `mocap dense` and `mocap mesh` in a row; each step resumes "
                   "from what the workspace holds.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.dense.step import DenseConfig
        from recon.mesh.step import MeshConfig
        from recon.sfm.pipeline import SfMConfig

        add_workspace_arguments(parser, images=True)
        add_config_arguments(parser, SfMConfig, exclude=("num_threads",))
        add_config_arguments(parser, DenseConfig)
        add_config_arguments(parser, MeshConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.dense.step import DenseConfig, densify
        from recon.mesh.step import MeshConfig, make_mesh, mesh_paths
        from recon.sfm.pipeline import SfMConfig, run_sfm

        ws = _workspace_of(args)
        summary = run_sfm(ws, config_from_args(SfMConfig, args), overwrite=args.overwrite)
        print("\n".join(summary.lines()[:-1]))
        dense = densify(ws, config_from_args(DenseConfig, args), overwrite=args.overwrite)
        print(
            f"dense       {dense.summary['points']} points ({dense.seconds:.1f} s)  "
            f"{ws.dense_cloud_path}"
        )
        mesh = make_mesh(ws, config_from_args(MeshConfig, args), overwrite=args.overwrite)
        print(
            f"mesh        {mesh.summary['vertices']} vertices, {mesh.summary['faces']} faces "
            f"({mesh.seconds:.1f} s)  {mesh_paths(ws)['ply']}"
        )
        print(f"view        mocap view {ws.root}")


class BatchCommand:
    help = ("many workspaces' steps (those `mocap plugins` lists as steps: sfm, dense, mesh; "
            "silhouettes, track, report) as tasks on a Dask cluster")
    description = ("Run the steps of every workspace as Dask tasks: on a LocalCluster sized to "
                   "this machine, or on a running scheduler (--scheduler). Dense stereo pairs, "
                   "each camera's background model and each run of its frames' silhouettes are "
                   "tasks of their own; tracking and the report run as one task per sequence. "
                   "A failed workspace is reported and the others go on; a re-run reuses "
                   "every finished step. Workspaces must be on a file system that every "
                   "worker sees at the same path.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.batch import add_step_arguments

        parser.add_argument("workspaces", type=Path, nargs="+", metavar="WS",
                            help="workspace folders (made with `mocap init`, `mocap init-video` "
                            "or `mocap synth`)")
        # --steps, --overwrite, where the tasks run, then every registered step's settings.
        add_step_arguments(parser)

    def run(self, args: argparse.Namespace) -> None:
        from recon.batch import BatchConfig, parse_steps, registered_steps, run_batch, step_settings

        steps = registered_steps()
        report = run_batch(
            args.workspaces,
            config_from_args(BatchConfig, args, steps=parse_steps(args.batch_steps, steps)),
            step_settings(args, steps),
            overwrite=args.overwrite,
            echo=print,
        )
        print("\n".join(report.lines()))
        if report.failed:
            raise UserError(f"{len(report.failed)} of {len(report.results)} workspaces failed")


class CompareCommand:
    help = "every focal initialiser on the same matches, vs truth"
    description = ("Run each intrinsic initialiser (Kruppa, Kruppa + BA, COLMAP default + BA, "
                   "view-graph calibration, with and without BA, EXIF when present) on the same "
                   "features and matches, each in WS/compare/<method>, and report focal length, "
                   "error against --gt, registered images, reprojection error and time. Writes "
                   "WS/compare/{comparison.json, report.md, pairs.png, errors.png} and "
                   "WS/logs/compare.rrd.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.calibration.compare import CompareConfig
        from recon.sfm.pipeline import SfMConfig

        add_workspace_arguments(parser)
        add_config_arguments(parser, CompareConfig)
        add_config_arguments(parser, SfMConfig,
                             exclude=("intrinsics", "intrinsics_options", "refine_focal"))

    def run(self, args: argparse.Namespace) -> None:
        from recon.calibration.compare import CompareConfig, compare_intrinsics
        from recon.sfm.pipeline import SfMConfig
        from recon.workspace import Workspace

        ws = Workspace.open(args.workspace)
        sfm = config_from_args(SfMConfig, args)
        comparison = compare_intrinsics(
            ws, sfm, config_from_args(CompareConfig, args), overwrite=args.overwrite
        )
        print("\n".join(comparison.lines()))


class ExperimentCommand:
    help = "reproduce the thesis' experiments"
    description = ("Reproducible experiments from the thesis, with tables and plots written to "
                   "--out.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from recon.calibration.experiment import KruppaNoiseConfig

        experiments = parser.add_subparsers(dest="experiment", required=True,
                                            metavar="EXPERIMENT")
        q = experiments.add_parser(
            "kruppa-noise",
            help="focal error against image noise on the thesis' synthetic scene",
            description="Two planar grids of 120 points meeting at 135°, f = 600 px, 640x480; "
            "Gaussian noise on the image points, many trials per level; relative focal error "
            "of the Kruppa estimate against σ, for a tilted (generic) and a coplanar-axes "
            "(singular) second camera. Writes table.csv, report.md, error_vs_noise.png and "
            "results.json.",
        )
        add_config_arguments(q, KruppaNoiseConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.calibration.experiment import KruppaNoiseConfig, run_kruppa_noise

        # kruppa-noise is the only experiment (argparse refuses any other name).
        report = run_kruppa_noise(config_from_args(KruppaNoiseConfig, args))
        print("\n".join(report.lines()))


class ViewCommand:
    help = "open the workspace's recordings in the Rerun viewer"
    description = ""
    writes_workspace = False

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("workspace", type=Path, metavar="WS", help="workspace folder")
        parser.add_argument("--bind", metavar="ADDRESS", default="127.0.0.1",
                            help="address the viewer's server listens on (default: 127.0.0.1, "
                                 "this machine only; 0.0.0.0 serves every network interface)")

    def run(self, args: argparse.Namespace) -> None:
        from recon.recording import open_viewer
        from recon.workspace import Workspace

        ws = Workspace.open(args.workspace)
        recordings = ws.recordings()
        if not recordings:
            raise UserError(f"{ws.logs_dir} holds no recordings yet; run `mocap sfm {ws.root}`")
        command = open_viewer(recordings, bind=args.bind)
        if command is None:
            print(f"opened {len(recordings)} recording(s) in the Rerun viewer")
        else:
            print("no display here; open the recordings on a machine with one:")
            print("  " + shlex.join(command))
            print("or serve them to a browser:  "
                  + shlex.join([command[0], "--web-viewer", *command[1:]]))


class PluginsCommand:
    help = "list every registered plugin of every kind"
    description = ""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        return None

    def run(self, args: argparse.Namespace) -> None:
        from plugins.registry import KINDS, list_plugins

        infos = list_plugins()
        for kind, spec in KINDS.items():
            print(f"{kind} ({spec.group}): {spec.summary}")
            print(f"  {spec.how_to_use()}")
            for info in (i for i in infos if i.kind == kind):
                print(f"  {info.name:<18} {info.description}")
                print(f"  {'':<18} {info.target}  [{info.distribution}]")
                for name, kind_text, help_text in info.options:
                    print(f"  {'':<18}   {name}: {kind_text}  {help_text}")
