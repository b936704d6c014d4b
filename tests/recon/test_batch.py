"""`mocap batch` on a real Dask LocalCluster (worker processes on loopback) against a serial run.

Two small synthetic rooms (6 photos of 320x240 each) run sfm → dense → mesh once in this
process, one after the other, and once as Dask tasks on two worker processes, with a third
"workspace" that is not one. The Dask run must give the very same files: COLMAP runs on one
thread with a fixed seed (its multi-threaded RANSAC varies run to run), and the mesher is ball
pivoting, because Open3D's Poisson solver sums in thread order and its vertices vary in the
last digits from run to run even serially.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import pytest

from recon.batch import (
    BatchConfig,
    BatchReport,
    BatchStep,
    StepStatus,
    map_ordered,
    parse_steps,
    run_batch,
    run_workspace,
)
from recon.dense.step import DenseConfig
from recon.errors import UserError
from recon.evaluation.synthetic_room import SyntheticSceneConfig, render_scene, write_scene
from recon.mesh.step import MeshConfig
from recon.sfm.pipeline import SfMConfig, cams_from_world
from recon.workspace import Workspace
from tests.helpers import run_cli, shared_dataset
from tracking.rig.synth import SynthConfig, synthesize
from tracking.silhouettes.step import SilhouettesConfig
from tracking.track.tracker import TrackConfig

SFM = SfMConfig(num_threads=1, seed=0, max_image_size=320, max_num_features=2000)
DENSE = DenseConfig(dense_max_image_size=320, num_threads=1)
MESH = MeshConfig(mesher="ball-pivoting")
SETTINGS_FLAGS = ("--num-threads", "1", "--max-image-size", "320", "--max-num-features", "2000",
                  "--dense-max-image-size", "320", "--mesher", "ball-pivoting")
SEEDS = (1, 2)


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    # Processes, as on a real cluster: tasks and their data are pickled between them.
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:
        yield cluster


@pytest.fixture(scope="module")
def runs(tmp_path_factory, cluster):
    """Serial and Dask runs of the same two rooms; the Dask batch also gets a non-workspace."""
    from distributed import Client, get_task_stream

    root = tmp_path_factory.mktemp("batch")
    for seed in SEEDS:
        scene = render_scene(SyntheticSceneConfig(num_views=6, width=320, height=240,
                                                  focal_px=300.0, seed=seed, supersample=1))
        write_scene(scene, root / f"photos{seed}", root / f"truth{seed}.json")
        for kind in ("serial", "dask"):
            Workspace.create(root / f"{kind}{seed}", root / f"photos{seed}")
    serial = [run_workspace(root / f"serial{seed}", sfm=SFM, dense=DENSE, mesh=MESH)
              for seed in SEEDS]
    (root / "not-a-workspace").mkdir()
    lines: list[str] = []
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch(
            [root / "dask1", root / "not-a-workspace", root / "dask2"],
            BatchConfig(scheduler=cluster.scheduler_address), SFM, DENSE, MESH, echo=lines.append,
        )
    return root, serial, report, lines, stream.data


def test_dask_run_gives_the_files_of_a_serial_run(runs):
    root, serial, report, lines, _ = runs
    assert all(r.ok for r in serial), [r.line() for r in serial]
    assert [r.ok for r in report.results] == [True, False, True]
    for seed in SEEDS:
        a, b = Workspace(root / f"serial{seed}"), Workspace(root / f"dask{seed}")
        steps_a, steps_b = a.read_run()["steps"], b.read_run()["steps"]
        assert set(steps_a) == set(steps_b) >= {"mapping", "dense", "mesh"}
        for name in steps_a:
            assert steps_a[name]["fingerprint"] == steps_b[name]["fingerprint"], name
            assert steps_a[name]["summary"] == steps_b[name]["summary"], name

        model_a, model_b = (pycolmap.Reconstruction(ws.model_dir) for ws in (a, b))
        poses_a, poses_b = cams_from_world(model_a), cams_from_world(model_b)
        assert len(poses_a) == 6 and poses_a.keys() == poses_b.keys()
        for name in poses_a:
            np.testing.assert_array_equal(poses_a[name], poses_b[name])
        xyz_a, xyz_b = (np.array([p.xyz for _, p in sorted(m.points3D.items())])
                        for m in (model_a, model_b))
        np.testing.assert_array_equal(xyz_a, xyz_b)

        cloud_a, cloud_b = (_read_cloud(ws.dense_cloud_path) for ws in (a, b))
        assert len(cloud_a[0]) > 50_000
        for x, y in zip(cloud_a, cloud_b, strict=True):
            np.testing.assert_array_equal(x, y)
        mesh_a, mesh_b = (_read_mesh(ws.mesh_dir / "mesh.ply") for ws in (a, b))
        assert len(mesh_a[1]) > 10_000
        for x, y in zip(mesh_a, mesh_b, strict=True):
            np.testing.assert_array_equal(x, y)

    # The stereo pairs ran as tasks of their own, one per pair of each workspace.
    stream = runs[4]
    pair_tasks = [t for t in stream if str(t["key"]).startswith("stereo_pair_depths")]
    pairs = sum(r.steps[1].summary["pairs"] for r in report.results if r.ok)
    assert len(pair_tasks) == pairs > 0
    assert lines[0].startswith("scheduler   tcp://127.0.0.1:")
    assert lines[1].startswith("dashboard   http://127.0.0.1:")


def test_a_failed_workspace_is_reported_and_the_others_finish(runs):
    root, _, report, _, _ = runs
    bad = report.results[1]
    assert [s.status for s in bad.steps] == [StepStatus.FAILED, StepStatus.SKIPPED,
                                             StepStatus.SKIPPED]
    assert bad.failure is not None and "is not a workspace" in bad.failure.error
    assert bad.failure.detail is None  # a UserError: one line, no traceback
    lines = report.lines()
    assert "FAILED at sfm" in lines[1] and "not-a-workspace" in lines[1]
    assert lines[-1].startswith("done        2 of 3 workspaces") and "(1 failed)" in lines[-1]
    for good in (report.results[0], report.results[2]):
        assert [s.status for s in good.steps] == [StepStatus.DONE] * 3


def test_a_rerun_from_the_cli_reuses_every_finished_step(runs):
    """No --scheduler: the CLI starts its own LocalCluster; every step resumes from run.json."""
    root, _, _, _, _ = runs
    workspaces = [root / "dask1", root / "not-a-workspace", root / "dask2"]
    finished = {ws: _finished(ws) for ws in (workspaces[0], workspaces[2])}
    result = run_cli("batch", *workspaces, "--workers", "2", "--threads-per-worker", "1",
                     *SETTINGS_FLAGS)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines()[-1] == (
        "mocap batch: error: 1 of 3 workspaces failed")
    assert result.stdout.count("(reused)") == 6  # 3 steps x 2 workspaces
    assert "scheduler   tcp://127.0.0.1:" in result.stdout
    assert "dashboard   http://" in result.stdout
    assert {ws: _finished(ws) for ws in finished} == finished  # nothing was rewritten


def test_map_ordered_keeps_input_order_on_a_cluster(cluster):
    from distributed import Client

    items = list(range(6))
    with Client(cluster) as client:
        # Later items finish first: results must still come back in input order.
        on_cluster = map_ordered(client, _slow_add, items, 10)
    assert on_cluster == map_ordered(None, _slow_add, items, 10) == [10, 11, 12, 13, 14, 15]
    assert map_ordered(None, _slow_add, [], 1) == []


def test_steps_and_bad_input():
    assert parse_steps("mesh, sfm") == (BatchStep.SFM, BatchStep.MESH)
    assert parse_steps("track,silhouettes") == (BatchStep.SILHOUETTES, BatchStep.TRACK)
    assert parse_steps(None) is None
    with pytest.raises(UserError, match="choose from sfm, dense, mesh, silhouettes, track"):
        parse_steps("sfm,fly")
    with pytest.raises(UserError, match="given twice"):
        run_batch(["ws", "./ws"], BatchConfig(scheduler="tcp://127.0.0.1:1"))
    result = run_cli("batch", "ws", "--steps", "sfm,fly")
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "mocap batch: error: --steps 'sfm,fly': choose from sfm, dense, mesh, silhouettes, "
        "track (comma-separated)")
    result = run_cli("batch", "ws", "--scheduler", "/nonexistent/scheduler.json")
    assert result.returncode == 2
    assert result.stderr.strip().endswith("no such scheduler file")


def test_serial_run_skips_the_steps_after_a_failure(tmp_path):
    result = run_workspace(tmp_path / "nothing", (BatchStep.DENSE, BatchStep.MESH))
    assert [s.step for s in result.steps] == [BatchStep.DENSE, BatchStep.MESH]
    assert [s.status for s in result.steps] == [StepStatus.FAILED, StepStatus.SKIPPED]
    assert isinstance(BatchReport((result,), 0.0).lines()[0], str)


# Video workspaces ---------------------------------------------------------------------------
TRACK = TrackConfig(init_simplex_evals=40)  # small budgets: ~10 s a sequence


@pytest.mark.slow
def test_tracking_sequences_on_dask_equal_a_serial_run(cluster, tmp_path):
    """Two synthetic sequences as parallel Dask chains (one tracking task each) against serial
    runs: the same tracks. Their silhouettes are given, so that step is skipped, not failed."""
    from distributed import Client, get_task_stream

    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    for fov in (50, 55):  # two sequences, as from two camera set-ups
        for kind in ("serial", "dask"):
            synthesize(tmp_path / f"{kind}{fov}", SynthConfig(
                bvh=walk, frames=3, cameras=3, size="160x120", fov_deg=fov, clean=True))
    serial = [run_workspace(tmp_path / f"serial{fov}", track=TRACK) for fov in (50, 55)]
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch([tmp_path / "dask50", tmp_path / "dask55"],
                           BatchConfig(scheduler=cluster.scheduler_address), track=TRACK)
    for result in (*serial, *report.results):
        assert result.ok, result.line()
        assert [(s.step, s.status, s.reason) for s in result.steps] == [
            (BatchStep.SILHOUETTES, StepStatus.SKIPPED, "silhouettes given (synthetic)"),
            (BatchStep.TRACK, StepStatus.DONE, None)]
        assert "silhouettes skipped (silhouettes given (synthetic))" in result.line()
    for fov in (50, 55):
        a, b = (tmp_path / f"{kind}{fov}" / "tracks" for kind in ("serial", "dask"))
        pose_a, pose_b = (json.loads((t / "pose.json").read_text()) for t in (a, b))
        assert len(pose_a["frames"]) == 3 and pose_a["frames"][0]["params"] is not None
        assert [f["params"] for f in pose_a["frames"]] == [f["params"] for f in pose_b["frames"]]
        assert pose_a == pose_b
        assert (a / "joints.csv").read_bytes() == (b / "joints.csv").read_bytes()
    track_tasks = [t for t in stream.data if str(t["key"]).startswith("mocap-track-")]
    assert len(track_tasks) == 2  # one sequential task per sequence
    # Photo steps do not apply to a video workspace: skipped with the reason, nothing fails.
    skipped = run_workspace(tmp_path / "serial50", (BatchStep.SFM, BatchStep.TRACK), track=TRACK)
    assert skipped.ok and [s.status for s in skipped.steps] == [StepStatus.SKIPPED,
                                                                StepStatus.REUSED]
    assert skipped.steps[0].reason == "not a photo workspace (it has cameras.json)"


def test_silhouettes_per_camera_and_frames_on_dask_equal_a_serial_run(cluster, tmp_path):
    """A real-video workspace: a task per camera's background model, then a task per run of
    frames of each camera, then a task per run of frames for the multi-view check, give the
    very masks (PNG bytes) and summary of the serial step."""
    from distributed import Client, get_task_stream

    from tests.tracking.rig.test_video import make_ball_scene
    from tracking.rig.video import init_video
    from tracking.silhouettes.step import frame_chunks

    cameras, frames = 3, 30
    videos, calibration, photos, _ = make_ball_scene(tmp_path / "scene", cameras=cameras,
                                                     frames=frames)
    for kind in ("serial", "dask"):
        init_video(tmp_path / kind, videos, calibration)
    settings = SilhouettesConfig(background_images=photos)
    serial = run_workspace(tmp_path / "serial", (BatchStep.SILHOUETTES,), silhouettes=settings)
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch([tmp_path / "dask"], BatchConfig(
            scheduler=cluster.scheduler_address, steps=(BatchStep.SILHOUETTES,)),
            silhouettes=settings)
    for result in (serial, report.results[0]):
        assert [(s.step, s.status) for s in result.steps] == [
            (BatchStep.SILHOUETTES, StepStatus.DONE)], result.line()
    # The runs' results were merged in frame order, as the serial loop lists them; a light
    # flashing in cam00's video alone is removed by the multi-view check.
    summary = serial.steps[0].summary
    assert summary["cameras"]["cam00"]["hull_removed"]["max"] > 0.1
    assert summary == report.results[0].steps[0].summary

    keys = [str(t["key"]) for t in stream.data]
    assert sum(k.startswith("camera_background-") for k in keys) == cameras
    runs = frame_chunks(list(range(frames)))
    assert [len(r) for r in runs] == [10, 10, 10]
    # Each run of each camera ran as a task: more tasks than cameras classified frames.
    assert sum(k.startswith("frame_silhouettes-") for k in keys) == cameras * len(runs) > cameras
    assert sum(k.startswith("frames_consistency-") for k in keys) == len(runs)
    assert not any(k.startswith("camera_silhouettes") for k in keys)

    a, b = (Workspace(tmp_path / kind).silhouettes_dir for kind in ("serial", "dask"))
    names = sorted(p.relative_to(a) for p in a.rglob("*.png"))
    assert len(names) == cameras * frames + 1  # and cam00/unknown.png (its photo's block)
    assert names == sorted(p.relative_to(b) for p in b.rglob("*.png"))
    assert all(cv2.imread(str(a / n), cv2.IMREAD_GRAYSCALE).any() for n in names)
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert not list(tmp_path.glob("dask/silhouettes*partial*"))


def _slow_add(item: int, offset: int) -> int:
    time.sleep(0.05 * (6 - item))
    return item + offset


def _read_cloud(path: Path) -> tuple[np.ndarray, ...]:
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(str(path))
    return np.asarray(cloud.points), np.asarray(cloud.colors), np.asarray(cloud.normals)


def _read_mesh(path: Path) -> tuple[np.ndarray, ...]:
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles), np.asarray(mesh.vertex_colors)


def _finished(ws: Path) -> dict[str, str]:
    steps = json.loads((ws / "run.json").read_text())["steps"]
    return {name: step["finished"] for name, step in steps.items()}
