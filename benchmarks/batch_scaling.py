"""Throughput of `mocap batch` with 1 and with 2 Dask workers: 4 synthetic photo workspaces, then
the silhouettes of one real video workspace.

Photo workspaces: one run renders 4 synthetic rooms (different seeds), then runs sfm → dense →
mesh on fresh workspaces of them, as Dask tasks on a LocalCluster of 1 worker process, then of 2
(one task thread each), and prints workspaces per minute for each and their ratio. COLMAP runs
on one thread per task, so that one task is one core's work and the ratio measures Dask's
scaling (OpenCV's matcher and Open3D still use a second thread here and there, which flatters
the single worker a little). The time is the batch's own, from submission to the last result:
starting the cluster and importing the libraries on the workers are left out. The two runs'
dense clouds are compared, as a check that scheduling changed no result.

Silhouettes: the Pose2Sim demo (4 cameras, 1088x1920 H.264, ../shared/data/pose2sim_demo;
skipped when absent), its first ``--frames`` frames, once in this process (`mocap silhouettes`,
one camera after the other) and as `mocap batch --steps silhouettes` on 1 and on 2 workers:
camera-frames per second, the tasks that ran (a background model per camera, a run of frames
per task) and whether all three wrote the same mask bytes.

    .venv/bin/python benchmarks/batch_scaling.py [--views 8] [--width 480] [--height 360]
                                                 [--frames 48]

Target: ratio ≥ 1.6 on 2 idle cores, for both parts.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from _cli import SHARED_DATA  # benchmarks/ is on sys.path when a script here runs


def main() -> None:
    import pycolmap
    from distributed import LocalCluster

    from recon.batch import BatchConfig, run_batch
    from recon.dense.step import DenseConfig
    from recon.evaluation.synthetic_room import SyntheticSceneConfig, render_scene, write_scene
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from recon.workspace import Workspace

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--workspaces", type=int, default=4)
    parser.add_argument("--frames", type=int, default=48,
                        help="video frames of the silhouettes part (0: skip it)")
    args = parser.parse_args()
    pycolmap.logging.minloglevel = 2  # as `mocap` does without -v; the workers follow it

    size = max(args.width, args.height)
    sfm = SfMConfig(num_threads=1, seed=0, max_image_size=size)
    dense = DenseConfig(dense_max_image_size=size, num_threads=1)
    mesh = MeshConfig()
    with tempfile.TemporaryDirectory(prefix="batch-scaling-") as tmp:
        root = Path(tmp)
        for seed in range(1, args.workspaces + 1):
            scene = render_scene(SyntheticSceneConfig(
                num_views=args.views, width=args.width, height=args.height,
                focal_px=600.0 * args.width / 640, seed=seed))
            write_scene(scene, root / f"photos{seed}", root / f"truth{seed}.json")
        print(f"{args.workspaces} workspaces x {args.views} photos {args.width}x{args.height}, "
              "sfm + dense + mesh, COLMAP on 1 thread per task")
        print("workers  seconds  workspaces/min")
        throughput, clouds = {}, {}
        for workers in (1, 2):
            roots = []
            for seed in range(1, args.workspaces + 1):
                ws, _ = Workspace.create(root / f"w{workers}" / f"ws{seed}", root / f"photos{seed}")
                roots.append(ws.root)
            with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              host="127.0.0.1", dashboard_address=None) as cluster:
                report = run_batch(roots, BatchConfig(scheduler=cluster.scheduler_address),
                                   {"sfm": sfm, "dense": dense, "mesh": mesh})
            if report.failed:
                details = [r.failure.detail or "" for r in report.failed if r.failure]
                raise SystemExit("\n".join([*report.lines(), *details]))
            throughput[workers] = 60.0 * args.workspaces / report.seconds
            clouds[workers] = [_points(Workspace(r).dense_cloud_path) for r in roots]
            steps = "  ".join(
                f"{step} {sum(r.steps[k].seconds for r in report.results):.0f}s"
                for k, step in enumerate(("sfm", "dense", "mesh")))
            print(f"{workers:<8} {report.seconds:7.1f}  {throughput[workers]:6.2f}"
                  f"          (task time: {steps})")
        same = all(np.array_equal(a, b) for a, b in zip(clouds[1], clouds[2], strict=True))
        print(f"ratio 2 vs 1 workers: {throughput[2] / throughput[1]:.2f}")
        print(f"dense clouds identical in both runs: {'yes' if same else 'NO'}")
        if args.frames > 0:
            _silhouettes_scaling(root, args.frames)


def _silhouettes_scaling(root: Path, frames: int) -> None:
    from distributed import Client, LocalCluster, get_task_stream

    from recon.batch import BatchConfig, run_batch
    from recon.workspace import Workspace
    from tracking.rig.video import init_video, workspace_cameras
    from tracking.silhouettes.step import SilhouettesConfig, make_silhouettes

    demo = SHARED_DATA / "pose2sim_demo"
    if not demo.is_dir():
        print(f"silhouettes: skipped ({demo} is absent)")
        return
    config = SilhouettesConfig(last=frames - 1)
    kinds = ("serial", "1", "2")
    for kind in kinds:
        init_video(root / f"video-{kind}", demo / "videos",
                   demo / "calibration" / "Calib.qca.txt")
    cameras = len(workspace_cameras(Workspace(root / "video-serial")))
    print(f"\nsilhouettes of the Pose2Sim demo: {cameras} cameras x {frames} frames, "
          "1088x1920, temporal-median background")
    # Seconds of the step as run.json records them: the same span (background models to the
    # last mask) in this process and in a worker's task.
    print("run        seconds  camera-frames/s  tasks")
    seconds = {}
    seconds["serial"] = make_silhouettes(Workspace(root / "video-serial"), config).seconds
    print(f"{'serial':<10} {seconds['serial']:7.1f}  {cameras * frames / seconds['serial']:8.2f}"
          "          (one process, camera after camera)")
    for workers in (1, 2):
        with (LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None) as cluster,
              Client(cluster) as client, get_task_stream(client) as stream):
            report = run_batch([root / f"video-{workers}"],
                               BatchConfig(scheduler=cluster.scheduler_address,
                                           steps=("silhouettes",)),
                               {"silhouettes": config}, client=client)
        if report.failed:
            details = [r.failure.detail or "" for r in report.failed if r.failure]
            raise SystemExit("\n".join([*report.lines(), *details]))
        record = Workspace(root / f"video-{workers}").step("silhouettes")
        assert record is not None
        seconds[str(workers)] = record.seconds
        keys = [str(t["key"]) for t in stream.data]
        backgrounds = sum(k.startswith("camera_background-") for k in keys)
        runs = sum(k.startswith("frame_silhouettes-") for k in keys)
        checks = sum(k.startswith("frames_consistency-") for k in keys)
        rate = cameras * frames / seconds[str(workers)]
        print(f"{workers} worker{'s' if workers > 1 else ' '} {seconds[str(workers)]:7.1f}  "
              f"{rate:8.2f}          {backgrounds} background + {runs} frame runs + "
              f"{checks} multi-view check runs")
    masks = [Workspace(root / f"video-{kind}").silhouettes_dir for kind in kinds]
    names = sorted(p.relative_to(masks[0]) for p in masks[0].rglob("*.png"))
    same = len(names) == cameras * frames and all(
        (m / n).read_bytes() == (masks[0] / n).read_bytes() for m in masks[1:] for n in names)
    print(f"ratio 2 vs 1 workers: {seconds['1'] / seconds['2']:.2f}")
    print(f"masks identical in all three runs: {'yes' if same else 'NO'}")


def _points(path: Path) -> np.ndarray:
    import open3d as o3d

    return np.asarray(o3d.io.read_point_cloud(str(path)).points)


if __name__ == "__main__":
    main()
