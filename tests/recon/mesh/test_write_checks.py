"""write_mesh on a full disk: an OSError, no partial file, and the old files untouched."""

from __future__ import annotations

import open3d as o3d
import pytest

from recon.mesh.meshing import write_mesh
from tests import helpers


@pytest.fixture
def small_disk(tmp_path):
    with helpers.small_disk(tmp_path / "disk", 1 << 20) as disk:
        yield disk


def _sphere(resolution: int) -> o3d.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)
    mesh.compute_vertex_normals()
    mesh.paint_uniform_color([0.5, 0.2, 0.1])
    return mesh


def test_a_full_disk_raises_and_keeps_the_old_files(small_disk, capfd):
    old = {s: b"old " + s.encode() for s in ("ply", "obj", "glb")}
    for suffix, data in old.items():
        (small_disk / f"mesh.{suffix}").write_bytes(data)
    called = []
    with pytest.raises(OSError):  # about 1.5 MB of PLY alone (a 40,000-vertex sphere)
        write_mesh(_sphere(140), small_disk / "mesh.ply", before_replace=lambda: called.append(1))
    assert not called
    assert {p.name: p.read_bytes() for p in small_disk.iterdir()} == {
        f"mesh.{s}": data for s, data in old.items()}
    assert "RPly" not in capfd.readouterr().err


def test_before_replace_runs_after_every_file_is_written(tmp_path):
    seen = []
    write_mesh(_sphere(10), tmp_path / "mesh.ply",
               before_replace=lambda: seen.append(sorted(p.name for p in tmp_path.iterdir())))
    assert seen == [["mesh.partial.glb", "mesh.partial.obj", "mesh.partial.ply"]]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.glb", "mesh.obj", "mesh.ply"]


def test_a_failing_before_replace_replaces_nothing(tmp_path):
    def fail() -> None:
        raise RuntimeError("recording failed")

    with pytest.raises(RuntimeError):
        write_mesh(_sphere(10), tmp_path / "mesh.ply", before_replace=fail)
    assert list(tmp_path.iterdir()) == []
