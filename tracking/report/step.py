"""`mocap report`: motion data reporting (thesis section 3.2.7) for any tracked sequence.

Inputs, all turned into one `MotionSequence` of the body model:

* a tracking workspace: ``WS/tracks/pose.json`` (see `read_pose_track` for the format); a
  synthetic workspace's ground truth ``WS/gt/pose.json`` only when asked (``--truth``: the
  report then goes to ``WS/gt/report/``), never in place of a tracked motion;
* a BVH clip, retargeted onto the body model (`tracking.body.retarget`);
* any `MotionSequence` built in code (`report_sequence`), e.g. a synthetic one.

Outputs, in ``report/`` (inside the workspace, or inside ``--out DIR`` for a BVH), written to
``report.partial/`` and renamed into place when complete:

* ``index.html``: summary tables, conventions, assumptions and plots (joint angles, joint
  angular velocities, centre of mass, joint moments), one self-contained page (the plots are
  embedded as data URIs; they are also beside it as image files);
* one tidy long-form CSV per quantity (``joint_angles.csv``: ``frame,time_s,joint,angle,
  degrees``; ``center_of_mass.csv``: ``frame,time_s,x,y,z`` in metres, in the input's Y-up
  axes (a pose file's upright frame; gravity is -Y); ...). Frames without data have no rows;
* ``motion.trc``: the joint centres as markers (OpenSim / Pose2Sim format, metres, Y up), named
  as Pose2Sim's OpenSim models name them unless ``--marker-set ours``; ``motion.mot``: the joint
  angles as an OpenSim motion file (`tracking.report.opensim`);
* ``summary.json``: the numbers of the summary, the config and its fingerprint;
* a Rerun recording (``report/report.rrd``; ``WS/logs/report.rrd`` for a workspace) with the
  curves and the skeleton on the ``frame`` and ``time`` timelines of the tracking recording.
"""

from __future__ import annotations

import base64
import dataclasses
import enum
import html
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from recon.errors import UserError
from recon.workspace import (
    Timer,
    Workspace,
    atomic_output,
    file_digest,
    fingerprint,
    write_json_atomic,
)
from tracking.body.model import BONES, N_POSE_PARAMS, NODE_NAMES, pose_params_problem
from tracking.body.motion import read_pose_file
from tracking.report.anthropometry import Sex, body_segments, default_body_mass
from tracking.report.dynamics import ASSUMPTIONS, JointLoads, inverse_dynamics
from tracking.report.kinematics import (
    ANGLE_JOINTS,
    ANGLE_NAMES,
    CONVENTION_OF_JOINT,
    MODEL_ANGLES,
    Kinematics,
    MotionSequence,
    compute_kinematics,
    shown_angles,
)
from tracking.report.opensim import (
    MarkerSet,
    format_rate,
    nominal_rate_hz,
    trc_markers,
    write_mot,
    write_trc,
)

MAX_REPORT_FRAMES = 200_000
"""Most frames (first to last, gaps included) a report holds: the analysis takes about 18 KB
per frame (3.6 GB here; measured on 3,000 and 12,000 frames), 1.9 h at 30 Hz."""
GT_POSE = Path("gt") / "pose.json"  # ground truth of `mocap synth`, same layout
REPORT_DIR = "report"
POSE_TRACK = Path("tracks") / "pose.json"


class PlotFormat(enum.StrEnum):
    PNG = "png"
    SVG = "svg"


@dataclass(frozen=True, kw_only=True)
class ReportConfig:
    """Settings of `mocap report`. Field help is the CLI's help."""

    cutoff_hz: float = field(
        default=6.0,
        metadata={"help": "low-pass cut-off before differentiation, Hz (-3 dB point of the "
                  "zero-lag Butterworth filter); 0 skips filtering"},
    )
    filter_order: int = field(default=2, metadata={"help": "Butterworth order of each pass"})
    max_gap_s: float = field(
        default=0.1,
        metadata={"help": "gaps of missing frames up to this long (seconds) are interpolated "
                  "and reported; longer gaps stay gaps"},
    )
    body_mass_kg: float | None = field(
        default=None,
        metadata={"help": "subject's body mass, kg (default: de Leva's sample body-mass index "
                  "at the subject's height)"},
    )
    sex: Sex = field(default=Sex.MALE, metadata={"help": "column of the de Leva (1996) table"})
    max_frames: int | None = field(
        default=None, metadata={"help": "report only the first N frames (quick looks)"}
    )
    metres_per_unit: float | None = field(
        default=None,
        metadata={"help": "BVH length unit in metres (default: its naming's; CMU: 0.0254/0.45, "
                  "Daz-style: 0.01)"},
    )
    plot_format: PlotFormat = field(
        default=PlotFormat.PNG, metadata={"help": "format of the plots in the HTML report"}
    )
    marker_set: MarkerSet = field(
        default=MarkerSet.POSE2SIM,
        metadata={"help": "marker names in motion.trc: pose2sim (Pose2Sim's: Hip, LHip, RKnee, "
                  "Neck, Head, ..., which its OpenSim models scale and track; the spine has no "
                  "such marker and is left out) or ours (the body model's 16 joint names)"},
    )
    truth: bool = field(
        default=False,
        metadata={"help": "report the ground truth of a synthetic workspace (`mocap synth`: "
                  "WS/gt/pose.json) instead of its tracked motion, into WS/gt/report/ and "
                  "WS/logs/report-truth.rrd"},
    )

    def __post_init__(self) -> None:
        if not self.cutoff_hz >= 0:
            raise UserError(f"--cutoff-hz must be >= 0 (0: no filtering), got {self.cutoff_hz}")
        if self.filter_order < 1:
            raise UserError(f"--filter-order must be at least 1, got {self.filter_order}")
        if not self.max_gap_s >= 0:
            raise UserError(f"--max-gap-s must be >= 0, got {self.max_gap_s}")
        if self.body_mass_kg is not None and not self.body_mass_kg > 0:
            raise UserError(f"--body-mass-kg must be positive, got {self.body_mass_kg}")
        if self.max_frames is not None and self.max_frames < 1:
            raise UserError(f"--max-frames must be at least 1, got {self.max_frames}")
        if self.metres_per_unit is not None and not self.metres_per_unit > 0:
            raise UserError(f"--metres-per-unit must be positive, got {self.metres_per_unit}")

    def as_dict(self) -> dict[str, Any]:
        return {k: (v.value if isinstance(v, enum.Enum) else v)
                for k, v in dataclasses.asdict(self).items()}  # fmt: skip


@dataclass(frozen=True)
class ReportSummary:
    """Where the report went and its headline numbers (the content of ``summary.json``)."""

    report_dir: Path
    recording: Path
    summary: dict[str, Any]
    reused: bool = False

    def lines(self) -> list[str]:
        s = self.summary
        gaps = s["gaps"]
        filled = [g for g in gaps if g["filled"]]
        left = [g for g in gaps if not g["filled"]]
        cut = s["cutoff_hz"]
        lines = [
            f"report      {self.report_dir / 'index.html'}" + ("  (up to date)" if self.reused
                                                              else ""),
            f"input       {s['source']}: {s['frames']} frames at {s['frame_rate']:.4g} Hz "
            f"({s['duration_s']:.2f} s)" + (f", {s['input_note']}" if s.get("input_note") else ""),
            f"subject     height {s['height_m']:.2f} m, mass {s['body_mass_kg']:.1f} kg "
            f"({s['body_mass_source']}; de Leva 1996, {s['sex']})",
            "filter      " + (f"zero-lag Butterworth, cut-off {cut:g} Hz (order "
                              f"{s['filter_order']}, two passes)" if cut > 0 else "none"),
            "gaps        " + ("none" if not gaps else
                              f"{len(filled)} interpolated ({sum(g['frames'] for g in filled)} "
                              f"frames), {len(left)} left as gaps "
                              f"({sum(g['frames'] for g in left)} frames)"),
        ]
        for joint in ("knee", "hip", "elbow"):
            peaks = [s["angles"].get(f"{side}_{joint}", {}).get("flexion", {}).get("max")
                     for side in "lr"]
            if all(p is not None for p in peaks):
                lines.append(f"{joint:<12}peak flexion left {peaks[0]:.1f} deg, right "
                             f"{peaks[1]:.1f} deg")
        com = s["center_of_mass"]
        if com.get("mean_horizontal_speed_m_s") is not None:
            lines.append(f"COM         mean horizontal speed {com['mean_horizontal_speed_m_s']:.2f}"
                         f" m/s, vertical range {100 * com['vertical_range_m']:.1f} cm")
        if s.get("external_vertical_force_bw"):
            lo, hi = s["external_vertical_force_bw"]
            lines.append(f"external    vertical force {lo:.2f}..{hi:.2f} body weights "
                         "(= total ground reaction)")
        for note in s["notes"]:
            lines.append(f"note        {note}")
        t = s.get("seconds", {})
        if t:
            lines.append("time        " + ", ".join(f"{k} {v:.1f} s" for k, v in t.items()))
        lines.append(f"recording   {self.recording}")
        return lines


# ---------------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------------


def sequence_from_bvh(
    path: Path, metres_per_unit: float | None = None, max_frames: int | None = None
) -> tuple[MotionSequence, str]:
    """A BVH clip retargeted onto the body model (world axes and frame rate of the clip).

    Returns the sequence and a note on the retargeting residual.
    """
    from tracking.body.bvh import read_bvh
    from tracking.body.motion import is_body_skeleton, poses_from_motion
    from tracking.body.retarget import retarget

    path = Path(path)
    if not path.is_file():
        raise UserError(f"BVH file {path} not found")
    try:
        motion = read_bvh(path)
    except (OSError, ValueError) as exc:
        raise UserError(str(exc).splitlines()[0]) from None
    n = motion.num_frames if max_frames is None else min(max_frames, motion.num_frames)
    if n == 0:
        raise UserError(f"{path} holds no frames")
    if is_body_skeleton(motion):
        # Our own skeleton (e.g. a tracked sequence exported as BVH): the channels are the pose.
        poses, shape = poses_from_motion(motion)
        params = np.stack([p.params for p in poses[:n]])
        _check_bvh_poses(path, params)
        seq = MotionSequence.from_poses(params, shape, motion.fps, 0, source=path.name)
        return seq, "body-model skeleton, read exactly"
    try:
        result = retarget(motion, metres_per_unit, frames=range(n))
    except (KeyError, ValueError) as exc:
        raise UserError(f"{path}: cannot retarget onto the body model ({exc}); "
                        "a CMU-style skeleton is needed") from None
    params = np.stack([p.params for p in result.poses])
    _check_bvh_poses(path, params)
    seq = MotionSequence.from_poses(params, result.shape, motion.fps, 0, source=path.name)
    note = f"retargeted, RMS {result.summary['mean_residual_mm']:.1f} mm over the joints"
    return seq, note


def _check_bvh_poses(path: Path, params: np.ndarray) -> None:
    """Refuse, naming the frame and parameter, a BVH frame whose pose no capture has: the
    reader refused non-finite numbers, so this is a root beyond `ROOT_TRANSLATION_BOUND_M`.
    Joint limits are not checked: a BVH stores rotations, which the report measures as they are
    (a rotation outside the model's ranges is the clip's, not an error of reading it)."""
    for frame, row in enumerate(params):
        if (problem := pose_params_problem(row, joint_limits=False)) is not None:
            raise UserError(f"{path}: frame {frame}: {problem}")


def read_pose_track(path: Path, max_frames: int | None = None) -> MotionSequence:
    """The sequence in a tracking workspace's ``tracks/pose.json`` (format: see
    `tracking.body.motion.read_pose_file`).

    ``params`` null (or all NaN) marks a frame the tracker lost; frame numbers missing
    from the list are lost frames too. `read_pose_file` refuses impossible frames and poses;
    a span of more than `MAX_REPORT_FRAMES` frames is refused unless ``max_frames`` cuts it.
    """
    given = read_pose_file(path)
    frame_rate, shape, entries = given.frame_rate, given.shape, given.frames
    if frame_rate is None:
        raise UserError(f"{path} holds a pose without a frame rate (such as mocap fit's "
                        "fit.json), not a motion to report")
    first = entries[0][0]
    count = entries[-1][0] - first + 1
    if max_frames is not None:
        count = min(count, max_frames)
    if count > MAX_REPORT_FRAMES:
        raise UserError(f"{path}: frames {first} to {entries[-1][0]} span {count} frames, more "
                        f"than the {MAX_REPORT_FRAMES} a report holds (about 18 KB of memory "
                        "each); report a part with --max-frames N")
    params = np.full((count, N_POSE_PARAMS), np.nan)
    for frame, row in entries:
        if row is not None and frame - first < count:
            params[frame - first] = row
    return MotionSequence.from_poses(params, shape, frame_rate, first, source=str(path))


# ---------------------------------------------------------------------------------------------
# Entry points
# ---------------------------------------------------------------------------------------------


def report_from_bvh(
    bvh: Path, out: Path, config: ReportConfig, *, overwrite: bool = False
) -> ReportSummary:
    """Report of a BVH clip in ``out/report/`` (recording ``out/report/report.rrd``)."""
    bvh, out = Path(bvh), Path(out)
    if config.truth:
        raise UserError("--truth reports the ground truth of a synthetic workspace "
                        "(mocap report WS --truth), not a BVH clip")
    if out.exists() and not out.is_dir():
        raise UserError(f"output path {out} is a file, not a folder")
    if not bvh.is_file():
        raise UserError(f"BVH file {bvh} not found")
    report_dir = out / REPORT_DIR
    fp = fingerprint("report", config.as_dict(), file_digest(bvh))
    if not overwrite and (done := _reusable(report_dir, report_dir / "report.rrd", fp)):
        return done
    with Timer() as timer:
        seq, note = sequence_from_bvh(bvh, config.metres_per_unit, config.max_frames)
    out.mkdir(parents=True, exist_ok=True)
    return report_sequence(seq, report_dir, config, recording=None, step_fingerprint=fp,
                           input_note=note, input_seconds=timer.seconds)


def report_from_workspace(
    workspace: Path, config: ReportConfig, *, overwrite: bool = False
) -> ReportSummary:
    """Report of ``WS/tracks/pose.json`` in ``WS/report/`` and ``WS/logs/report.rrd``.

    A workspace that has not been tracked is refused, also a synthetic one (`mocap synth`):
    its ground truth ``gt/pose.json`` is reported only when asked for (``config.truth``), in
    ``WS/gt/report/`` and ``WS/logs/report-truth.rrd`` (step ``report-truth``), so that no
    report of the truth can pass for one of the tracked motion."""
    root = Path(workspace)
    if root.exists() and not root.is_dir():
        raise UserError(f"workspace path {root} is a file, not a folder")
    ws = Workspace(root)
    if config.truth:
        track, report_dir, step = root / GT_POSE, ws.gt_dir / REPORT_DIR, "report-truth"
        if not track.is_file():
            raise UserError(f"{track} not found: --truth reports the ground truth of a "
                            "synthetic sequence (made with `mocap synth`)")
    else:
        track, report_dir, step = root / POSE_TRACK, root / REPORT_DIR, "report"
        if not track.is_file():
            truth = (f"; {root / GT_POSE} is the synthetic ground truth, reported with --truth"
                     if (root / GT_POSE).is_file() else "")
            raise UserError(f"{track} not found: track the sequence first (`mocap track "
                            f"{root}`), or report a BVH clip with `mocap report --bvh FILE "
                            f"--out DIR`{truth}")
    fp = fingerprint("report", config.as_dict(), file_digest(track))
    recording = ws.logs_dir / f"{step}.rrd"
    if not overwrite and (done := _reusable(report_dir, recording, fp)):
        return done
    with Timer() as timer:
        seq = read_pose_track(track, config.max_frames)
    result = report_sequence(seq, report_dir, config, recording=ws.log_path(step),
                             step_fingerprint=fp, input_seconds=timer.seconds)
    ws.record_step(step, fp, outputs=[report_dir], config=config.as_dict(), seconds=sum(
        result.summary["seconds"].values()), summary={
        k: result.summary[k] for k in ("frames", "frame_rate", "cutoff_hz", "notes")})
    return result


def _reusable(report_dir: Path, recording: Path, fp: str) -> ReportSummary | None:
    summary_path = report_dir / "summary.json"
    if not (summary_path.is_file() and recording.is_file()
            and (report_dir / "index.html").is_file()):
        return None
    try:
        summary = json.loads(summary_path.read_text())
    except json.JSONDecodeError:
        return None
    if summary.get("fingerprint") != fp:
        return None
    return ReportSummary(report_dir, recording, summary, reused=True)


def report_sequence(
    seq: MotionSequence,
    report_dir: Path,
    config: ReportConfig,
    *,
    recording: Path | None = None,
    step_fingerprint: str | None = None,
    input_note: str = "",
    input_seconds: float = 0.0,
) -> ReportSummary:
    """Compute and write the whole report of ``seq`` into ``report_dir`` (atomically).

    ``recording``: where the Rerun recording goes (default ``report_dir/report.rrd``).
    """
    report_dir = Path(report_dir)
    timings = {"input": input_seconds}
    with Timer() as timer:
        kin, loads, mass_source = analyse(seq, config)
    timings["analysis"] = timer.seconds
    own_recording = recording is None
    final_recording = report_dir / "report.rrd" if own_recording else Path(recording)
    with Timer() as timer:
        report_dir.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(report_dir) as tmp:
            tmp.mkdir()
            summary = _summary(seq, kin, loads, config, mass_source, input_note)
            summary["fingerprint"] = step_fingerprint or fingerprint("report", config.as_dict())
            summary["config"] = config.as_dict()
            write_csvs(tmp, kin, loads)
            write_trc(tmp / "motion.trc", kin.frames, kin.frame_rate, kin.joint_centres,
                      config.marker_set)
            columns, angles_deg = mot_columns(kin)
            write_mot(tmp / "motion.mot", kin.frames, kin.frame_rate, columns, angles_deg)
            figures = write_plots(tmp, kin, loads, config.plot_format)
            rrd = tmp / "report.rrd" if own_recording else final_recording
            log_report(rrd, kin, loads)
            summary["seconds"] = {**timings, "outputs": 0.0}
            write_html(tmp / "index.html", summary, kin, loads, figures, final_recording)
            write_json_atomic(tmp / "summary.json", summary)
    summary["seconds"]["outputs"] = timer.seconds
    write_json_atomic(report_dir / "summary.json", summary)
    return ReportSummary(report_dir, final_recording, summary)


def analyse(seq: MotionSequence, config: ReportConfig) -> tuple[Kinematics, JointLoads, str]:
    """Kinematics and joint loads of ``seq`` with the settings of ``config``."""
    if config.max_frames is not None and seq.num_frames > config.max_frames:
        seq = MotionSequence(seq.world_from_node[: config.max_frames], seq.shape,
                             seq.frame_rate, seq.first_frame, seq.source)
    if config.body_mass_kg is None:
        mass = default_body_mass(seq.shape.height, config.sex)
        source = "assumed from height"
    else:
        mass, source = config.body_mass_kg, "given"
    segments = body_segments(seq.shape, mass, config.sex)
    kin = compute_kinematics(
        seq, segments, cutoff_hz=config.cutoff_hz, filter_order=config.filter_order,
        max_gap_frames=int(np.floor(config.max_gap_s * seq.frame_rate + 1e-9)),
    )
    return kin, inverse_dynamics(kin), source


# ---------------------------------------------------------------------------------------------
# Summary
# ---------------------------------------------------------------------------------------------


def _range(values: np.ndarray) -> dict[str, float] | None:
    ok = values[np.isfinite(values)]
    if not len(ok):
        return None
    return {"min": float(ok.min()), "max": float(ok.max())}


def _summary(seq: MotionSequence, kin: Kinematics, loads: JointLoads, config: ReportConfig,
             mass_source: str, input_note: str) -> dict[str, Any]:  # fmt: skip
    angles = {}
    for j, joint in enumerate(ANGLE_JOINTS):
        angles[joint] = {name: _range(np.degrees(kin.joint_angles[:, j, k]))
                         for k, name in enumerate(ANGLE_NAMES)}  # fmt: skip
    moments = {}
    for s, joint in enumerate(loads.joints):
        peak = np.nanmax(np.abs(loads.moment_anatomical[:, s]), axis=0) if np.isfinite(
            loads.moment_anatomical[:, s]).any() else np.full(3, np.nan)  # fmt: skip
        force = np.linalg.norm(loads.force_in_world[:, s], axis=-1)
        moments[joint] = {
            **{f"peak_{name}_moment_nm": _float(peak[k]) for k, name in enumerate(ANGLE_NAMES)},
            "peak_force_n": _float(np.nanmax(force)) if np.isfinite(force).any() else None,
        }
    horizontal = np.linalg.norm(kin.com_velocity[:, [0, 2]], axis=-1)
    com_y = kin.com[:, 1]
    weight = kin.segments.total_mass_kg * 9.80665
    vertical = loads.force_in_world[:, 0, 1] / weight
    return {
        "source": seq.source,
        "input_note": input_note,
        "frames": int(seq.num_frames),
        "frames_with_data": int(kin.valid.sum()),
        "first_frame": int(seq.first_frame),
        "frame_rate": float(seq.frame_rate),
        "duration_s": float(seq.num_frames / seq.frame_rate),
        "height_m": float(seq.shape.height),
        "body_mass_kg": float(kin.segments.total_mass_kg),
        "body_mass_source": mass_source,
        "sex": str(config.sex),
        "cutoff_hz": float(kin.cutoff_hz),
        "filter_order": int(kin.filter_order),
        "max_gap_s": float(config.max_gap_s),
        "gaps": [{"first_frame": g.first_frame, "last_frame": g.last_frame,
                  "frames": g.num_frames, "filled": g.filled, "reason": g.reason}
                 for g in kin.gaps],  # fmt: skip
        "notes": list(kin.notes),
        "angles": angles,
        "loads": moments,
        "center_of_mass": {
            "mean_horizontal_speed_m_s": _float(np.nanmean(horizontal))
            if np.isfinite(horizontal).any() else None,
            "vertical_range_m": _float(np.nanmax(com_y) - np.nanmin(com_y)),
            "travelled_m": _float(np.nansum(np.linalg.norm(np.diff(kin.com, axis=0), axis=-1))),
        },
        "external_vertical_force_bw": [float(np.nanmin(vertical)), float(np.nanmax(vertical))]
        if np.isfinite(vertical).any() else None,
        "assumptions": list(ASSUMPTIONS),
        "opensim": {
            "rate_hz": nominal_rate_hz(kin.frame_rate),
            "marker_set": str(config.marker_set),
            "markers": [name for _, name in trc_markers(config.marker_set)],
        },
    }


def _float(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


# ---------------------------------------------------------------------------------------------
# CSV (the TRC and MOT: tracking.report.opensim)
# ---------------------------------------------------------------------------------------------


def _num(value: float) -> str:
    return f"{value:.6g}"


def _write_long(path: Path, header: Sequence[str], kin: Kinematics,
                labels: Sequence[Sequence[str]], values: np.ndarray,
                decimals: int | None = None) -> None:  # fmt: skip
    """Tidy rows ``frame,time_s,<labels>,<values>`` for every frame and label with data.

    values: (T, K, C) with K = len(labels); ``decimals``: fixed-point digits (default: 6
    significant digits).
    """
    lines = [",".join(header)]
    finite = np.isfinite(values).all(axis=-1)
    fmt = _num if decimals is None else (lambda v: f"{v + 0.0:.{decimals}f}")
    for t in range(values.shape[0]):
        head = f"{kin.frames[t]},{kin.times_s[t]:.6f}"
        for k, label in enumerate(labels):
            if finite[t, k]:
                lines.append(",".join([head, *label, *map(fmt, values[t, k])]))
    path.write_text("\n".join(lines) + "\n")


def write_csvs(folder: Path, kin: Kinematics, loads: JointLoads) -> list[str]:
    """One tidy CSV per quantity; returns the file names."""
    seg = [(name,) for name in kin.segments.names]
    angle_labels = [(j, a) for j in ANGLE_JOINTS for a in ANGLE_NAMES]
    t = len(kin.frames)
    xyz = ("x", "y", "z")
    files: dict[str, tuple[Sequence[str], Sequence[Sequence[str]], np.ndarray]] = {
        "joint_angles.csv": (("joint", "angle", "degrees"), angle_labels,
                             np.degrees(kin.joint_angles).reshape(t, -1, 1)),
        "joint_angular_velocity.csv": (("joint", "angle", "degrees_per_s"), angle_labels,
                                       np.degrees(kin.joint_angular_velocity).reshape(t, -1, 1)),
        "center_of_mass.csv": (xyz, [()], kin.com[:, None]),
        "center_of_mass_displacement.csv": (xyz, [()], kin.com_displacement[:, None]),
        "center_of_mass_velocity.csv": (xyz, [()], kin.com_velocity[:, None]),
        "center_of_mass_acceleration.csv": (xyz, [()], kin.com_acceleration[:, None]),
        "joint_positions.csv": (("joint", *xyz), [(n,) for n in NODE_NAMES], kin.joint_centres),
        "segment_position.csv": (("segment", *xyz), seg, kin.segment_com),
        "segment_displacement.csv": (("segment", *xyz), seg, kin.segment_displacement),
        "segment_velocity.csv": (("segment", *xyz), seg, kin.segment_velocity),
        "segment_acceleration.csv": (("segment", *xyz), seg, kin.segment_acceleration),
        "segment_orientation.csv": (("segment", "qx", "qy", "qz", "qw"), seg,
                                    _quaternions(kin.segment_rotation)),
        "segment_angular_velocity.csv": (("segment", *xyz), seg, kin.segment_angular_velocity),
        "segment_angular_acceleration.csv": (("segment", *xyz), seg,
                                             kin.segment_angular_acceleration),
        "joint_forces.csv": (("joint", *xyz), [(j,) for j in loads.joints],
                             loads.force_in_world),
        "joint_moments.csv": (("joint", "component", "newton_metres"),
                              [(j, c) for j in loads.joints for c in ANGLE_NAMES],
                              loads.moment_anatomical.reshape(t, -1, 1)),
    }  # fmt: skip
    # Angles to 1e-4 degree, moments to 1e-4 N m: below that it is float noise.
    decimals = {"joint_angles.csv": 4, "joint_angular_velocity.csv": 4,
                "joint_moments.csv": 4, "joint_forces.csv": 4}
    for name, (columns, labels, values) in files.items():
        _write_long(folder / name, ("frame", "time_s", *columns), kin, labels, values,
                    decimals.get(name))
    gaps = ["first_frame,last_frame,frames,filled,reason"] + [
        f"{g.first_frame},{g.last_frame},{g.num_frames},{str(g.filled).lower()},\"{g.reason}\""
        for g in kin.gaps
    ]
    (folder / "gaps.csv").write_text("\n".join(gaps) + "\n")
    s = kin.segments
    rows = ["segment,node,mass_kg,com_x,com_y,com_z,inertia_xx,inertia_yy,inertia_zz"] + [
        ",".join([name, NODE_NAMES[s.node[i]], _num(s.mass_kg[i]), *map(_num, s.com_in_node[i]),
                  *map(_num, np.diag(s.inertia_in_node[i]))])
        for i, name in enumerate(s.names)
    ]
    (folder / "segments.csv").write_text("\n".join(rows) + "\n")
    return [*files, "gaps.csv", "segments.csv"]


def mot_columns(kin: Kinematics) -> tuple[list[str], np.ndarray]:
    """Columns ``<joint>_<angle>`` of ``motion.mot`` (the angles `shown_angles` keeps: the
    body model's degrees of freedom) and their (T, C) values in degrees."""
    shown = shown_angles(kin.joint_angles)
    columns, values = [], []
    for j, joint in enumerate(ANGLE_JOINTS):
        for k, name in enumerate(ANGLE_NAMES):
            if name in shown[joint]:
                columns.append(f"{joint}_{name}")
                values.append(np.degrees(kin.joint_angles[:, j, k]))
    return columns, np.stack(values, axis=1)


def _quaternions(rotations: np.ndarray) -> np.ndarray:
    """(T, S, 4) xyzw (scalar last, scipy and Rerun order); NaN where the frame has no data."""
    from scipy.spatial.transform import Rotation

    out = np.full((*rotations.shape[:2], 4), np.nan)
    ok = np.isfinite(rotations).all(axis=(-1, -2))
    out[ok] = Rotation.from_matrix(rotations[ok]).as_quat()
    return out


# ---------------------------------------------------------------------------------------------
# Plots
# ---------------------------------------------------------------------------------------------

_PLOT_JOINTS = ("pelvis", "spine", "neck", "shoulder", "elbow", "hip", "knee")
_MOMENT_JOINTS = ("neck", "spine", "shoulder", "elbow", "hip", "knee", "ankle")
PLOT_DPI = 100
"""Pixels per inch of the PNG plots: a 12-inch figure is 1,200 px, the width of the page, so
they show at about 100% in a browser."""
PLOT_STYLE = {"font.size": 11.0, "axes.titlesize": 12.0, "axes.labelsize": 11.0,
              "legend.fontsize": 12.0, "xtick.labelsize": 10.0, "ytick.labelsize": 10.0,
              "figure.titlesize": 14.0, "svg.fonttype": "none"}  # fmt: skip
"""Font sizes in points: at `PLOT_DPI` the smallest (tick labels, 10 pt) is 14 px high and the
legends (12 pt) 17 px, readable at 100% zoom. SVG text stays text (smaller, searchable)."""
_SIDE_STYLE = {"l": ("-", "tab:blue", "left"), "r": ("--", "tab:red", "right"),
               "": ("-", "k", "midline")}  # fmt: skip


def _sides(name: str, joints: Sequence[str]) -> list[tuple[int, str]]:
    """(index, side: "l", "r" or "" for a midline joint) of a joint or of both sides of a limb
    joint."""
    if name in joints:
        return [(joints.index(name), "")]
    return [(joints.index(f"{s}_{name}"), s) for s in "lr" if f"{s}_{name}" in joints]


def _figure_legend(fig: Any, sides: Sequence[str]) -> None:
    """One legend for the whole figure, in a row under its title: outside every plot."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], ls=_SIDE_STYLE[s][0], color=_SIDE_STYLE[s][1], lw=1.6,
                      label=_SIDE_STYLE[s][2]) for s in ("", "l", "r") if s in sides]  # fmt: skip
    fig.legend(handles=handles, loc="upper center", ncols=len(handles), frameon=False,
               bbox_to_anchor=(0.5, 1 - 0.55 / fig.get_figheight()))


def grid_figure(kin: Kinematics, rows: Sequence[str], joints: Sequence[str],
                values: np.ndarray, ylabel: str, title: str,
                shown: dict[str, tuple[str, ...]] | None = None) -> Any:  # fmt: skip
    """A (rows x 3) grid of curves over time, one row per joint (both sides of a limb in one
    plot), columns `ANGLE_NAMES`. ``shown``: the angles of each joint to draw (default all); a
    plot of an angle no joint of the row has says so instead of drawing a line at zero."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with plt.rc_context(PLOT_STYLE):
        fig, axes = plt.subplots(len(rows), 3, figsize=(12, 2.1 * len(rows) + 1.2),
                                 sharex=True, squeeze=False)  # fmt: skip
        sides_drawn: set[str] = set()
        for r, name in enumerate(rows):
            for c, component in enumerate(ANGLE_NAMES):
                ax = axes[r, c]
                drawn = False
                for j, side in _sides(name, joints):
                    if shown is not None and component not in shown[joints[j]]:
                        continue
                    style, color, _ = _SIDE_STYLE[side]
                    ax.plot(kin.times_s, values[:, j, c], style, color=color, lw=1.3)
                    sides_drawn.add(side)
                    drawn = True
                ax.grid(alpha=0.3)
                if not drawn:
                    ax.text(0.5, 0.5, "not a degree of freedom\nof the body model",
                            transform=ax.transAxes, ha="center", va="center", color="0.45")
                    ax.set_yticks([])
                else:
                    low, high = ax.get_ylim()
                    if high - low < 2.0:  # a constant curve: no zoom onto float noise
                        mid = 0.5 * (low + high)
                        ax.set_ylim(mid - 1.0, mid + 1.0)
                if r == 0:
                    ax.set_title(component)
                if c == 0:
                    ax.set_ylabel(f"{name}\n{ylabel}")
        for ax in axes[-1]:
            ax.set_xlabel("time (s)")
        fig.suptitle(title, y=1 - 0.12 / fig.get_figheight(), va="top")
        _figure_legend(fig, sorted(sides_drawn))
        # Fixed margins (tight_layout costs about a second on 21 axes); the top 1.2 inches hold
        # the title and the legend.
        fig.subplots_adjust(left=0.09, right=0.985, top=1 - 1.2 / fig.get_figheight(),
                            bottom=0.55 / fig.get_figheight(), hspace=0.18, wspace=0.22)
    return fig


def com_figure(kin: Kinematics, loads: JointLoads) -> Any:
    """Centre of mass: position, speed, top-view path and the external vertical force."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with plt.rc_context(PLOT_STYLE):
        fig, axes = plt.subplots(2, 3, figsize=(12, 7.0))
        t = kin.times_s
        for k, axis in enumerate("xyz"):
            axes[0, k].plot(t, kin.com[:, k], color="k", lw=1.3)
            axes[0, k].set_title(f"COM {axis} (m)")
        speed = np.linalg.norm(kin.com_velocity, axis=-1)
        horizontal = np.linalg.norm(kin.com_velocity[:, [0, 2]], axis=-1)
        axes[1, 0].plot(t, speed, color="k", lw=1.3, label="speed")
        axes[1, 0].plot(t, horizontal, "--", color="tab:green", lw=1.3, label="horizontal")
        # The legend is the plot's title line: outside the curves whatever they do.
        axes[1, 0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncols=2, frameon=False,
                          borderaxespad=0.2, title="COM speed (m/s):", alignment="left")
        axes[1, 1].plot(kin.com[:, 0], kin.com[:, 2], color="k", lw=1.3)
        axes[1, 1].set_aspect("equal", adjustable="datalim")
        axes[1, 1].set_title("COM path, top view (x, z in m)")
        weight = kin.segments.total_mass_kg * 9.80665
        axes[1, 2].plot(t, loads.force_in_world[:, 0, 1] / weight, color="tab:purple", lw=1.3)
        axes[1, 2].axhline(1.0, color="0.5", lw=0.8)
        axes[1, 2].set_title("external vertical force (body weights)")
        for ax in axes.ravel():
            ax.grid(alpha=0.3)
        for ax in (axes[0, 0], axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 2]):
            ax.set_xlabel("time (s)")
        fig.tight_layout()
    return fig


def _save(fig: Any, path: Path) -> None:
    import matplotlib.pyplot as plt

    with plt.rc_context(PLOT_STYLE):
        fig.savefig(path, dpi=PLOT_DPI)
    plt.close(fig)


def write_plots(folder: Path, kin: Kinematics, loads: JointLoads,
                fmt: PlotFormat = PlotFormat.PNG) -> dict[str, str]:  # fmt: skip
    """The report's figures; returns title -> file name."""
    ext = PlotFormat(fmt).value
    figures = {
        "Joint angles": f"joint_angles.{ext}",
        "Joint angular velocities": f"joint_angular_velocity.{ext}",
        "Centre of mass": f"center_of_mass.{ext}",
        "Joint moments": f"joint_moments.{ext}",
    }
    shown = shown_angles(kin.joint_angles)
    _save(grid_figure(kin, _PLOT_JOINTS, ANGLE_JOINTS, np.degrees(kin.joint_angles), "deg",
                      "Joint angles", shown), folder / figures["Joint angles"])
    _save(grid_figure(kin, _PLOT_JOINTS, ANGLE_JOINTS, np.degrees(kin.joint_angular_velocity),
                      "deg/s", "Joint angular velocities", shown),
          folder / figures["Joint angular velocities"])
    _save(com_figure(kin, loads), folder / figures["Centre of mass"])
    # Moments about every axis, hinges too: the joint's structures hold what it does not move.
    _save(grid_figure(kin, _MOMENT_JOINTS, loads.joints, loads.moment_anatomical, "N m",
                      "Joint moments on the proximal segment's axes (legs: valid in swing only)"),
          folder / figures["Joint moments"])
    return figures


# ---------------------------------------------------------------------------------------------
# Rerun
# ---------------------------------------------------------------------------------------------


def log_report(path: Path, kin: Kinematics, loads: JointLoads) -> None:
    """Curves and skeleton on the ``frame``/``time`` timelines, saved atomically to ``path``."""
    from recon.recording import (
        log_frame_series,
        log_skeleton_frames,
        log_y_up_world,
        step_recording,
    )

    frames, times = kin.frames, kin.times_s
    with step_recording(path, "report") as rec:
        log_y_up_world(rec)
        log_skeleton_frames(rec, "world/skeleton", frames, times, kin.joint_centres, BONES)
        log_skeleton_frames(rec, "world/center_of_mass", frames, times, kin.com[:, None], [],
                            radius=0.04)  # fmt: skip
        for j, joint in enumerate(ANGLE_JOINTS):
            for k, name in enumerate(ANGLE_NAMES):
                log_frame_series(rec, f"report/joint_angles/{joint}/{name}", frames, times,
                                 np.degrees(kin.joint_angles[:, j, k]))  # fmt: skip
        for k, axis in enumerate("xyz"):
            log_frame_series(rec, f"report/center_of_mass/{axis}", frames, times, kin.com[:, k])
        log_frame_series(rec, "report/center_of_mass/speed", frames, times,
                         np.linalg.norm(kin.com_velocity, axis=-1))
        for s, joint in enumerate(loads.joints):
            for k, name in enumerate(ANGLE_NAMES):
                log_frame_series(rec, f"report/joint_moments/{joint}/{name}", frames, times,
                                 loads.moment_anatomical[:, s, k])


# ---------------------------------------------------------------------------------------------
# HTML
# ---------------------------------------------------------------------------------------------


def _cell(value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.1f}" if abs(value) >= 0.05 else "0.0"
    return html.escape(str(value))


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>"
                   for row in rows)  # fmt: skip
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


_CSS = """body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;
color:#222}table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;
padding:3px 8px;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}img{max-width:100%;border:1px solid #ddd}
td.nodof{text-align:center;color:#888;font-style:italic}
code{background:#f3f3f3;padding:0 3px}li{margin:0.2em 0}"""


def write_html(path: Path, summary: dict[str, Any], kin: Kinematics, loads: JointLoads,
               figures: dict[str, str], recording: Path) -> None:  # fmt: skip
    s = summary
    cut = s["cutoff_hz"]
    overview = [
        ("source", s["source"] + (f" ({s['input_note']})" if s["input_note"] else "")),
        ("frames", f"{s['frames']} ({s['frames_with_data']} with data), first {s['first_frame']}"),
        ("frame rate", f"{s['frame_rate']:.4g} Hz ({s['duration_s']:.2f} s)"),
        ("subject", f"height {s['height_m']:.3f} m, mass {s['body_mass_kg']:.1f} kg "
                    f"({s['body_mass_source']}), de Leva 1996 {s['sex']}"),
        ("filter", f"zero-lag Butterworth, -3 dB cut-off {cut:g} Hz, order {s['filter_order']} "
                   "per pass, two passes" if cut > 0 else "none (raw data differentiated)"),
        ("gaps", f"interpolated up to {s['max_gap_s']:g} s; {len(s['gaps'])} gap(s)"),
    ]
    com = s["center_of_mass"]
    com_rows = [
        ("mean horizontal speed (m/s)", _fmt(com["mean_horizontal_speed_m_s"], 3)),
        ("vertical range (m)", _fmt(com["vertical_range_m"], 3)),
        ("path length (m)", _fmt(com["travelled_m"], 3)),
    ]
    if s["external_vertical_force_bw"]:
        lo, hi = s["external_vertical_force_bw"]
        com_rows.append(("external vertical force (body weights)", f"{lo:.2f} .. {hi:.2f}"))
    angle_table = _angle_table(s["angles"], shown_angles(kin.joint_angles))
    load_rows = [[j, *(s["loads"][j][f"peak_{n}_moment_nm"] for n in ANGLE_NAMES),
                  s["loads"][j]["peak_force_n"]] for j in loads.joints]  # fmt: skip
    conventions = [(c.joint, "-".join(c.sequence), c.meaning)
                   for c in (CONVENTION_OF_JOINT[j] for j in ANGLE_JOINTS)]  # fmt: skip
    gaps = [(g["first_frame"], g["last_frame"], g["frames"],
             "interpolated" if g["filled"] else "left as gap", g["reason"]) for g in s["gaps"]]
    csvs = sorted(p.name for p in path.parent.glob("*.csv"))
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>Motion report: {html.escape(s['source'])}</title><style>{_CSS}</style>",
        "</head><body>",
        f"<h1>Motion report: {html.escape(s['source'])}</h1>",
        _table(("item", "value"), overview),
    ]
    if s["notes"]:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(n)}</li>"
                                                      for n in s["notes"]) + "</ul>")
    if gaps:
        parts += ["<h2>Gaps</h2>", _table(("first frame", "last frame", "frames", "status",
                                           "reason"), gaps)]  # fmt: skip
    parts += [
        "<h2>Summary</h2><h3>Centre of mass</h3>", _table(("quantity", "value"), com_rows),
        "<h3>Joint angles (degrees)</h3>",
        f"<p>Only the angles the body model can move: {_hinge_note()}; the others are 0 by "
        "construction and left out (<code>joint_angles.csv</code> still lists them).</p>",
        angle_table,
        "<h3>Joint loads (peaks)</h3>",
        _table(("joint", "|flexion moment| N m", "|abduction moment| N m",
                "|rotation moment| N m", "|force| N"), load_rows),
        "<h2>Plots</h2>",
        # Embedded, so that the page copied or mailed alone still shows them.
        *(f"<h3>{html.escape(title)}</h3><img src='{embedded_image(path.parent / name)}' "
          f"alt='{html.escape(title)}'>" for title, name in figures.items()),
        "<h2>Conventions</h2>",
        "<p>World axes of the input (Y up, metres). Segment frames are the body model's node "
        "frames (X to the subject's left, Y along the segment, Z forward at rest). Joint angles "
        "are Cardan angles of the distal segment relative to the proximal one (ISB: Wu et al. "
        "2002, 2005), flexion, abduction and internal rotation positive; pelvis, spine and neck: "
        "lateral bending to the right and axial rotation to the left positive. Moments are "
        "those the proximal segment exerts on the distal one about the joint centre, resolved "
        "on the proximal segment's axes with the same signs. The pelvis frame is the body "
        "model's: Y from the midpoint of the hip joints to the waist joint, so its tilt "
        "differs from a clinical (ASIS/PSIS) pelvic tilt by a roughly constant offset, and the "
        "hip and spine angles with it.</p>",
        _table(("joint", "Euler sequence (intrinsic)", "angles"), conventions),
        "<h2>Assumptions of the joint loads</h2><ul>",
        *(f"<li>{html.escape(a)}</li>" for a in s["assumptions"]),
        "</ul><p>Segment parameters: de Leva P. (1996) Adjustments to Zatsiorsky-Seluyanov's "
        "segment inertia parameters. J Biomech 29(9):1223-1230 (values used: "
        "<code>segments.csv</code>).</p>",
        # Named, not linked: the page stands alone (a copy has no files beside it).
        "<h2>Files</h2><p>In the report's folder, beside <code>index.html</code>; the plots "
        "above are also there as image files.</p><ul>",
        *(f"<li><code>{html.escape(n)}</code></li>" for n in csvs),
        f"<li><code>motion.trc</code>: joint centres as markers for OpenSim and Pose2Sim, "
        f"{html.escape(_marker_note(s['opensim']))}, "
        f"{format_rate(s['opensim']['rate_hz'])} Hz</li>",
        "<li><code>motion.mot</code>: the joint angles above as an OpenSim motion file "
        "(degrees; columns <code>&lt;joint&gt;_&lt;angle&gt;</code>, the report's ISB angles, "
        "not the coordinates of an OpenSim model)</li>",
        f"<li>Rerun recording: <code>{html.escape(str(recording))}</code> (open with "
        f"<code>rerun {html.escape(str(recording))}</code>)</li></ul>",
        "<p>Units: positions m, velocities m/s, accelerations m/s², angles degrees, angular "
        "velocities deg/s (joints) or rad/s (segments, world axes), angular accelerations "
        "rad/s², forces N (world axes), moments N m. Orientations are world_from_segment "
        "quaternions, scalar last.</p>",
        "</body></html>",
    ]
    path.write_text("\n".join(parts) + "\n")


def embedded_image(path: Path) -> str:
    """The plot file (PNG or SVG) as a data URI for ``<img src>``. SVG goes in a data URI too,
    not inline: matplotlib's SVG element ids (clip paths) repeat across figures and would clash
    in one page."""
    mime = {".png": "image/png", ".svg": "image/svg+xml"}[path.suffix.lower()]
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


def _angle_table(angles: dict[str, Any], shown: dict[str, tuple[str, ...]]) -> str:
    """Min and max of each joint's angles; the angles not in ``shown`` (not degrees of freedom
    of the body model) are one grey cell per run of them, not columns of zeros."""
    header = ["joint"] + [f"{n} {m}" for n in ANGLE_NAMES for m in ("min", "max")]
    rows = []
    for joint in ANGLE_JOINTS:
        cells = [f"<td>{html.escape(joint)}</td>"]
        missing: list[str] = []
        for name in (*ANGLE_NAMES, None):
            if name is not None and name not in shown[joint]:
                missing.append(name)
                continue
            if missing:
                cells.append(f"<td class='nodof' colspan='{2 * len(missing)}'>no "
                             f"{' or '.join(missing)} in the body model</td>")
                missing = []
            if name is not None:
                r = angles[joint][name]
                cells += [f"<td>{_cell(v)}</td>" for v in ((r["min"], r["max"]) if r
                                                           else (None, None))]  # fmt: skip
        rows.append("<tr>" + "".join(cells) + "</tr>")
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


def _hinge_note() -> str:
    """Which joints of the body model turn about fewer than three axes, and about which."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for joint, angles in MODEL_ANGLES.items():
        if len(angles) < len(ANGLE_NAMES):
            groups.setdefault(angles, []).append(joint)
    return "; ".join(f"{', '.join(joints)}: {' and '.join(angles)} only"
                     for angles, joints in groups.items())  # fmt: skip


def _marker_note(opensim: dict[str, Any]) -> str:
    if opensim["marker_set"] == MarkerSet.POSE2SIM:
        return (f"Pose2Sim's marker names ({', '.join(opensim['markers'])}; the spine has none "
                "and is left out)")
    return "the body model's joint names (--marker-set ours)"


def _fmt(value: float | None, digits: int) -> str:
    return "–" if value is None else f"{value:.{digits}f}"
