"""`mocap batch` on video workspaces: tracking's batch steps (tracking/batch_steps.py),
``silhouettes`` → ``track``, on a real Dask LocalCluster against a serial run."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from recon.batch import (
    BatchConfig,
    StepStatus,
    parse_steps,
    registered_steps,
    run_batch,
    run_workspace,
)
from recon.workspace import Workspace
from tests.helpers import shared_dataset
from tests.tracking.rig.test_video import make_ball_scene
from tracking.rig.synth import SynthConfig, synthesize
from tracking.silhouettes.step import SilhouettesConfig
from tracking.track.tracker import TrackConfig

TRACK = {"track": TrackConfig(init_simplex_evals=40)}  # small budgets: ~10 s a sequence


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    # Processes, as on a real cluster: tasks and their data are pickled between them.
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:
        yield cluster


def test_video_steps_are_the_video_pipeline(tmp_path):
    steps = registered_steps()
    # The video pipeline is `mocap capture`'s after init-video.
    assert steps.of_kind("video") == ("silhouettes", "track", "report")
    assert parse_steps("track,silhouettes") == ("silhouettes", "track")
    # A photo workspace is not theirs: skipped with the reason, nothing fails.
    (tmp_path / "images").mkdir()
    result = run_workspace(tmp_path, ("silhouettes", "track"))
    assert result.ok
    assert [(s.status, s.reason) for s in result.steps] == [
        (StepStatus.SKIPPED, "not a video workspace (no cameras.json)")] * 2
    # A video workspace's default steps are its kind's.
    (tmp_path / "cameras.json").write_text("{}")
    assert [s.step for s in run_workspace(tmp_path).steps] == ["silhouettes", "track", "report"]


@pytest.mark.slow
@pytest.mark.shared_data
def test_tracking_sequences_on_dask_equal_a_serial_run(cluster, tmp_path):
    """Two synthetic sequences as parallel Dask chains (one tracking task each) against serial
    runs: the same tracks. Their silhouettes are given, so that step is skipped, not failed."""
    from distributed import Client, get_task_stream

    walk = shared_dataset("mocap_bvh") / "cmu_02_01_walk.bvh"
    for fov in (50, 55):  # two sequences, as from two camera set-ups
        for kind in ("serial", "dask"):
            synthesize(tmp_path / f"{kind}{fov}", SynthConfig(
                bvh=walk, frames=3, cameras=3, size="160x120", fov_deg=fov, clean=True))
    serial = [run_workspace(tmp_path / f"serial{fov}", settings=TRACK) for fov in (50, 55)]
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch([tmp_path / "dask50", tmp_path / "dask55"],
                           BatchConfig(scheduler=cluster.scheduler_address), TRACK)
    for result in (*serial, *report.results):
        assert result.ok, result.line()
        assert [(s.step, s.status, s.reason) for s in result.steps] == [
            ("silhouettes", StepStatus.SKIPPED, "silhouettes given (synthetic)"),
            ("track", StepStatus.DONE, None), ("report", StepStatus.DONE, None)]
        assert "silhouettes skipped (silhouettes given (synthetic))" in result.line()
    for fov in (50, 55):
        a, b = (tmp_path / f"{kind}{fov}" / "tracks" for kind in ("serial", "dask"))
        pose_a, pose_b = (json.loads((t / "pose.json").read_text()) for t in (a, b))
        assert len(pose_a["frames"]) == 3 and pose_a["frames"][0]["params"] is not None
        # Worker processes may round differently in the last bit (1e-15 seen): equal to 1e-9.
        np.testing.assert_allclose([f["params"] for f in pose_a["frames"]],
                                   [f["params"] for f in pose_b["frames"]], rtol=0, atol=1e-9)
        assert (a / "joints.csv").read_bytes() == (b / "joints.csv").read_bytes()
    track_tasks = [t for t in stream.data if str(t["key"]).startswith("mocap-track-")]
    assert len(track_tasks) == 2  # one sequential task per sequence
    # Photo steps do not apply to a video workspace: skipped with the reason, nothing fails.
    skipped = run_workspace(tmp_path / "serial50", ("sfm", "track"), TRACK)
    assert skipped.ok and [s.status for s in skipped.steps] == [StepStatus.SKIPPED,
                                                                StepStatus.REUSED]
    assert skipped.steps[0].reason == "not a photo workspace (it has cameras.json)"


@pytest.mark.slow  # its path is covered faster elsewhere (make test's 10-minute budget)
def test_silhouettes_per_camera_and_frames_on_dask_equal_a_serial_run(cluster, tmp_path):
    """A real-video workspace: a task per camera's background model, then a task per run of
    frames of each camera, then a task per run of frames for the multi-view check, give the
    very masks (PNG bytes) and summary of the serial step."""
    from distributed import Client, get_task_stream

    from tracking.rig.video import init_video
    from tracking.silhouettes.step import frame_chunks

    cameras, frames = 3, 30
    videos, calibration, photos, _ = make_ball_scene(tmp_path / "scene", cameras=cameras,
                                                     frames=frames)
    for kind in ("serial", "dask"):
        init_video(tmp_path / kind, videos, calibration)
    settings = {"silhouettes": SilhouettesConfig(background_images=photos)}
    serial = run_workspace(tmp_path / "serial", ("silhouettes",), settings)
    with Client(cluster) as client, get_task_stream(client) as stream:
        report = run_batch([tmp_path / "dask"], BatchConfig(
            scheduler=cluster.scheduler_address, steps=("silhouettes",)), settings)
    for result in (serial, report.results[0]):
        assert [(s.step, s.status) for s in result.steps] == [
            ("silhouettes", StepStatus.DONE)], result.line()
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
