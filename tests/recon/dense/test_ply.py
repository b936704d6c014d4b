"""PLY checks of the dense and mesh steps: a damaged file is called damaged, not empty."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from recon.dense.ply import PlyError, check_ply, parse_header, payload_size

HEADER = (b"ply\nformat binary_little_endian 1.0\ncomment Created by Open3D\n"
          b"element vertex 10\nproperty double x\nproperty double y\nproperty double z\n"
          b"property uchar red\nproperty uchar green\nproperty uchar blue\n"
          b"element face 4\nproperty list uchar uint vertex_indices\nend_header\n")


def test_header_counts_and_payload_size():
    header = parse_header(HEADER + b"\0" * 10)
    assert header.format == "binary_little_endian"
    assert (header.count("vertex"), header.count("face"), header.count("edge")) == (10, 4, 0)
    assert header.header_bytes == len(HEADER)
    assert payload_size(header) == 10 * (3 * 8 + 3) + 4 * (1 + 3 * 4)


@pytest.mark.parametrize(("data", "message"), [
    (b"\x89PNG\r\n\x1a\n" + b"\0" * 100, "not a PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n", "no end_header"),
    (HEADER.replace(b"property double y", b"property quad y"), "header line 6"),
    (HEADER.replace(b"binary_little_endian", b"binary_middle_endian"), "format"),
    (HEADER[:-1], "ends in its header"),
])
def test_broken_headers_are_named(data, message):
    with pytest.raises(PlyError, match=message):
        parse_header(data)


def _cloud(n: int) -> o3d.geometry.PointCloud:
    rng = np.random.default_rng(0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.random((n, 3))))
    cloud.normals = o3d.utility.Vector3dVector(rng.random((n, 3)))
    cloud.colors = o3d.utility.Vector3dVector(rng.random((n, 3)))
    return cloud


def test_an_open3d_cloud_checks_and_a_cut_one_does_not(tmp_path):
    from recon.dense.step import cloud_file_size

    path = tmp_path / "fused.ply"
    cloud = _cloud(1000)
    assert o3d.io.write_point_cloud(str(path), cloud)
    header = check_ply(path, vertices=1000)
    assert payload_size(header) == cloud_file_size(cloud)  # the free-space estimate is exact
    with pytest.raises(PlyError, match="declares 1000 vertex elements, not 999"):
        check_ply(path, vertices=999)
    data = path.read_bytes()
    path.write_bytes(data[:-51])  # one point (48 + 3 bytes) short
    with pytest.raises(PlyError, match=r"truncated: the header declares vertex 1000 \(51000 "
                                       r"bytes\), the file holds 50949"):
        check_ply(path)
    path.write_bytes(data + b"\0")
    with pytest.raises(PlyError, match="longer than its header says"):
        check_ply(path)


def test_ascii_files_are_checked_by_header_only(tmp_path):
    path = tmp_path / "a.ply"
    assert o3d.io.write_point_cloud(str(path), _cloud(10), write_ascii=True)
    assert check_ply(path, vertices=10).format == "ascii"


def test_write_cloud_fails_in_one_line_when_the_writer_fails_silently(tmp_path, monkeypatch):
    """Open3D reports success for a write that failed (a full disk): past the free-space
    check, the read-back of the header and size catches it."""
    from recon.dense import step
    from recon.errors import UserError
    from tests.helpers import small_disk

    with small_disk(tmp_path / "disk", 512 * 1024) as disk:
        monkeypatch.setattr(step, "check_free_space", lambda *args: None)
        with pytest.raises(UserError, match=r"cannot write .*fused\.ply: no space left"):
            step.write_cloud(disk / "fused.partial.ply", _cloud(20_000),
                             target=disk / "fused.ply")
