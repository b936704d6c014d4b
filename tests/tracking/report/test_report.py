"""Tests of tracking.report.step and `mocap report`: a synthetic tracking workspace with gaps, a CMU
BVH clip round trip, and bad input."""

from __future__ import annotations

import base64
import csv
import json
import shutil
import subprocess
import sys
from dataclasses import fields
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from recon.errors import UserError
from tests.helpers import recording_entities, run_cli, shared_dataset
from tracking.body.bvh import CMU_METRES_PER_UNIT, read_bvh
from tracking.body.model import (
    LOWER_LIMITS,
    N_POSE_PARAMS,
    NODE_NAMES,
    PARAM_INDEX,
    UPPER_LIMITS,
    BodyShape,
)
from tracking.body.retarget import cmu_node_positions
from tracking.report.kinematics import ANGLE_JOINTS, ANGLE_NAMES, MODEL_ANGLES, shown_angles
from tracking.report.step import (
    PLOT_DPI,
    ReportConfig,
    analyse,
    com_figure,
    grid_figure,
    read_pose_track,
    report_from_bvh,
    report_from_workspace,
)

SHAPE = BodyShape.default(1.70)
FPS = 30.0
N = 90
VELOCITY = np.array([0.1, 0.0, 1.2])  # pelvis, m/s: straight and constant, so filtering keeps it


def walking_params(n: int = N) -> np.ndarray:
    """(n, N_POSE_PARAMS) a gait-like synthetic motion: 1 Hz leg and arm swing, pelvis moving
    at VELOCITY."""
    t = np.arange(n) / FPS
    swing = np.sin(2 * np.pi * t)
    p = np.zeros((n, N_POSE_PARAMS))
    p[:, PARAM_INDEX["root_tx"]] = 0.3 + VELOCITY[0] * t
    p[:, PARAM_INDEX["root_ty"]] = SHAPE.hip_height
    p[:, PARAM_INDEX["root_tz"]] = VELOCITY[2] * t
    p[:, PARAM_INDEX["l_hip_rx"]] = -0.35 * swing
    p[:, PARAM_INDEX["r_hip_rx"]] = 0.35 * swing
    p[:, PARAM_INDEX["l_knee_flex"]] = 0.6 + 0.5 * swing
    p[:, PARAM_INDEX["r_knee_flex"]] = 0.6 - 0.5 * swing
    p[:, PARAM_INDEX["l_shoulder_rx"]] = 0.3 * swing
    p[:, PARAM_INDEX["r_elbow_flex"]] = 0.4
    return p


def write_pose_track(ws: Path, params: np.ndarray, skip: range = range(0),
                     lost: range = range(0)) -> Path:  # fmt: skip
    """WS/tracks/pose.json in the format `read_pose_track` documents."""
    frames = [{"frame": k, "params": None if k in lost else params[k].tolist()}
              for k in range(len(params)) if k not in skip]  # fmt: skip
    data = {"frame_rate": FPS,
            "shape": {f.name: getattr(SHAPE, f.name) for f in fields(BodyShape)},
            "frames": frames}  # fmt: skip
    path = ws / "tracks" / "pose.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))
    return path


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def workspace_report(tmp_path_factory: pytest.TempPathFactory):
    ws = tmp_path_factory.mktemp("ws")
    # Frames 20-21 lost (0.07 s: interpolated), frames 50-59 absent (0.33 s: left as a gap).
    write_pose_track(ws, walking_params(), skip=range(50, 60), lost=range(20, 22))
    return ws, report_from_workspace(ws, ReportConfig())


def test_workspace_report_writes_every_output(workspace_report) -> None:
    ws, result = workspace_report
    report = ws / "report"
    assert result.report_dir == report and result.recording == ws / "logs" / "report.rrd"
    for name in ("index.html", "joint_angles.csv", "center_of_mass.csv", "joint_moments.csv",
                 "joint_forces.csv", "segment_angular_velocity.csv", "motion.trc",
                 "motion.mot", "summary.json", "joint_angles.png", "center_of_mass.png",
                 "joint_moments.png", "joint_angular_velocity.png"):
        assert (report / name).is_file(), name
    assert not (report / "report.rrd").exists() and not (ws / "report.partial").exists()
    page = (report / "index.html").read_text()
    for needle in ("<img src='data:image/png;base64,", "de Leva", "Ground reaction forces are "
                   "unknown", "6 Hz"):
        assert needle in page, needle
    assert json.loads((ws / "run.json").read_text())["steps"]["report"]["summary"]["frames"] == N


def test_csvs_are_tidy_and_leave_long_gaps_empty(workspace_report) -> None:
    ws, _ = workspace_report
    report = ws / "report"
    header = (report / "joint_angles.csv").read_text().splitlines()[0]
    assert header == "frame,time_s,joint,angle,degrees"
    assert (report / "center_of_mass.csv").read_text().splitlines()[0] == "frame,time_s,x,y,z"
    angles = read_rows(report / "joint_angles.csv")
    frames = {int(r["frame"]) for r in angles}
    assert frames == set(range(N)) - set(range(50, 60))  # the short gap is filled
    assert {r["angle"] for r in angles} == {"flexion", "abduction", "rotation"}
    knee = {int(r["frame"]): float(r["degrees"]) for r in angles
            if r["joint"] == "l_knee" and r["angle"] == "flexion"}  # fmt: skip
    truth = np.degrees(walking_params()[:, PARAM_INDEX["l_knee_flex"]])
    # 1 Hz motion through a 6 Hz low-pass: within 0.5 degree; the two interpolated frames (an
    # arc replaced by a chord) within 1.5 degrees.
    assert max(abs(knee[k] - truth[k]) for k in knee if k not in (20, 21)) < 0.5
    assert max(abs(knee[k] - truth[k]) for k in (20, 21)) < 1.5
    # Joint centres are in the input's own world axes: the pelvis follows the root translation.
    pelvis = np.array([[float(r[a]) for a in "xyz"]
                       for r in read_rows(report / "joint_positions.csv")
                       if r["joint"] == "pelvis"])
    expected = walking_params()[:, [PARAM_INDEX[f"root_t{a}"] for a in "xyz"]]
    np.testing.assert_allclose(pelvis, np.delete(expected, range(50, 60), axis=0), atol=1e-5)
    gaps = read_rows(report / "gaps.csv")
    assert [(g["first_frame"], g["last_frame"], g["filled"]) for g in gaps] == [
        ("20", "21", "true"), ("50", "59", "false")]


def test_com_and_trc_are_in_metres_in_the_world_axes(workspace_report) -> None:
    ws, result = workspace_report
    report = ws / "report"
    com = read_rows(report / "center_of_mass.csv")
    height = np.array([float(r["y"]) for r in com])
    # Standing height centre of mass sits at about 55% of the body height, Y up.
    assert np.all(np.abs(height / SHAPE.height - 0.55) < 0.05)
    speed = result.summary["center_of_mass"]["mean_horizontal_speed_m_s"]
    assert speed == pytest.approx(np.hypot(VELOCITY[0], VELOCITY[2]), rel=0.05)
    lines = (report / "motion.trc").read_text().splitlines()
    assert lines[0].startswith("PathFileType\t4\t(X/Y/Z)\tmotion.trc")
    # Pose2Sim's marker names by default: the 15 joints that have one (not the spine).
    assert lines[2].split("\t")[:5] == ["30", "30", str(N), "15", "m"]
    assert lines[3].split("\t")[:3] == ["Frame#", "Time", "Hip"]
    data = lines[6:]
    assert len(data) == N
    assert data[55].split("\t")[2:] == ["NaN"] * 45  # a frame of the long gap: no invented markers
    hip = [float(v) for v in data[0].split("\t")[2:5]]  # Pose2Sim's Hip: our pelvis joint
    np.testing.assert_allclose(hip, [0.3, SHAPE.hip_height, 0.0], atol=1e-5)


def trc_markers(path: Path) -> dict[str, np.ndarray]:
    """Marker name -> (T, 3) positions of a TRC file (NaN where missing)."""
    lines = path.read_text().splitlines()
    names = [n for n in lines[3].split("\t")[2:] if n]
    data = np.array([[float(v) for v in line.split("\t")[2:]] for line in lines[6:]])
    assert data.shape[1] == 3 * len(names)
    return {name: data[:, 3 * i:3 * i + 3] for i, name in enumerate(names)}


def test_trc_markers_are_where_pose2sims_are(workspace_report) -> None:
    """Pose2Sim's markers sit at the joint centres its pose model finds: Hip is the midpoint of
    LHip and RHip, Head the top of the head above Neck, each wrist at the end of its forearm."""
    ws, _ = workspace_report
    markers = trc_markers(ws / "report" / "motion.trc")
    joints = {name: np.array([[float(r[a]) for a in "xyz"] for r in rows])
              for name in NODE_NAMES
              if (rows := [r for r in read_rows(ws / "report" / "joint_positions.csv")
                           if r["joint"] == name])}  # fmt: skip
    ok = np.isfinite(markers["Hip"][:, 0])
    assert ok.sum() == N - 10
    for ours, theirs in (("pelvis", "Hip"), ("l_hip", "LHip"), ("r_knee", "RKnee"),
                         ("l_wrist", "LWrist"), ("head_top", "Head"), ("neck", "Neck")):
        # The CSV holds 6 significant digits, the TRC 6 decimals: 10 µm apart at most.
        np.testing.assert_allclose(markers[theirs][ok], joints[ours], atol=1e-5, err_msg=theirs)
    mid = 0.5 * (markers["LHip"] + markers["RHip"])
    assert np.nanmax(np.linalg.norm(markers["Hip"] - mid, axis=1)) < 1e-3  # metres
    assert np.all(markers["Head"][ok, 1] > markers["Neck"][ok, 1] + 0.15)
    assert "spine" not in markers and "pelvis" not in markers


def test_mot_holds_the_model_angles_in_degrees(workspace_report) -> None:
    ws, _ = workspace_report
    lines = (ws / "report" / "motion.mot").read_text().splitlines()
    end = lines.index("endheader")
    header = dict(line.split("=") for line in lines[1:end])
    columns = lines[end + 1].split("\t")
    rows = np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2:]])
    expected = ["time"] + [f"{j}_{a}" for j in ANGLE_JOINTS for a in MODEL_ANGLES[j]]
    assert lines[0] == "motion" and columns == expected and "l_knee_abduction" not in columns
    assert header == {"version": "1", "nRows": str(len(rows)), "nColumns": str(len(columns)),
                      "inDegrees": "yes"}
    assert rows.shape == (N - 10, len(columns))  # the long gap has no rows, as in the CSVs
    knee = {round(float(r["time_s"]), 4): float(r["degrees"])
            for r in read_rows(ws / "report" / "joint_angles.csv")
            if r["joint"] == "l_knee" and r["angle"] == "flexion"}  # fmt: skip
    ours = rows[:, columns.index("l_knee_flexion")]
    np.testing.assert_allclose(ours, [knee[round(t, 4)] for t in rows[:, 0]], atol=1e-3)


def test_opensim_reads_the_trc_and_the_mot(workspace_report, tmp_path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    monkeypatch.chdir(tmp_path)  # OpenSim writes opensim.log into the working folder
    opensim = pytest.importorskip(
        "opensim", reason="the opensim package is not installed (pip install opensim; not a "
        "dependency): OpenSim's own readers are not tried")
    ws, _ = workspace_report
    trc, mot = ws / "report" / "motion.trc", ws / "report" / "motion.mot"
    table = opensim.TRCFileAdapter().read(str(trc))["markers"]
    assert table.getNumRows() == N and table.getNumColumns() == 15
    assert list(table.getColumnLabels())[:3] == ["Hip", "Neck", "LShoulder"]
    assert table.getTableMetaDataAsString("DataRate") == "30"
    assert table.getTableMetaDataAsString("Units") == "m"
    markers = opensim.TimeSeriesTableVec3(str(trc))  # the same adapter, typed table
    first, gap = markers.getRowAtIndex(0), markers.getRowAtIndex(55)
    hip = first[list(markers.getColumnLabels()).index("Hip")]
    np.testing.assert_allclose([hip[0], hip[1], hip[2]], [0.3, SHAPE.hip_height, 0.0],
                               atol=1e-5)
    assert np.isnan(gap[0][0])  # the long gap stays missing
    assert markers.getIndependentColumn()[1] == pytest.approx(1 / FPS, abs=1e-6)
    angles = opensim.TimeSeriesTable(str(mot))
    assert angles.getNumRows() == N - 10
    assert angles.getTableMetaDataAsString("inDegrees") == "yes"
    assert "r_knee_flexion" in list(angles.getColumnLabels())


class _Page(HTMLParser):
    """The references of a page (every URL-valued attribute), its images and its tables."""

    URL_ATTRIBUTES = frozenset({"src", "href", "srcset", "data", "poster", "action",
                                "xlink:href", "background", "formaction"})  # fmt: skip

    def __init__(self, text: str) -> None:
        super().__init__()
        self.references: list[tuple[str, str, str]] = []
        self.images: list[str] = []
        self.tables: list[list[list[tuple[str, dict[str, str | None]]]]] = []
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for name, value in attrs:
            if name in self.URL_ATTRIBUTES and value is not None:
                self.references.append((tag, name, value))
        if tag == "img":
            self.images.append(dict(attrs).get("src") or "")
        elif tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []
            self.tables[-1][-1].append(("", dict(attrs)))

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            row = self.tables[-1][-1]
            row[-1] = ("".join(self._cell), row[-1][1])
            self._cell = None


PLOTS = ("joint_angles", "joint_angular_velocity", "center_of_mass", "joint_moments")


def test_index_html_stands_alone_with_its_plots_embedded(workspace_report, tmp_path) -> None:
    """Issue 21: the page linked its plots by relative path, so a copy showed broken images."""
    ws, _ = workspace_report
    report = ws / "report"
    copy = tmp_path / "mailed.html"
    shutil.copy(report / "index.html", copy)  # alone, without the report's folder
    text = copy.read_text()
    page = _Page(text)
    assert [r for r in page.references if not r[2].startswith("data:")] == []
    assert "url(" not in text and "@import" not in text  # nor from the style sheet
    assert len(page.images) == len(PLOTS)
    for src, name in zip(page.images, PLOTS, strict=True):
        head, _, payload = src.partition(",")
        assert head == "data:image/png;base64"
        assert base64.b64decode(payload) == (report / f"{name}.png").read_bytes()


BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome",
            "chrome-headless-shell")  # fmt: skip


@pytest.mark.slow
def test_index_html_alone_shows_its_plots_in_a_headless_browser(workspace_report,
                                                                tmp_path) -> None:  # fmt: skip
    """The page copied alone into an empty folder, screenshotted by a headless Chromium at 100%:
    the curves' colours are on screen, which a broken image (the page before issue 21) lacks."""
    from PIL import Image

    browser = next((path for name in BROWSERS if (path := shutil.which(name))), None)
    if browser is None:
        pytest.skip(f"no headless browser on PATH ({', '.join(BROWSERS)}): the page is not "
                    "screenshotted (apt-get install chromium)")
    ws, _ = workspace_report
    page = tmp_path / "alone" / "index.html"
    page.parent.mkdir()
    shutil.copy(ws / "report" / "index.html", page)
    shot = tmp_path / "shot.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    "--force-device-scale-factor=1", "--window-size=1280,9000",
                    f"--screenshot={shot}", page.as_uri()],
                   capture_output=True, timeout=180, check=True)  # fmt: skip
    image = np.asarray(Image.open(shot).convert("RGB"), dtype=int)
    assert image.shape[1] == 1280
    # matplotlib's tab:blue (left side) and tab:red (right side), drawn only in the plots.
    for rgb in ((31, 119, 180), (214, 39, 40)):
        pixels = int((np.abs(image - rgb).sum(axis=-1) < 40).sum())
        assert pixels > 3000, (rgb, pixels)


def test_angle_table_leaves_out_what_the_model_cannot_move(workspace_report) -> None:
    """Hinges (neck, elbows, knees) get one grey cell, not abduction and rotation columns of
    zeros; the other joints keep all six numbers."""
    ws, result = workspace_report
    page = _Page((ws / "report" / "index.html").read_text())
    table = next(t for t in page.tables if t[0][1][0] == "flexion min")
    rows = {row[0][0]: row[1:] for row in table[1:]}
    assert list(rows) == list(ANGLE_JOINTS)
    for joint, cells in rows.items():
        width = sum(int(attrs.get("colspan") or 1) for _, attrs in cells)
        numbers = [float(text) for text, attrs in cells if attrs.get("class") != "nodof"]
        assert width == 6 and len(numbers) == 2 * len(MODEL_ANGLES[joint]), joint
        if len(MODEL_ANGLES[joint]) == 1:
            assert cells[2][0] == "no abduction or rotation in the body model", joint
    knee = result.summary["angles"]["l_knee"]["flexion"]
    assert [float(t) for t, _ in rows["l_knee"][:2]] == pytest.approx(
        [knee["min"], knee["max"]], abs=0.051)


def test_shown_angles_are_the_models_and_whatever_else_moves() -> None:
    angles = np.zeros((5, len(ANGLE_JOINTS), 3))
    assert shown_angles(angles) == MODEL_ANGLES
    elbow = ANGLE_JOINTS.index("l_elbow")
    angles[3, elbow, ANGLE_NAMES.index("rotation")] = np.radians(2.0)
    angles[0] = np.nan
    shown = shown_angles(angles)
    assert shown["l_elbow"] == ("flexion", "rotation") and shown["r_elbow"] == ("flexion",)


def test_plot_text_is_readable_at_100_percent_and_legends_stay_off_the_plots(
    workspace_report,
) -> None:  # fmt: skip
    """Every text of the figures is at least 12 px high at the PNG's resolution (the page
    shows the 1,200 px images at about their size), and no legend covers a plot."""
    import matplotlib.text

    ws, _ = workspace_report
    kin, loads, _ = analyse(read_pose_track(ws / "tracks" / "pose.json"), ReportConfig())
    figures = [grid_figure(kin, ("pelvis", "elbow", "knee"), ANGLE_JOINTS,
                           np.degrees(kin.joint_angles), "deg", "Joint angles",
                           shown_angles(kin.joint_angles)),
               com_figure(kin, loads)]  # fmt: skip
    for fig in figures:
        fig.set_dpi(PLOT_DPI)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend())]
        assert legends
        for legend in legends:
            box = legend.get_window_extent(renderer)
            assert not any(box.overlaps(ax.get_window_extent(renderer)) for ax in fig.axes)
        texts = [t for t in fig.findobj(matplotlib.text.Text) if t.get_visible() and t.get_text()]
        sizes_px = [t.get_fontsize() * PLOT_DPI / 72 for t in texts]
        assert min(sizes_px) >= 12.0, min(sizes_px)
        assert fig.get_figwidth() * PLOT_DPI == 1200
    import matplotlib.pyplot as plt

    for fig in figures:
        plt.close(fig)


def test_recording_has_curves_and_skeleton_on_the_tracking_timelines(workspace_report) -> None:
    ws, _ = workspace_report
    entities = recording_entities(ws / "logs" / "report.rrd")
    for wanted in ("/report/joint_angles/l_knee/flexion@Scalars:scalars",
                   "/report/center_of_mass/y@Scalars:scalars",
                   "/report/joint_moments/l_hip/flexion@Scalars:scalars",
                   "/world/skeleton/joints@Points3D:positions",
                   "/world/skeleton/bones@LineStrips3D:strips"):
        assert wanted in entities, wanted
    # The curves' timelines, as Rerun's own reader shows them: the frame number and seconds.
    rerun = Path(sys.executable).with_name("rerun")
    dump = subprocess.run([rerun, "rrd", "print", "-vv", ws / "logs" / "report.rrd"],
                          capture_output=True, text=True, check=True).stdout  # fmt: skip
    assert "index_name: frame" in dump and "index_name: time" in dump


def test_report_is_reused_until_its_input_or_settings_change(workspace_report) -> None:
    ws, _ = workspace_report
    assert report_from_workspace(ws, ReportConfig()).reused
    again = report_from_workspace(ws, ReportConfig(cutoff_hz=4.0))
    assert not again.reused and again.summary["cutoff_hz"] == 4.0


def test_bad_workspace_inputs_get_one_line_messages(tmp_path: Path) -> None:
    with pytest.raises(UserError, match=r"tracks/pose.json not found.*mocap track"):
        report_from_workspace(tmp_path, ReportConfig())
    write_pose_track(tmp_path, walking_params(6))
    with pytest.raises(UserError, match="too short.*6 frame.*needs at least 10"):
        report_from_workspace(tmp_path, ReportConfig())
    write_pose_track(tmp_path, walking_params(40), lost=range(40))
    with pytest.raises(UserError, match="no frame with data"):
        report_from_workspace(tmp_path, ReportConfig())
    (tmp_path / "tracks" / "pose.json").write_text("{not json")
    with pytest.raises(UserError, match="not valid JSON"):
        report_from_workspace(tmp_path, ReportConfig())
    with pytest.raises(UserError, match="too high for 30 frames/s"):
        write_pose_track(tmp_path, walking_params(40))
        report_from_workspace(tmp_path, ReportConfig(cutoff_hz=14.0))


def test_a_synthetic_truth_is_reported_only_when_asked(tmp_path: Path) -> None:
    """A `mocap synth` workspace not tracked yet: its gt/pose.json is no tracked motion."""
    write_pose_track(tmp_path, walking_params(40))
    (tmp_path / "gt").mkdir()
    (tmp_path / "tracks" / "pose.json").rename(tmp_path / "gt" / "pose.json")
    with pytest.raises(UserError, match=r"tracks/pose.json not found.*reported with --truth"):
        report_from_workspace(tmp_path, ReportConfig())
    assert not (tmp_path / "report").exists() and not (tmp_path / "run.json").exists()
    truth = report_from_workspace(tmp_path, ReportConfig(truth=True))
    assert truth.report_dir == tmp_path / "gt" / "report"
    assert truth.recording == tmp_path / "logs" / "report-truth.rrd" and truth.recording.is_file()
    assert truth.summary["source"].endswith("gt/pose.json") and truth.summary["frames"] == 40
    assert list(json.loads((tmp_path / "run.json").read_text())["steps"]) == ["report-truth"]
    assert report_from_workspace(tmp_path, ReportConfig(truth=True)).reused
    with pytest.raises(UserError, match="--truth reports the ground truth"):
        report_from_workspace(tmp_path / "tracked", ReportConfig(truth=True))
    with pytest.raises(UserError, match="not a BVH clip"):
        report_from_bvh(tmp_path / "clip.bvh", tmp_path / "out", ReportConfig(truth=True))


def test_a_single_pose_is_no_motion_to_report(tmp_path: Path) -> None:
    """`mocap fit`'s fit.json is a pose file without a frame rate."""
    path = write_pose_track(tmp_path, walking_params(1))
    data = json.loads(path.read_text())
    del data["frame_rate"]
    path.write_text(json.dumps(data))
    with pytest.raises(UserError, match="without a frame rate .*not a motion to report"):
        report_from_workspace(tmp_path, ReportConfig())


def test_cli_reports_a_workspace(tmp_path: Path) -> None:
    write_pose_track(tmp_path / "ws", walking_params(40))
    ok = run_cli("report", tmp_path / "ws", "--cutoff-hz", "5", "--plot-format", "svg",
                 "--marker-set", "ours")
    assert ok.returncode == 0, ok.stderr
    report = tmp_path / "ws/report"
    assert "cut-off 5 Hz" in ok.stdout and (report / "joint_angles.svg").is_file()
    # SVG plots are embedded too, as data URIs.
    images = _Page((report / "index.html").read_text()).images
    assert [src.partition(",")[0] for src in images] == ["data:image/svg+xml;base64"] * 4
    assert base64.b64decode(images[0].partition(",")[2]) == (
        report / "joint_angles.svg").read_bytes()
    # Our own marker names: all 16 joints.
    assert list(trc_markers(report / "motion.trc")) == list(NODE_NAMES)


@pytest.mark.parametrize(("args", "message"), [
    ((), "give either a workspace"),
    (("nothing",), "tracks/pose.json not found"),
    (("--bvh", "missing.bvh", "--out", "o"), "missing.bvh not found"),
    (("--bvh", "missing.bvh"), "--bvh needs --out DIR"),
])  # fmt: skip
def test_cli_bad_input_gets_one_line_and_exit_2(
    args: tuple[str, ...], message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    from recon.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["report", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err


# ---------------------------------------------------------------------------------------------
# A real CMU clip
# ---------------------------------------------------------------------------------------------

FRAMES = 60  # 0.5 s of the 120 Hz clip keeps the retargeting to a few seconds


@pytest.fixture(scope="module")
def walk_report(tmp_path_factory: pytest.TempPathFactory):
    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    out = tmp_path_factory.mktemp("walk")
    return walk, report_from_bvh(walk, out, ReportConfig(max_frames=FRAMES))


@pytest.mark.shared_data
def test_cmu_walk_round_trip_matches_the_clip(walk_report) -> None:
    walk, result = walk_report
    report = result.report_dir
    assert result.recording == report / "report.rrd" and result.recording.is_file()
    motion = read_bvh(walk)
    truth = {k: v[:FRAMES] for k, v in cmu_node_positions(motion, CMU_METRES_PER_UNIT).items()}
    # Knee flexion against the angle between thigh and shank in the clip itself.
    angles = read_rows(report / "joint_angles.csv")
    for side in "lr":
        thigh = truth[f"{side}_hip"] - truth[f"{side}_knee"]
        shank = truth[f"{side}_ankle"] - truth[f"{side}_knee"]
        cos = np.sum(thigh * shank, axis=1) / np.linalg.norm(thigh, axis=1) / np.linalg.norm(
            shank, axis=1)  # fmt: skip
        clip = 180.0 - np.degrees(np.arccos(cos))
        ours = np.array([float(r["degrees"]) for r in angles
                         if r["joint"] == f"{side}_knee" and r["angle"] == "flexion"])
        # Degrees; the retargeting fits a hinge knee to the clip's 3-DOF one (20 mm RMS).
        assert np.abs(ours - clip).max() < 6.0, side
    # The pelvis marker (Pose2Sim's Hip) sits at the clip's hip midpoint, in the clip's own
    # (Y-up) world.
    hip = trc_markers(report / "motion.trc")["Hip"]
    assert np.linalg.norm(hip - truth["pelvis"], axis=1).max() < 0.03  # metres


@pytest.mark.shared_data
def test_cmu_walk_files_carry_the_nominal_120_hz(walk_report) -> None:
    """Issue 21: CMU's frame time 0.008333 s is 120.0048 Hz, and the TRC read 120.005."""
    walk, result = walk_report
    assert read_bvh(walk).frame_time_s == 0.008333
    lines = (result.report_dir / "motion.trc").read_text().splitlines()
    assert lines[2].split("\t")[:3] == ["120", "120", str(FRAMES)]
    assert lines[2].split("\t")[5] == "120"
    times = [float(line.split("\t")[1]) for line in lines[6:]]
    np.testing.assert_allclose(np.diff(times), 1 / 120, atol=1.5e-6)  # 6 decimals in the file
    mot = (result.report_dir / "motion.mot").read_text().splitlines()
    first = mot.index("endheader") + 2
    assert float(mot[first + 1].split("\t")[0]) - float(mot[first].split("\t")[0]) == (
        pytest.approx(1 / 120, abs=1.5e-6))
    assert result.summary["opensim"]["rate_hz"] == 120


@pytest.mark.shared_data
def test_cmu_walk_angles_stay_within_the_joint_limits(walk_report) -> None:
    _, result = walk_report
    angles = result.summary["angles"]
    deg = np.degrees

    def limit(name: str) -> tuple[float, float]:
        i = PARAM_INDEX[name]
        return deg(LOWER_LIMITS[i]), deg(UPPER_LIMITS[i])

    tol = 1.0  # degrees: the low-pass may overshoot a limit the retargeting stopped at
    hinges = {("l_knee", "flexion"): limit("l_knee_flex"), ("r_knee", "flexion"):
              limit("r_knee_flex"), ("l_elbow", "flexion"): limit("l_elbow_flex"),
              ("r_elbow", "flexion"): limit("r_elbow_flex"), ("spine", "flexion"):
              limit("spine_flex"), ("neck", "flexion"): limit("neck_flex")}  # fmt: skip
    for side in "lr":
        lo, hi = limit(f"{side}_hip_rx")
        hinges[(f"{side}_hip", "flexion")] = (-hi, -lo)  # flexion is -rx
        lo, hi = limit(f"{side}_shoulder_rx")
        hinges[(f"{side}_shoulder", "flexion")] = (-hi, -lo)
    for (joint, angle), (lo, hi) in hinges.items():
        r = angles[joint][angle]
        assert lo - tol <= r["min"] and r["max"] <= hi + tol, (joint, angle, r, (lo, hi))
    # Walking: the knees flex well past 30 degrees somewhere in half a second of gait.
    assert max(angles["l_knee"]["flexion"]["max"], angles["r_knee"]["flexion"]["max"]) > 30
