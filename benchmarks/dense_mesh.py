"""Dense + mesh time against SfM time on fountain_p11 at a 1024-pixel maximum side, one run.

    .venv/bin/python benchmarks/dense_mesh.py [--images DIR] [--keep DIR]

Each stage runs as the CLI a user would type (`mocap sfm`, `mocap dense`, `mocap mesh`), in a
fresh process; its wall time and the peak resident memory of its process are measured. Then
the mesh is checked against COLMAP's own sparse points (median distance relative to the scene
extent) and rendered to a PNG for a person to look at.

Target (issue 4): dense + mesh <= 1.5 x sfm on 2 cores.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _cli import SHARED_DATA  # benchmarks/ is on sys.path when a script here runs

ROOT = Path(__file__).resolve().parents[1]
FOUNTAIN = SHARED_DATA / "fountain_p11" / "images"
SIZE = "1024"


def _stage(*args: str) -> tuple[float, float]:
    """(seconds, peak RSS in MB) of one `mocap` command in its own process."""
    start = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    result = subprocess.run([sys.executable, "-m", "recon.cli", *args], capture_output=True,
                            text=True)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        sys.exit(f"mocap {' '.join(args)} failed:\n{result.stderr}")
    # ru_maxrss of children is the largest child so far (kB on Linux); stages grow in memory
    # in this order, and the first stage's figure stands alone.
    peak = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) / 1024
    return seconds, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=Path, default=FOUNTAIN)
    parser.add_argument("--keep", type=Path, help="keep the workspace in this folder")
    args = parser.parse_args()
    if not args.images.is_dir():
        sys.exit(f"{args.images} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        ws = (args.keep or Path(tmp)) / "fountain"
        t_sfm, m_sfm = _stage("sfm", str(ws), "--images", str(args.images),
                              "--max-image-size", SIZE, "--overwrite")
        t_dense, m_dense = _stage("dense", str(ws), "--dense-max-image-size", SIZE, "--overwrite")
        t_mesh, m_mesh = _stage("mesh", str(ws), "--overwrite")
        figures = _quality(ws, Path(args.keep or ROOT / "workspaces") / "fountain_mesh.png")
    print(f"images: {args.images} at {SIZE} px max side")
    print(f"sfm          {t_sfm:7.1f} s   peak {m_sfm:7.0f} MB")
    print(f"dense        {t_dense:7.1f} s   peak {m_dense:7.0f} MB")
    print(f"mesh         {t_mesh:7.1f} s   peak {m_mesh:7.0f} MB")
    ratio = (t_dense + t_mesh) / t_sfm
    print(f"ratio (dense + mesh) / sfm: {ratio:.2f}  (target <= 1.5)  "
          f"{'PASS' if ratio <= 1.5 else 'FAIL'}")
    for key, value in figures.items():
        print(f"{key:<44} {value}")


def _quality(ws: Path, picture: Path) -> dict[str, str]:
    import open3d as o3d
    import pycolmap

    from recon.evaluation.surface import points_to_mesh_distance, render_mesh_png

    model = pycolmap.Reconstruction(ws / "sparse" / "0")
    points = np.array([p.xyz for p in model.points3D.values()])
    mesh = o3d.io.read_triangle_mesh(str(ws / "mesh" / "mesh.ply"))
    cloud = o3d.io.read_point_cloud(str(ws / "dense" / "fused.ply"))
    # Scene extent: the diagonal of the central 98% of the sparse points (a few stray points
    # far away would otherwise set it).
    lo, hi = np.percentile(points, [1, 99], axis=0)
    extent = float(np.linalg.norm(hi - lo))
    distances = points_to_mesh_distance(points, mesh)
    # Seen from the middle photo's camera (pulled back a little), so it can be compared.
    images = sorted(model.images.values(), key=lambda im: im.name)
    middle = images[len(images) // 2]
    camera = model.cameras[middle.camera_id]
    cam_from_world = middle.cam_from_world().matrix()
    cam_from_world[2, 3] += 0.3 * extent
    K = camera.calibration_matrix() * np.array([[1000 / camera.width], [700 / camera.height],
                                                 [1]])
    picture.parent.mkdir(parents=True, exist_ok=True)
    render_mesh_png(mesh, picture, width=1000, height=700, camera=(K, cam_from_world))
    return {
        "sparse points": str(len(points)),
        "dense points": str(len(cloud.points)),
        "mesh vertices / faces": f"{len(mesh.vertices)} / {len(mesh.triangles)}",
        "median sparse-point-to-mesh distance / extent": f"{np.median(distances) / extent:.5f}",
        "90th percentile / extent": f"{np.percentile(distances, 90) / extent:.5f}",
        "picture": str(picture),
    }


if __name__ == "__main__":
    main()
