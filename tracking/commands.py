"""tracking's `mocap` subcommands (plugin kind ``command``): body, track, fit, report, synth,
init-video, silhouettes, capture, and demo.

Registered in ``pyproject.toml`` under ``mocap.commands``, as a third-party package registers
its own. Each parses its flags and calls one library function. `mocap --help` imports this
module to list the commands, so it imports the pipeline only inside the methods.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from recon.commands import add_workspace_arguments
from recon.configs import add_config_arguments, config_from_args
from recon.errors import UserError


def add_silhouettes_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags of the silhouettes settings (`mocap silhouettes` and `mocap batch`)."""
    from tracking.silhouettes.coherence import CoherenceConfig
    from tracking.silhouettes.hull import HullCheckConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.silhouettes.subtraction import SilhouetteConfig

    add_config_arguments(parser, SilhouettesConfig, exclude=("thresholds", "hull", "coherence"))
    add_config_arguments(parser, SilhouetteConfig)
    add_config_arguments(parser, HullCheckConfig)
    add_config_arguments(parser, CoherenceConfig)


def silhouettes_config(args: argparse.Namespace) -> Any:
    """`SilhouettesConfig` from the flags of :func:`add_silhouettes_arguments`, with its nested
    threshold, multi-view check and camera correction settings."""
    from tracking.silhouettes.coherence import CoherenceConfig
    from tracking.silhouettes.hull import HullCheckConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.silhouettes.subtraction import SilhouetteConfig

    try:
        thresholds = config_from_args(SilhouetteConfig, args)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return config_from_args(SilhouettesConfig, args, thresholds=thresholds,
                            hull=config_from_args(HullCheckConfig, args),
                            coherence=config_from_args(CoherenceConfig, args))


class BodyCommand:
    help = "posed body mesh and joints of one BVH frame"
    description = ("Retarget frame K of a BVH clip onto the articulated body model (bone "
                   "lengths give the shape, least squares the 26 pose parameters) and write "
                   "OUT/body.ply (metres, Y up, in the BVH's world) and OUT/joints.json.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from tracking.body.export import BodyExportConfig

        add_config_arguments(parser, BodyExportConfig)

    def run(self, args: argparse.Namespace) -> None:
        from tracking.body.export import BodyExportConfig, export_body

        out = export_body(config_from_args(BodyExportConfig, args))
        print(f"body mesh  {out['mesh']}  ({out['vertices']} vertices, {out['faces']} faces)")
        print(f"joints     {out['joints']}")
        print(f"fit        {out['residual_mm']:.1f} mm RMS over the joints; "
              f"subject height {out['height_m']:.2f} m")


class TrackCommand:
    help = "track the body through a video workspace's silhouettes"
    description = ("Multi-view silhouette tracking (thesis ch. 6): per frame, the pose whose "
                   "rendered silhouettes best overlap WS/silhouettes in every camera (XOR energy "
                   "on an image pyramid), optimised root first, then spine and neck, then each "
                   "limb (grid search + downhill simplex). The first frame is initialised "
                   "automatically from the visual hull (or --init-pose). Writes "
                   "WS/tracks/joints.csv (world frame), pose.json, motion.bvh and subject.glb "
                   "(the skinned subject, for Blender or three.js; in the camera rig's upright "
                   "frame, Y up; pose.json holds its world_from_upright rotation) and "
                   "WS/logs/track.rrd. --body chooses the body model: superquadric (the "
                   "thesis' rigid segments) or mpfb (MakeHuman's skinned body, its macro shape "
                   "and clothing refined from the first frames' silhouettes).")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from tracking.track.step import TrackStepConfig
        from tracking.track.tracker import TrackConfig

        parser.add_argument("workspace", type=Path, metavar="WS", help="video workspace")
        parser.add_argument("--overwrite", action="store_true",
                            help="recompute even if up to date")
        add_config_arguments(parser, TrackStepConfig)
        add_config_arguments(parser, TrackConfig)

    def run(self, args: argparse.Namespace) -> None:
        from recon.workspace import Workspace
        from tracking.track.step import TrackStepConfig, track_workspace
        from tracking.track.tracker import TrackConfig

        step = config_from_args(TrackStepConfig, args)
        config = config_from_args(TrackConfig, args)
        ws = Workspace.open_video(args.workspace)
        summary = track_workspace(ws, step, config, overwrite=args.overwrite)
        note = " (up to date)" if summary.get("up_to_date") else ""
        print(f"track      {summary['tracked']}/{summary['frames']} frames tracked{note}; median "
              f"XOR {summary['median_xor_fraction']:.1%} of the silhouette; "
              f"{summary['seconds_per_frame']:.2f} s/frame"
              + (f" (start and shape pass {summary['shape_pass_seconds']:.0f} s, then "
                 f"{summary['tracking_seconds_per_frame']:.2f} s/frame"
                 + (f", tracking back {summary['track_back_seconds']:.0f} s"
                    if summary.get("track_back_seconds") else "") + ")"
                 if "shape_pass_seconds" in summary else "")  # older runs lack it
              + (f" ({summary['evaluations_per_second']:.0f} energy evaluations/s)"
                 if "evaluations_per_second" in summary else "")  # older runs lack it
              + f"; subject height {summary['height_m']:.2f} m")
        for warning in summary.get("warnings", []):  # older runs lack them
            print(f"warning: {warning}", file=sys.stderr)
        without_pose = (  # summary key, the frames' label and why, the warning's subject
            ("lost", "lost", "", "the subject was lost"),
            ("absent", "absent", " (no silhouette in any camera: the subject is out of view; "
             "no pose)", "no subject in view"),
            ("two_subjects", "two subjects", " (two or more subjects in view: not tracked; no "
             "pose)", "two or more subjects in view"),
        )  # fmt: skip
        for key, label, why, subject in without_pose:
            if summary.get(key):  # older runs lack absent and two_subjects
                print(f"{label:<10} frames {summary[key]}{why}")
                print(f"warning: {subject} in {len(summary[key])} of {summary['frames']} frames "
                      "(see the events above): tracks/pose.json has no pose for them"
                      + (" and motion.bvh repeats the last tracked one" if key == "lost" else ""),
                      file=sys.stderr)  # fmt: skip
        if summary.get("partly_out_of_view"):  # older runs lack it
            print(f"partly out of view frames {summary['partly_out_of_view']} (a silhouette "
                  "touches its image border: tracked on what the images show; pose.json names "
                  "the cameras)")
        if summary.get("unexplained"):  # older runs lack it
            print(f"unexplained frames {summary['unexplained']} (the visual hull has a part "
                  "the body leaves out: a limb is likely misplaced; their poses are kept, but "
                  "not trusted)")
            print(f"warning: a limb is likely misplaced in {len(summary['unexplained'])} of "
                  f"{summary['frames']} frames (pose.json: unexplained)", file=sys.stderr)
        if summary.get("recovered"):  # older runs lack it
            print(f"recovered  frames {summary['recovered']} (found again by the start search, "
                  "or back to this subject's usual XOR after a divergence)")
        if summary.get("diverged"):
            print(f"diverged   frames {summary['diverged']} (far above this subject's usual XOR "
                  "and not found again: their poses are kept, but not trusted)")
        for frame, event in summary.get("events", {}).items():
            print(f"frame {frame:>5}: {event}")
        print(f"outputs    {ws.tracks_dir}/joints.csv, pose.json, motion.bvh, subject.glb; "
              f"{ws.logs_dir}/track.rrd")


class FitCommand:
    help = "fit the articulated body model to a human point cloud"
    description = ("Estimate the body's shape and 26 pose parameters from a point cloud: a "
                   "workspace's dense cloud (mocap fit WS → WS/body/fit.json, fit.ply, "
                   "logs/fit.rrd) or any point cloud in metres (mocap fit --cloud FILE.ply --out "
                   "DIR → DIR/fit.json, fit.ply, fit.rrd). Initialisation is automatic: the "
                   "thesis' superquadric body is searched and fitted, then refined with "
                   "MakeHuman's skinned body (pose, macro shape, clothing; --body superquadric "
                   "stops at the first); fit.json records that subject for mocap track "
                   "--init-pose. A cloud that no body explains, or a fit that leaves a limb's "
                   "points unexplained or a limb where the cloud has none, is reported as a "
                   "failure (exit code 2) with its reason.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from tracking.fit.body_fit import FitConfig
        from tracking.fit.step import SubjectConfig

        parser.add_argument("workspace", type=Path, nargs="?", metavar="WS",
                            help="workspace with a dense cloud (mocap dense)")
        parser.add_argument("--cloud", type=Path, metavar="FILE",
                            help="fit this point cloud instead")
        parser.add_argument("--out", type=Path, metavar="DIR", default=Path("workspaces/fit"),
                            help="output folder for --cloud (default: %(default)s)")
        parser.add_argument("--overwrite", action="store_true",
                            help="recompute even if up to date")
        add_config_arguments(parser, SubjectConfig)
        add_config_arguments(parser, FitConfig)

    def run(self, args: argparse.Namespace) -> None:
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
        residuals = ("" if summary["residual_median"] is None else
                     f"median distance {summary['residual_median']:.4g}, "
                     f"{summary['inlier_fraction']:.0%} inliers, ")  # (none: --no-judge)
        print(f"body fit   {verdict}: {summary['message']}; {residuals}"
              f"height {summary['height']:.3g}")
        for path in paths.values():
            print(f"           {path}")
        if not summary["success"]:
            raise UserError("the cloud does not look like one human body (see fit.json)")


class ReportCommand:
    help = "motion report: joint angles, centre of mass, joint loads (HTML, CSV, TRC, MOT)"
    description = ("Kinematics and inverse dynamics of a tracked sequence (WS/tracks/pose.json) "
                   "or of a BVH clip (--bvh FILE --out DIR): segment positions, velocities, "
                   "accelerations and orientations, centre of mass, angular velocities and "
                   "accelerations, ISB joint angles, and Newton-Euler joint forces and moments "
                   "(de Leva 1996 segments), after a zero-lag Butterworth low-pass. Writes "
                   "report/index.html (self-contained), report/*.csv, report/motion.trc "
                   "(Pose2Sim's marker names unless --marker-set ours), report/motion.mot "
                   "(joint angles for OpenSim) and a Rerun recording (WS/logs/report.rrd or "
                   "DIR/report/report.rrd).")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from tracking.report.step import ReportConfig

        parser.add_argument("workspace", type=Path, nargs="?", metavar="WS",
                            help="tracking workspace (reads WS/tracks/pose.json)")
        parser.add_argument("--bvh", type=Path, metavar="FILE",
                            help="report this BVH clip instead")
        parser.add_argument("--out", type=Path, metavar="DIR", help="output folder for --bvh")
        parser.add_argument("--overwrite", action="store_true",
                            help="recompute even if up to date")
        add_config_arguments(parser, ReportConfig)

    def run(self, args: argparse.Namespace) -> None:
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


class SynthCommand:
    help = "synthetic multi-camera silhouette sequence of a BVH clip, with ground truth"
    description = ("Drive the body model with a BVH clip, render its silhouettes from "
                   "calibrated cameras on a ring around it and add background-subtraction noise "
                   "(boundary jitter, holes, a floor shadow). Writes a video workspace: "
                   "WS/cameras.json, WS/silhouettes/<camera>/<frame:06d>.png, WS/gt/joints.csv, "
                   "WS/gt/pose.json and WS/logs/synth.rrd. Re-running with the same settings is "
                   "skipped unless --overwrite.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from tracking.rig.synth import SynthConfig

        add_workspace_arguments(parser)
        add_config_arguments(parser, SynthConfig)

    def run(self, args: argparse.Namespace) -> None:
        from tracking.rig.synth import SynthConfig, synthesize

        if args.bvh is None:
            raise UserError("--bvh FILE is required (the clip that drives the body)")
        result = synthesize(args.workspace, config_from_args(SynthConfig, args),
                            overwrite=args.overwrite)
        print("\n".join(result.lines()))


class InitVideoCommand:
    help = "make a video workspace from synchronised videos and their calibration"
    description = ("Make a video workspace: WS/cameras.json from the calibration (COLMAP model "
                   "folder, Qualisys .qca.txt, Pose2Sim/Anipose Calib.toml, or mocap-cameras-v1 "
                   "JSON) and WS/videos/<camera>.<ext>, hard links (or copies) of the videos, "
                   "never modified. A camera goes with the video named like it (any case; '_', "
                   "'-' and spaces ignored, so Pose2Sim's cam_01 goes with cam01.mp4), or with "
                   "--match order the k-th camera of the file with the k-th video by the number "
                   "in its name (Pose2Sim's rule). The videos must have the same frame count and "
                   "their cameras' image size (or be that image scaled to fit with black bars, "
                   "whose camera is then adjusted).")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("workspace", type=Path, metavar="WS", help="workspace folder to create")
        parser.add_argument("--videos", type=Path, required=True, metavar="DIR",
                            help="folder of synchronised videos, one per camera")
        parser.add_argument("--calibration", type=Path, required=True, metavar="FILE",
                            help="calibration of the cameras (file, or COLMAP model folder)")
        parser.add_argument("--match", choices=("name", "order"), default="name",
                            help="pair cameras and videos by name (default) or by order")
        parser.add_argument("--copy", action="store_true", help="copy instead of hard-linking")
        parser.add_argument("--overwrite", action="store_true",
                            help="replace the videos and cameras of an existing workspace "
                            "(derived files are removed)")

    def run(self, args: argparse.Namespace) -> None:
        from tracking.rig.video import STEP, init_video

        ws = init_video(args.workspace, args.videos, args.calibration, match=args.match,
                        copy=args.copy, overwrite=args.overwrite)
        summary = ws.step(STEP).summary
        print(f"workspace {ws.root}: {len(summary['cameras'])} cameras x {summary['frames']} "
              f"frames at {summary['fps']:g} fps; {ws.cameras_path}, {ws.videos_dir}")
        for note in summary["notes"]:
            print(f"note: {note}", file=sys.stderr)


class SilhouettesCommand:
    help = "foreground masks of every camera's video frames (background subtraction)"
    description = ("Per camera, a background model (background plates: photos or a clip of "
                   "the empty scene; else the temporal median of the video, or the mean and "
                   "spread of its empty-scene frames) and per frame a full-resolution silhouette: "
                   "thresholds for foreground, background and shadow, then morphological "
                   "clean-up. Writes WS/silhouettes/<camera>/<frame:06d>.png (0/255) and "
                   "WS/logs/silhouettes.rrd; frames whose silhouette is empty or touches the "
                   "image border are reported.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_workspace_arguments(parser)
        add_silhouettes_arguments(parser)

    def run(self, args: argparse.Namespace) -> None:
        from recon.workspace import Workspace
        from tracking.silhouettes.step import make_silhouettes, summary_lines

        config = silhouettes_config(args)
        ws = Workspace.open_video(args.workspace)
        print("\n".join(summary_lines(ws, make_silhouettes(ws, config, overwrite=args.overwrite))))




def add_capture_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags of ``mocap capture WS --videos DIR --calibration FILE [--background-images
    DIR] [step flags]``: those of `CaptureConfig` and of the steps' configs, as `mocap
    init-video`, `mocap silhouettes`, `mocap track` and `mocap report` have them (the frame
    range is the silhouettes' ``--first``, ``--last``, ``--frame-step``: the tracker follows
    every frame that has silhouettes)."""
    from tracking.capture import CaptureConfig
    from tracking.report.step import ReportConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig

    parser.add_argument("workspace", type=Path, metavar="WS",
                        help="video workspace to create (or resume)")
    parser.add_argument("--videos", type=Path, required=True, metavar="DIR",
                        help="folder of synchronised videos, one per camera")
    parser.add_argument("--calibration", type=Path, required=True, metavar="FILE",
                        help="calibration of the cameras (COLMAP model folder, Qualisys "
                        ".qca.txt, Pose2Sim/Anipose Calib.toml, or mocap-cameras-v1 JSON)")
    parser.add_argument("--overwrite", action="store_true", help="recompute every step")
    add_config_arguments(parser, CaptureConfig)
    add_silhouettes_arguments(parser)  # --background-images is a SilhouettesConfig flag
    add_config_arguments(parser, TrackStepConfig, exclude=("first", "last"))
    add_config_arguments(parser, TrackConfig)
    add_config_arguments(parser, ReportConfig, exclude=("truth", "metres_per_unit"))


def run_capture_command(args: argparse.Namespace) -> None:
    """`mocap capture`: `capture` with the flags of `add_capture_arguments`; prints its
    summary."""
    from tracking.capture import CaptureConfig, capture
    from tracking.report.step import ReportConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig

    try:
        silhouettes = silhouettes_config(args)
    except UserError as exc:
        raise UserError(f"silhouettes: {exc}") from None
    # --first/--last belong to the silhouettes; the tracker takes every frame they cover.
    track_step = config_from_args(TrackStepConfig, args, first=0, last=None)
    result = capture(
        args.workspace, args.videos, args.calibration,
        background_images=args.background_images,
        config=config_from_args(CaptureConfig, args),
        silhouettes=silhouettes,
        track_step=track_step,
        track=config_from_args(TrackConfig, args),
        report=config_from_args(ReportConfig, args),
        overwrite=args.overwrite,
    )
    print("\n".join(result.lines()))


class CaptureCommand:
    """``mocap capture`` (plugin kind ``command``): `add_capture_arguments` and
    `run_capture_command`; wired by one entry point, ``capture = "tracking.capture:
    CaptureCommand"`` in ``[project.entry-points."mocap.commands"]``."""

    help = "synchronised videos and their calibration → silhouettes → tracked motion → report"
    description = (
        "`mocap init-video`, `mocap silhouettes`, `mocap track` and `mocap report` in a row, "
        "each with its own flags and defaults: WS/cameras.json and WS/videos/, "
        "WS/silhouettes/, WS/tracks/ (joints.csv, pose.json, motion.bvh) and WS/report/ "
        "(index.html, CSVs, motion.trc), with WS/logs/*.rrd. A re-run reuses every finished "
        "step whose inputs and settings are unchanged; a failure names the step and why, in "
        "one line, and leaves the finished steps in place.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_capture_arguments(parser)

    def run(self, args: argparse.Namespace) -> None:
        run_capture_command(args)




def add_demo_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags of ``mocap demo``: the photo demo's (`recon.demo.DemoConfig`, --overwrite,
    and the sfm, dense and mesh settings) and `MotionDemoConfig`'s."""
    from recon.demo import DemoConfig
    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.demo import MotionDemoConfig

    add_config_arguments(parser, DemoConfig)
    parser.add_argument("--overwrite", action="store_true", help="recompute every step")
    add_config_arguments(parser, MotionDemoConfig)
    add_config_arguments(parser, SfMConfig, exclude=("seed", "num_threads"))
    add_config_arguments(parser, DenseConfig)
    add_config_arguments(parser, MeshConfig)


def run_demo_command(args: argparse.Namespace) -> None:
    """``mocap demo``: `run_demo` with the flags of `add_demo_arguments`; prints the report."""
    from recon.demo import DemoConfig
    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.demo import MotionDemoConfig, run_demo

    report = run_demo(
        config_from_args(DemoConfig, args),
        config_from_args(MotionDemoConfig, args),
        config_from_args(SfMConfig, args),
        config_from_args(DenseConfig, args),
        config_from_args(MeshConfig, args),
        overwrite=args.overwrite,
    )
    print("\n".join(report.lines()))


class DemoCommand:
    """``mocap demo`` (plugin kind ``command``): `add_demo_arguments` and `run_demo_command`;
    re-pointed by one entry point, ``demo = "tracking.demo:DemoCommand"``."""

    help = "the three modules on generated data with known answers, scored against the truth"
    description = (
        "Photos of a synthetic textured room with known cameras through the whole photo "
        "pipeline (sparse model, dense cloud, mesh: focal length, pose errors and mesh "
        "accuracy against the truth); every focal initialiser compared on the same photos "
        "(mocap compare); and a synthetic walk filmed by a ring of cameras, captured from its "
        "videos to a motion report (mocap capture: joint errors and silhouette IoU against "
        "the truth). No download needed; a second run reuses every step.")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_demo_arguments(parser)

    def run(self, args: argparse.Namespace) -> None:
        run_demo_command(args)
