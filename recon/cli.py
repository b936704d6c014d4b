"""The `mocap` command. Each subcommand parses flags and calls one library function."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from recon.configs import add_config_arguments, config_from_args
from recon.errors import UserError

_EPILOG = """examples:
  mocap demo                                  synthetic scene → model, errors vs truth
  mocap init ws/temple --images photos/       make a workspace from a folder of photos
  mocap sfm ws/temple                         sparse model in ws/temple/sparse/0
  mocap run ws/statue --images photos/        photos → sparse → dense → mesh (PLY/OBJ/GLB)
  mocap batch ws/* --scheduler tcp://HOST:8786   many workspaces as tasks on a Dask cluster
  mocap sfm ws/temple --intrinsics fixed -O focal_px=1520
  mocap compare ws/temple --gt photos/templeSR_par.txt   focal initialisers vs truth
  mocap experiment kruppa-noise               the thesis' noise experiment, table + plot
  mocap fit --cloud person.ply --out DIR      fit the body model to a point cloud
  mocap synth ws/walk --bvh clip.bvh          synthetic multi-camera silhouettes + ground truth
  mocap init-video ws/demo --videos videos/ --calibration Calib.qca.txt   a video workspace
  mocap silhouettes ws/demo                   foreground masks of every video frame
  mocap track ws/walk                         silhouette tracking → tracks/*.csv, .json, .bvh
  mocap report ws/walk                        joint angles, COM, joint loads → report/
  mocap view ws/temple                        open the recordings in the Rerun viewer
  mocap plugins                               list the registered plugins
"""


def _cmd_init(args: argparse.Namespace) -> None:
    from recon.workspace import Workspace

    ws, notes = Workspace.create(
        args.workspace, args.images, copy=args.copy, overwrite=args.overwrite
    )
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"workspace {ws.root}: {len(ws.image_names())} images in {ws.images_dir}")


def _cmd_sfm(args: argparse.Namespace) -> None:
    from recon.sfm.pipeline import SfMConfig, run_sfm
    from recon.workspace import Workspace

    config = config_from_args(SfMConfig, args)
    if args.images is not None:
        ws, notes = Workspace.create(args.workspace, args.images)
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
    else:
        ws = Workspace.open(args.workspace)
    summary = run_sfm(ws, config, overwrite=args.overwrite)
    print("\n".join(summary.lines()))


def _cmd_dense(args: argparse.Namespace) -> None:
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


def _cmd_mesh(args: argparse.Namespace) -> None:
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


def _cmd_run(args: argparse.Namespace) -> None:
    from recon.dense.step import DenseConfig, densify
    from recon.mesh.step import MeshConfig, make_mesh, mesh_paths
    from recon.sfm.pipeline import SfMConfig, run_sfm
    from recon.workspace import Workspace

    if args.images is not None:
        ws, notes = Workspace.create(args.workspace, args.images)
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
    else:
        ws = Workspace.open(args.workspace)
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


def _cmd_batch(args: argparse.Namespace) -> None:
    from recon.batch import BatchConfig, parse_steps, run_batch
    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.track.tracker import TrackConfig

    report = run_batch(
        args.workspaces,
        config_from_args(BatchConfig, args, steps=parse_steps(args.batch_steps)),
        config_from_args(SfMConfig, args),
        config_from_args(DenseConfig, args),
        config_from_args(MeshConfig, args),
        overwrite=args.overwrite,
        echo=print,
        silhouettes=_silhouettes_config(args),
        track=config_from_args(TrackConfig, args),
    )
    print("\n".join(report.lines()))
    if report.failed:
        raise UserError(f"{len(report.failed)} of {len(report.results)} workspaces failed")


def _cmd_body(args: argparse.Namespace) -> None:
    from tracking.body.export import BodyExportConfig, export_body

    out = export_body(config_from_args(BodyExportConfig, args))
    print(f"body mesh  {out['mesh']}  ({out['vertices']} vertices, {out['faces']} faces)")
    print(f"joints     {out['joints']}")
    print(f"fit        {out['residual_mm']:.1f} mm RMS over the joints; "
          f"subject height {out['height_m']:.2f} m")


def _cmd_view(args: argparse.Namespace) -> None:
    from recon.recording import open_viewer
    from recon.workspace import Workspace

    ws = Workspace.open(args.workspace)
    recordings = ws.recordings()
    if not recordings:
        raise UserError(f"{ws.logs_dir} holds no recordings yet; run `mocap sfm {ws.root}`")
    command = open_viewer(recordings)
    if command is None:
        print(f"opened {len(recordings)} recording(s) in the Rerun viewer")
    else:
        print("no display here; open the recordings on a machine with one:")
        print("  " + shlex.join(command))
        print(
            "or serve them to a browser:  " + shlex.join([command[0], "--web-viewer", *command[1:]])
        )


def _cmd_plugins(args: argparse.Namespace) -> None:
    from plugins.registry import KINDS, list_plugins

    infos = list_plugins()
    for kind, spec in KINDS.items():
        print(f"{kind} ({spec.group}): {spec.summary}")
        print(f"  choose with {spec.choose_flag} NAME; options with {spec.option_flag} KEY=VALUE")
        for info in (i for i in infos if i.kind == kind):
            print(f"  {info.name:<18} {info.description}")
            print(f"  {'':<18} {info.target}  [{info.distribution}]")
            for name, kind_text, help_text in info.options:
                print(f"  {'':<18}   {name}: {kind_text}  {help_text}")


def _cmd_demo(args: argparse.Namespace) -> None:
    from recon.demo import DemoConfig, run_demo
    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig

    config = config_from_args(DemoConfig, args)
    report = run_demo(
        config,
        config_from_args(SfMConfig, args),
        config_from_args(DenseConfig, args),
        config_from_args(MeshConfig, args),
        overwrite=args.overwrite,
    )
    print("\n".join(report.lines()))


def _cmd_compare(args: argparse.Namespace) -> None:
    from recon.calibration.compare import CompareConfig, compare_intrinsics
    from recon.sfm.pipeline import SfMConfig
    from recon.workspace import Workspace

    ws = Workspace.open(args.workspace)
    sfm = config_from_args(SfMConfig, args)
    comparison = compare_intrinsics(
        ws, sfm, config_from_args(CompareConfig, args), overwrite=args.overwrite
    )
    print("\n".join(comparison.lines()))


def _cmd_report(args: argparse.Namespace) -> None:
    from tracking.report.step import ReportConfig, report_from_bvh, report_from_workspace

    config = config_from_args(ReportConfig, args)
    if (args.workspace is None) == (args.bvh is None):
        raise UserError("give either a workspace (mocap report WS) or --bvh FILE --out DIR")
    if args.bvh is not None:
        if args.out is None:
            raise UserError("--bvh needs --out DIR (the report goes to DIR/report/)")
        result = report_from_bvh(args.bvh, args.out, config, overwrite=args.overwrite)
    else:
        result = report_from_workspace(args.workspace, config, overwrite=args.overwrite)
    print("\n".join(result.lines()))


def _cmd_fit(args: argparse.Namespace) -> None:
    from recon.workspace import Workspace
    from tracking.fit.body_fit import FitConfig
    from tracking.fit.step import FitCloudConfig, SubjectConfig, fit_cloud_file, fit_workspace

    if (args.workspace is None) == (args.cloud is None):
        raise UserError("give either a workspace (mocap fit WS) or --cloud FILE.ply --out DIR")
    subject, config = config_from_args(SubjectConfig, args), config_from_args(FitConfig, args)
    if args.cloud is not None:
        result, paths = fit_cloud_file(config_from_args(FitCloudConfig, args), subject, config)
        summary = result.summary()
    else:
        ws = Workspace.open(args.workspace)
        summary, paths = fit_workspace(ws, subject, config, overwrite=args.overwrite)
    verdict = "fitted" if summary["success"] else "FAILED"
    print(f"body fit   {verdict}: {summary['message']}; median distance "
          f"{summary['residual_median']:.4g}, {summary['inlier_fraction']:.0%} inliers, "
          f"height {summary['height']:.3g}")
    for path in paths.values():
        print(f"           {path}")
    if not summary["success"]:
        raise UserError("the cloud does not look like one human body (see fit.json)")


def _cmd_init_video(args: argparse.Namespace) -> None:
    from tracking.rig.video import STEP, init_video

    ws = init_video(args.workspace, args.videos, args.calibration, match=args.match,
                    copy=args.copy, overwrite=args.overwrite)
    summary = ws.step(STEP).summary
    print(f"workspace {ws.root}: {len(summary['cameras'])} cameras x {summary['frames']} frames "
          f"at {summary['fps']:g} fps; {ws.cameras_path}, {ws.videos_dir}")
    for note in summary["notes"]:
        print(f"note: {note}", file=sys.stderr)


def _silhouettes_config(args: argparse.Namespace) -> Any:
    """`SilhouettesConfig` from the flags of `mocap silhouettes` (and `mocap batch`), with its
    nested threshold and multi-view check settings."""
    from tracking.silhouettes.hull import HullCheckConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.silhouettes.subtraction import SilhouetteConfig

    try:
        thresholds = config_from_args(SilhouetteConfig, args)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return config_from_args(SilhouettesConfig, args, thresholds=thresholds,
                            hull=config_from_args(HullCheckConfig, args))


def _cmd_silhouettes(args: argparse.Namespace) -> None:
    from recon.workspace import Workspace
    from tracking.silhouettes.step import make_silhouettes, summary_lines

    config = _silhouettes_config(args)
    ws = Workspace.open_video(args.workspace)
    print("\n".join(summary_lines(ws, make_silhouettes(ws, config, overwrite=args.overwrite))))


def _cmd_synth(args: argparse.Namespace) -> None:
    from tracking.rig.synth import SynthConfig, synthesize

    if args.bvh is None:
        raise UserError("--bvh FILE is required (the clip that drives the body)")
    result = synthesize(args.workspace, config_from_args(SynthConfig, args),
                        overwrite=args.overwrite)
    print("\n".join(result.lines()))


def _cmd_track(args: argparse.Namespace) -> None:
    from recon.workspace import Workspace
    from tracking.track.step import TrackStepConfig, track_workspace
    from tracking.track.tracker import TrackConfig

    step, config = config_from_args(TrackStepConfig, args), config_from_args(TrackConfig, args)
    ws = Workspace.open_video(args.workspace)
    summary = track_workspace(ws, step, config, overwrite=args.overwrite)
    note = " (up to date)" if summary.get("up_to_date") else ""
    print(f"track      {summary['tracked']}/{summary['frames']} frames tracked{note}; median "
          f"XOR {summary['median_xor_fraction']:.1%} of the silhouette; "
          f"{summary['seconds_per_frame']:.2f} s/frame; subject height "
          f"{summary['height_m']:.2f} m")
    if summary["lost"]:
        print(f"lost       frames {summary['lost']}")
    for frame, event in summary.get("events", {}).items():
        print(f"frame {frame:>5}: {event}")
    print(f"outputs    {ws.tracks_dir}/joints.csv, pose.json, motion.bvh; {ws.logs_dir}/track.rrd")


def _cmd_experiment_kruppa_noise(args: argparse.Namespace) -> None:
    from recon.calibration.experiment import KruppaNoiseConfig, run_kruppa_noise

    report = run_kruppa_noise(config_from_args(KruppaNoiseConfig, args))
    print("\n".join(report.lines()))


def _step_command(
    sub: argparse._SubParsersAction,
    name: str,
    *,
    help: str,
    description: str,
    images: bool = False,
) -> argparse.ArgumentParser:
    """A subcommand that works on a workspace: WS, optionally --images, and --overwrite."""
    p = sub.add_parser(name, help=help, description=description)
    p.add_argument("workspace", type=Path, metavar="WS", help="workspace folder")
    if images:
        p.add_argument(
            "--images",
            type=Path,
            metavar="DIR",
            help="create the workspace from this photo folder first (as `mocap init`)",
        )
    p.add_argument("--overwrite", action="store_true", help="recompute every step")
    return p


def build_parser() -> argparse.ArgumentParser:
    from recon.batch import BatchConfig
    from recon.calibration.compare import CompareConfig
    from recon.calibration.experiment import KruppaNoiseConfig
    from recon.demo import DemoConfig
    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.body.export import BodyExportConfig
    from tracking.fit.body_fit import FitConfig
    from tracking.fit.step import SubjectConfig
    from tracking.report.step import ReportConfig
    from tracking.rig.synth import SynthConfig
    from tracking.silhouettes.hull import HullCheckConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.silhouettes.subtraction import SilhouetteConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig

    parser = argparse.ArgumentParser(
        prog="mocap",
        description="Markerless 3D human motion capture: photos → calibrated cameras → "
        "models → tracking, with Rerun recordings of every step.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="show COLMAP's own log lines (hidden unless they are errors)",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "init",
        help="make a workspace from a folder of photos",
        description="Make a workspace: photos are hard-linked (or copied) into "
        "WS/images, never modified. Non-image files are skipped.",
    )
    p.add_argument("workspace", type=Path, metavar="WS", help="workspace folder to create")
    p.add_argument(
        "--images",
        type=Path,
        required=True,
        metavar="DIR",
        help="folder of photos (searched recursively)",
    )
    p.add_argument("--copy", action="store_true", help="copy instead of hard-linking")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the images of an existing workspace (derived files are removed)",
    )
    p.set_defaults(func=_cmd_init)

    p = _step_command(
        sub,
        "sfm",
        images=True,
        help="sparse reconstruction: features, matching, mapping, BA",
        description="COLMAP structure from motion on the workspace photos. "
        "Writes WS/database.db, WS/sparse/0 and WS/logs/*.rrd; finished steps "
        "are reused unless their settings change or --overwrite is given.",
    )
    add_config_arguments(p, SfMConfig)
    p.set_defaults(func=_cmd_sfm)

    p = _step_command(
        sub,
        "dense",
        help="dense coloured point cloud from the sparse model (CPU)",
        description="Undistort the registered photos (downscaled to "
        "--dense-max-image-size), run the dense backend (default cpu-stereo: "
        "rectified stereo on neighbour pairs, left-right and multi-view depth "
        "checks) and fuse into WS/dense/fused.ply, with normals and colours.",
    )
    add_config_arguments(p, DenseConfig)
    p.set_defaults(func=_cmd_dense)

    p = _step_command(
        sub,
        "mesh",
        help="coloured mesh from the dense cloud (PLY, OBJ, GLB)",
        description="Mesh WS/dense/fused.ply (default: screened Poisson, "
        "trimmed to the cloud), clean it with pymeshlab and write "
        "WS/mesh/mesh.ply, mesh.obj (Blender) and mesh.glb (web).",
    )
    add_config_arguments(p, MeshConfig)
    p.set_defaults(func=_cmd_mesh)

    p = _step_command(
        sub,
        "run",
        images=True,
        help="photos → sparse model → dense cloud → mesh, in one go",
        description="`mocap sfm`, `mocap dense` and `mocap mesh` in a row; "
        "each step resumes from what the workspace holds.",
    )
    add_config_arguments(p, SfMConfig, exclude=("num_threads",))
    add_config_arguments(p, DenseConfig)
    add_config_arguments(p, MeshConfig)
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "batch",
        help="many workspaces' steps (sfm, dense, mesh; silhouettes, track) as tasks on a "
        "Dask cluster",
        description="Run the steps of every workspace as Dask tasks: on a LocalCluster "
        "sized to this machine, or on a running scheduler (--scheduler). Dense stereo "
        "pairs, each camera's background model and each run of its frames' silhouettes are "
        "tasks of their own; tracking runs as one task per sequence. A failed workspace is "
        "reported and the others go on; a re-run reuses every finished step. Workspaces "
        "must be on a file system that every worker sees at the same path.",
    )
    p.add_argument("workspaces", type=Path, nargs="+", metavar="WS",
                   help="workspace folders (made with `mocap init`, `mocap init-video` or "
                   "`mocap synth`)")
    p.add_argument("--steps", dest="batch_steps", default=None, metavar="STEPS",
                   help="steps to run, comma-separated: sfm,dense,mesh (photo workspaces), "
                   "silhouettes,track (video workspaces); a step that does not apply to a "
                   "workspace is skipped (default: all steps of each workspace's kind)")
    p.add_argument("--overwrite", action="store_true", help="recompute every step")
    add_config_arguments(p, BatchConfig, exclude=("steps",))
    add_config_arguments(p, SfMConfig, exclude=("num_threads",))
    add_config_arguments(p, DenseConfig)
    add_config_arguments(p, MeshConfig)
    # Video workspaces: the settings of `mocap silhouettes` and `mocap track`.
    add_config_arguments(p, SilhouettesConfig, exclude=("thresholds", "hull"))
    add_config_arguments(p, SilhouetteConfig)
    add_config_arguments(p, HullCheckConfig)
    add_config_arguments(p, TrackConfig)
    p.set_defaults(func=_cmd_batch)

    p = _step_command(
        sub,
        "compare",
        help="every focal initialiser on the same matches, vs truth",
        description="Run each intrinsic initialiser (Kruppa, Kruppa + BA, COLMAP "
        "default + BA, view-graph calibration, with and without BA, EXIF when "
        "present) on the same features and matches, each in WS/compare/<method>, "
        "and report focal length, error against --gt, registered images, "
        "reprojection error and time. Writes WS/compare/{comparison.json, "
        "report.md, pairs.png, errors.png} and WS/logs/compare.rrd.",
    )
    add_config_arguments(p, CompareConfig)
    add_config_arguments(p, SfMConfig, exclude=("intrinsics", "intrinsics_options", "refine_focal"))
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser(
        "experiment",
        help="reproduce the thesis' experiments",
        description="Reproducible experiments from the thesis, with tables and "
        "plots written to --out.",
    )
    experiments = p.add_subparsers(dest="experiment", required=True, metavar="EXPERIMENT")
    q = experiments.add_parser(
        "kruppa-noise",
        help="focal error against image noise on the thesis' synthetic scene",
        description="Two planar grids of 120 points meeting at 135°, f = 600 px, 640x480; "
        "Gaussian noise on the image points, many trials per level; relative focal error of "
        "the Kruppa estimate against σ, for a tilted (generic) and a coplanar-axes (singular) "
        "second camera. Writes table.csv, report.md, error_vs_noise.png and results.json.",
    )
    add_config_arguments(q, KruppaNoiseConfig)
    q.set_defaults(func=_cmd_experiment_kruppa_noise)

    p = sub.add_parser(
        "body",
        help="posed body mesh and joints of one BVH frame",
        description="Retarget frame K of a BVH clip onto the articulated body model (bone "
        "lengths give the shape, least squares the 24 pose parameters) and write "
        "OUT/body.ply (metres, Y up, in the BVH's world) and OUT/joints.json.",
    )
    add_config_arguments(p, BodyExportConfig)
    p.set_defaults(func=_cmd_body)

    p = sub.add_parser(
        "track",
        help="track the body through a video workspace's silhouettes",
        description="Multi-view silhouette tracking (thesis ch. 6): per frame, the pose whose "
        "rendered silhouettes best overlap WS/silhouettes in every camera (XOR energy on an "
        "image pyramid), optimised root first, then spine and neck, then each limb (grid "
        "search + downhill simplex). The first frame is initialised automatically from the "
        "visual hull (or --init-pose). Writes WS/tracks/joints.csv (world frame), pose.json "
        "and motion.bvh (in the camera rig's upright frame, Y up; pose.json holds its "
        "world_from_upright rotation) and WS/logs/track.rrd.",
    )
    p.add_argument("workspace", type=Path, metavar="WS", help="video workspace")
    p.add_argument("--overwrite", action="store_true", help="recompute even if up to date")
    add_config_arguments(p, TrackStepConfig)
    add_config_arguments(p, TrackConfig)
    p.set_defaults(func=_cmd_track)

    p = sub.add_parser(
        "fit",
        help="fit the articulated body model to a human point cloud",
        description="Estimate the body's height, girth and 24 pose parameters from a point "
        "cloud: a workspace's dense cloud (mocap fit WS → WS/body/fit.json, fit.ply, "
        "logs/fit.rrd) or any point cloud in metres (mocap fit --cloud FILE.ply --out DIR → "
        "DIR/fit.json, fit.ply, fit.rrd). Initialisation is automatic. A cloud that no body "
        "explains is reported as a failure (exit code 2) with its residual.",
    )
    p.add_argument("workspace", type=Path, nargs="?", metavar="WS",
                   help="workspace with a dense cloud (mocap dense)")
    p.add_argument("--cloud", type=Path, metavar="FILE", help="fit this point cloud instead")
    p.add_argument("--out", type=Path, metavar="DIR", default=Path("workspaces/fit"),
                   help="output folder for --cloud (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="recompute even if up to date")
    add_config_arguments(p, SubjectConfig)
    add_config_arguments(p, FitConfig)
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser(
        "report",
        help="motion report: joint angles, centre of mass, joint loads (HTML, CSV, TRC)",
        description="Kinematics and inverse dynamics of a tracked sequence (WS/tracks/pose.json) "
        "or of a BVH clip (--bvh FILE --out DIR): segment positions, velocities, accelerations "
        "and orientations, centre of mass, angular velocities and accelerations, ISB joint "
        "angles, and Newton-Euler joint forces and moments (de Leva 1996 segments), after a "
        "zero-lag Butterworth low-pass. Writes report/index.html, report/*.csv, "
        "report/motion.trc and a Rerun recording (WS/logs/report.rrd or DIR/report/report.rrd).",
    )
    p.add_argument("workspace", type=Path, nargs="?", metavar="WS",
                   help="tracking workspace (reads WS/tracks/pose.json)")
    p.add_argument("--bvh", type=Path, metavar="FILE", help="report this BVH clip instead")
    p.add_argument("--out", type=Path, metavar="DIR", help="output folder for --bvh")
    p.add_argument("--overwrite", action="store_true", help="recompute even if up to date")
    add_config_arguments(p, ReportConfig)
    p.set_defaults(func=_cmd_report)

    p = _step_command(
        sub,
        "synth",
        help="synthetic multi-camera silhouette sequence of a BVH clip, with ground truth",
        description="Drive the body model with a BVH clip, render its silhouettes from "
        "calibrated cameras on a ring around it and add background-subtraction noise (boundary "
        "jitter, holes, a floor shadow). Writes a video workspace: WS/cameras.json, "
        "WS/silhouettes/<camera>/<frame:06d>.png, WS/gt/joints.csv, WS/gt/pose.json and "
        "WS/logs/synth.rrd. Re-running with the same settings is skipped unless --overwrite.",
    )
    add_config_arguments(p, SynthConfig)
    p.set_defaults(func=_cmd_synth)

    p = sub.add_parser(
        "init-video",
        help="make a video workspace from synchronised videos and their calibration",
        description="Make a video workspace: WS/cameras.json from the calibration (COLMAP model "
        "folder, Qualisys .qca.txt, Pose2Sim/Anipose Calib.toml, or mocap-cameras-v1 JSON) and "
        "WS/videos/<camera>.<ext>, hard links (or copies) of the videos, never modified. A "
        "camera goes with the video named like it (any case; '_', '-' and spaces ignored, so "
        "Pose2Sim's cam_01 goes with cam01.mp4), or with --match order the k-th camera of the "
        "file with the k-th video by the number in its name (Pose2Sim's rule). The videos must "
        "have the same frame count and their cameras' image size (or be that image scaled to "
        "fit with black bars, whose camera is then adjusted).",
    )
    p.add_argument("workspace", type=Path, metavar="WS", help="workspace folder to create")
    p.add_argument("--videos", type=Path, required=True, metavar="DIR",
                   help="folder of synchronised videos, one per camera")
    p.add_argument("--calibration", type=Path, required=True, metavar="FILE",
                   help="calibration of the cameras (file, or COLMAP model folder)")
    p.add_argument("--match", choices=("name", "order"), default="name",
                   help="pair cameras and videos by name (default) or by order")
    p.add_argument("--copy", action="store_true", help="copy instead of hard-linking")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the videos and cameras of an existing workspace (derived "
                   "files are removed)")
    p.set_defaults(func=_cmd_init_video)

    p = _step_command(
        sub,
        "silhouettes",
        help="foreground masks of every camera's video frames (background subtraction)",
        description="Per camera, a background model (temporal median of the video, or mean and "
        "spread of empty-scene frames) and per frame a full-resolution silhouette: thresholds "
        "for foreground, background and shadow, then morphological clean-up. Writes "
        "WS/silhouettes/<camera>/<frame:06d>.png (0/255) and WS/logs/silhouettes.rrd; frames "
        "whose silhouette is empty or touches the image border are reported.",
    )
    add_config_arguments(p, SilhouettesConfig, exclude=("thresholds", "hull"))
    add_config_arguments(p, SilhouetteConfig)
    add_config_arguments(p, HullCheckConfig)
    p.set_defaults(func=_cmd_silhouettes)

    p = sub.add_parser("view", help="open the workspace's recordings in the Rerun viewer")
    p.add_argument("workspace", type=Path, metavar="WS", help="workspace folder")
    p.set_defaults(func=_cmd_view)

    p = sub.add_parser("plugins", help="list every registered plugin of every kind")
    p.set_defaults(func=_cmd_plugins)

    p = sub.add_parser(
        "demo",
        help="run the pipeline on a synthetic scene and score it",
        description="Render photos of a synthetic textured room with known "
        "cameras, run the whole pipeline on them (sparse model, dense cloud, "
        "mesh), and print the recovered focal length, pose errors and mesh "
        "accuracy against the truth. No download needed.",
    )
    add_config_arguments(p, DemoConfig)
    p.add_argument("--overwrite", action="store_true", help="recompute every step")
    add_config_arguments(p, SfMConfig, exclude=("seed", "num_threads"))
    add_config_arguments(p, DenseConfig)
    add_config_arguments(p, MeshConfig)
    p.set_defaults(func=_cmd_demo)
    return parser


def _version() -> str:
    from recon import __version__

    return f"mocap {__version__}"


def _quiet_colmap(verbose: bool) -> None:
    import pycolmap

    # glog levels: 0 INFO, 1 WARNING, 2 ERROR. COLMAP's warnings are about situations we report
    # ourselves in plain words, so only errors pass by default.
    pycolmap.logging.minloglevel = 0 if verbose else 2


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _quiet_colmap(args.verbose)
    from plugins.registry import PluginError

    try:
        args.func(args)
    except (UserError, PluginError) as exc:
        print(f"mocap {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            f"mocap {args.command}: interrupted; finished steps are kept, the unfinished "
            "one left no output",
            file=sys.stderr,
        )
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
