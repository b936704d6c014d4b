"""`mocap batch` on a real Dask LocalCluster (worker processes on loopback) against a serial run.

Two small synthetic rooms (6 photos of 320x240 each) run sfm → dense → mesh once in this
process, one after the other, and once as Dask tasks on two worker processes, with a third
"workspace" that is not one. The Dask run must give the very same files: COLMAP runs on one
thread with a fixed seed (its multi-threaded RANSAC varies run to run), and the mesher is ball
pivoting, because Open3D's Poisson solver sums in thread order and its vertices vary in the
last digits from run to run even serially. The video workspaces' steps, tracking's, are tested
in tests/tracking/test_batch_steps.py; third-party steps here, through faked entry points.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from plugins.protocols import BaseBatchStep, StepResult
from plugins.registry import PluginError
from recon.batch import (
    BatchConfig,
    BatchReport,
    StepStatus,
    map_ordered,
    parse_steps,
    registered_steps,
    run_batch,
    run_workspace,
)
from recon.dense.step import DenseConfig
from recon.errors import UserError
from recon.evaluation.synthetic_room import SyntheticSceneConfig, render_scene, write_scene
from recon.mesh.step import MeshConfig
from recon.sfm.pipeline import SfMConfig, cams_from_world
from recon.workspace import Workspace
from tests.helpers import fake_entry_points, run_cli

SFM = SfMConfig(num_threads=1, seed=0, max_image_size=320, max_num_features=2000)
DENSE = DenseConfig(dense_max_image_size=320, num_threads=1)
MESH = MeshConfig(mesher="ball-pivoting")
SETTINGS = {"sfm": SFM, "dense": DENSE, "mesh": MESH}
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
    serial = [run_workspace(root / f"serial{seed}", settings=SETTINGS) for seed in SEEDS]
    (root / "not-a-workspace").mkdir()
    lines: list[str] = []
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch(
            [root / "dask1", root / "not-a-workspace", root / "dask2"],
            BatchConfig(scheduler=cluster.scheduler_address), SETTINGS, echo=lines.append,
        )
    return root, serial, report, lines, stream.data


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
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


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
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


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
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
    assert parse_steps("mesh, sfm") == ("sfm", "mesh")
    assert parse_steps(None) is None
    with pytest.raises(UserError, match="choose from sfm, dense, mesh, silhouettes, track"):
        parse_steps("sfm,fly")
    with pytest.raises(UserError, match="given twice"):
        run_batch(["ws", "./ws"], BatchConfig(scheduler="tcp://127.0.0.1:1"))
    result = run_cli("batch", "ws", "--steps", "sfm,fly")
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "mocap batch: error: --steps 'sfm,fly': choose from sfm, dense, mesh, silhouettes, "
        "track, report (comma-separated)")
    result = run_cli("batch", "ws", "--scheduler", "/nonexistent/scheduler.json")
    assert result.returncode == 2
    assert result.stderr.strip().endswith("no such scheduler file")


def test_serial_run_skips_the_steps_after_a_failure(tmp_path):
    result = run_workspace(tmp_path / "nothing", ("mesh", "dense"))
    assert [s.step for s in result.steps] == ["dense", "mesh"]
    assert [s.status for s in result.steps] == [StepStatus.FAILED, StepStatus.SKIPPED]
    assert isinstance(BatchReport((result,), 0.0).lines()[0], str)


# Steps as plugins --------------------------------------------------------------------------
class EchoStep(BaseBatchStep):
    """A third-party step after the photo pipeline's last: its settings back as its summary."""

    description = "says its settings"
    workspace = "photo"
    follows = "mesh"

    def settings(self, args):
        return "default words"

    def run(self, workspace, settings, *, overwrite):
        return StepResult(summary={"said": settings})

    def figure(self, summary):
        return f"[{summary['said']}]"


class NoRun:
    description = "broken: no run method"
    workspace = "photo"
    follows = None


def test_a_registered_step_extends_its_kind_pipeline(monkeypatch, tmp_path):
    fake_entry_points(monkeypatch, "mocap.steps", echo=f"{__name__}:EchoStep")
    steps = registered_steps()
    assert steps.of_kind("photo") == ("sfm", "dense", "mesh", "echo")
    assert parse_steps("echo,sfm", steps) == ("sfm", "echo")
    photo = tmp_path / "photo"
    (photo / "images").mkdir(parents=True)
    result = run_workspace(photo, ("echo",), {"echo": "hello"})
    assert [(s.step, s.status, s.summary) for s in result.steps] == [
        ("echo", StepStatus.DONE, {"said": "hello"})]
    assert "echo" in result.line() and "[hello]" in result.line()
    assert run_workspace(photo, ("echo",)).steps[0].summary == {"said": "default words"}
    # Not its kind: skipped with the reason, nothing fails.
    video = tmp_path / "video"
    video.mkdir()
    (video / "cameras.json").write_text("{}")
    skipped = run_workspace(video, ("echo",))
    assert skipped.ok and skipped.steps[0].status is StepStatus.SKIPPED
    assert skipped.steps[0].reason == "not a photo workspace (it has cameras.json)"
    with pytest.raises(UserError, match="settings of unknown batch step"):
        run_workspace(photo, ("echo",), {"ecco": "typo"})


def test_a_broken_step_is_set_aside_and_named_when_asked_for(monkeypatch):
    fake_entry_points(monkeypatch, "mocap.steps", norun=f"{__name__}:NoRun",
                      gone="no_such_module_xyz:Step")
    steps = registered_steps()
    assert set(steps.broken) == {"norun", "gone"}
    assert steps.names == ("sfm", "dense", "mesh", "silhouettes", "track", "report")
    with pytest.raises(PluginError, match="has no `run` method"):
        parse_steps("sfm,norun", steps)
    with pytest.raises(PluginError, match="failed to import"):
        parse_steps("gone", steps)


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
