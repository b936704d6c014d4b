"""Robustness table: the dense and mesh steps under bad options, a full disk and a damaged
cloud (issue 23). Each row runs `mocap` as a user does (tests.robustness.harness).

Full-disk rows put the workspace on a small tmpfs (root only; skipped otherwise), sized from
the measured sizes of the scene's outputs so that the step fails at the write in question.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers import mount_small_disk, run_cli, unmount_small_disk
from tests.robustness import scenes
from tests.robustness.harness import Case, assert_clean_success, check_case, rows
from tests.robustness.scenes import workspace

MiB = 1 << 20


# Helpers ---------------------------------------------------------------------------------------
def _steps(ws: Path) -> dict:
    return json.loads((ws / "run.json").read_text()).get("steps", {})


def _tmpfs_bytes(root: Path) -> int:
    """What the files under ``root`` take on a tmpfs (whole 4 KiB pages)."""
    return sum(-(-p.stat().st_size // 4096) * 4096 for p in root.rglob("*") if p.is_file())


def _assert_no_leftovers(ws: Path) -> None:
    partial = [p for p in ws.rglob("*") if ".partial" in p.name or p.name.endswith(".old")]
    assert not partial, partial
    assert not list(ws.glob(".dense-*"))


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _on_tmpfs(stage: str, spare: int):
    """Setup: the ``stage`` workspace copied onto a tmpfs with ``spare(stage sizes)`` bytes
    free beyond it."""

    def setup(folder: Path) -> None:
        source = scenes.built_workspace(stage)
        ws = mount_small_disk(folder / "ws", _tmpfs_bytes(source) + spare)
        shutil.copytree(source, ws, symlinks=True, dirs_exist_ok=True)

    return setup


def _unmount(folder: Path) -> None:
    unmount_small_disk(folder / "ws")


def _size(stage: str, relative: str) -> int:
    path = scenes.built_workspace(stage) / relative
    return _tmpfs_bytes(path) if path.is_dir() else -(-path.stat().st_size // 4096) * 4096


def _cloud_does_not_fit() -> int:
    # The undistorted photos fit, fused.ply (about 7 MB here) does not.
    return _size("dense", "dense/undistorted") + MiB


def _recording_does_not_fit() -> int:
    # fused.ply fits, then logs/dense.rrd (about 2.7 MB) does not.
    return _size("dense", "dense/undistorted") + _size("dense", "dense/fused.ply") + MiB


# Then checks -------------------------------------------------------------------------------
def _no_work_done(step: str, output: str):
    def then(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
        ws = folder / "ws"
        assert step not in _steps(ws)
        assert not (ws / output).exists(), f"{output} was made before the option was checked"
        _assert_no_leftovers(ws)

    return then


def _dense_failed_cleanly(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    assert "dense" not in _steps(ws)
    assert not (ws / "dense" / "fused.ply").exists()
    assert not (ws / "logs" / "dense.rrd").exists()
    assert "RPly" not in result.stderr
    _assert_no_leftovers(ws)


def _dense_kept_previous(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    # The failed --overwrite left the cloud and its record as they were: it is reused.
    ws = folder / "ws"
    before = _digest(ws / "dense" / "fused.ply")
    _assert_no_leftovers(ws)
    result = run_cli("dense", ws)
    assert_clean_success(result)
    assert _digest(ws / "dense" / "fused.ply") == before
    assert "dense" in _steps(ws)


def _mesh_failed_cleanly(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    assert "mesh" not in _steps(ws)
    assert not list(ws.glob("mesh/mesh.*"))
    assert not (ws / "logs" / "mesh.rrd").exists()
    assert "RPly" not in result.stderr
    _assert_no_leftovers(ws)


def _mesh_kept_previous(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    ws = folder / "ws"
    _assert_no_leftovers(ws)
    before = {p.name: _digest(p) for p in (ws / "mesh").glob("mesh.*")}
    result = run_cli("mesh", ws)  # the default options of the recorded mesh: reused
    assert_clean_success(result)
    assert {p.name: _digest(p) for p in (ws / "mesh").glob("mesh.*")} == before


def _damage_cloud(how: str, resign: bool):
    """Setup: the dense workspace with fused.ply replaced by garbage or cut short; with
    ``resign``, its record re-signed, as if the damage happened before the step recorded it
    (the PLY check itself is then what catches it)."""

    def setup(folder: Path) -> None:
        ws = workspace(folder, "dense")
        cloud = ws / "dense" / "fused.ply"
        if how == "garbage":
            cloud.write_bytes(bytes(range(256)) * 400)
        else:
            os.truncate(cloud, cloud.stat().st_size // 2)
        if resign:
            from recon.workspace import Workspace

            record = _steps(ws)["dense"]
            Workspace(ws).record_step("dense", record["fingerprint"], outputs=[cloud],
                                      config=record["config"], seconds=record["seconds"],
                                      summary=record["summary"])

    return setup


def _dense_recomputes(folder: Path, _: subprocess.CompletedProcess[str], *flags: str) -> None:
    ws = folder / "ws"
    assert not (ws / "mesh" / "mesh.ply").exists()
    result = run_cli("dense", ws, *flags)
    assert_clean_success(result)
    assert (ws / "dense" / "fused.ply").read_bytes().startswith(b"ply\n")


def _dense_overwrite_recomputes(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    # A record that signed a damaged file is trusted (only a hand-edited run.json does that):
    # the error says to rerun with --overwrite, and that recomputes.
    assert "--overwrite" in result.stderr
    _dense_recomputes(folder, result, "--overwrite")


def _stale_scratch(folder: Path) -> None:
    ws = workspace(folder, "dense")
    (ws / ".dense-k1ll3d").mkdir()  # what a killed run's TemporaryDirectory leaves
    (ws / ".dense-0ld").mkdir()


def _scratch_gone(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    assert not list((folder / "ws").glob(".dense-*"))


def _dense(*options: str):
    return lambda d: ["dense", d / "ws", *options]


def _mesh(*options: str):
    return lambda d: ["mesh", d / "ws", *options]


SFM, DENSE = (lambda d: workspace(d, "sfm")), (lambda d: workspace(d, "dense"))
_OPTION_THEN_DENSE = _no_work_done("dense", "dense/undistorted")
_OPTION_THEN_MESH = _no_work_done("mesh", "mesh")

CASES = [
    # 1. Option bounds, refused before any work (no undistortion, no cloud read).
    Case("dense-option-max-pairs-0", _dense("--dense-option", "max_pairs_per_view=0"), SFM,
         message=r"max_pairs_per_view must be in 1\.\.8, got 0", then=_OPTION_THEN_DENSE),
    Case("dense-option-max-pairs-too-many", _dense("--dense-option", "max_pairs_per_view=50"),
         SFM, message=r"max_pairs_per_view must be in 1\.\.8", then=_OPTION_THEN_DENSE),
    Case("dense-option-rel-depth-tol-negative", _dense("--dense-option", "rel_depth_tol=-1"),
         SFM, message=r"rel_depth_tol must be in \(0, 1\)", then=_OPTION_THEN_DENSE),
    Case("dense-option-rel-depth-tol-nan", _dense("--dense-option", "rel_depth_tol=nan"), SFM,
         message=r"rel_depth_tol must be in \(0, 1\)", then=_OPTION_THEN_DENSE),
    Case("dense-option-min-consistent-negative",
         _dense("--dense-option", "min_consistent_views=-1"), SFM,
         message=r"min_consistent_views must be >= 0", then=_OPTION_THEN_DENSE),
    Case("mesh-option-depth-0", _mesh("--mesh-option", "depth=0"), DENSE,
         message=r"depth must be in 1\.\.13", then=_OPTION_THEN_MESH),
    Case("mesh-option-depth-40", _mesh("--mesh-option", "depth=40"), DENSE,
         message=r"depth must be in 1\.\.13 \(each level doubles memory", then=_OPTION_THEN_MESH),
    Case("mesh-option-max-distance-inf", _mesh("--mesh-option", "max_distance_factor=inf"),
         DENSE, message=r"max_distance_factor must be >= 0 and finite",
         then=_OPTION_THEN_MESH),
    Case("mesh-option-density-quantile-1", _mesh("--mesh-option", "density_quantile=1"),
         DENSE, message=r"density_quantile must be in \[0, 1\)", then=_OPTION_THEN_MESH),
    Case("mesh-faces-2", _mesh("--faces", "2"), DENSE, message=r"at least 4 faces",
         then=_OPTION_THEN_MESH),
    # 2. A full disk during `mocap dense`: the cloud, then the recording, does not fit.
    Case("dense-full-disk-cloud", _dense(), lambda d: _on_tmpfs("sfm", _cloud_does_not_fit())(d),
         message=r"cannot write .*fused\.ply: no space left", then=_dense_failed_cleanly,
         cleanup=_unmount),
    Case("dense-full-disk-recording", _dense(),
         lambda d: _on_tmpfs("sfm", _recording_does_not_fit())(d),
         message=r"cannot write the recording .*dense\.rrd: no space left",
         then=_dense_failed_cleanly, cleanup=_unmount),
    Case("dense-full-disk-keeps-previous", _dense("--overwrite"),
         lambda d: _on_tmpfs("dense", MiB + MiB // 2)(d), message=r"no space left",
         inputs=["ws/dense/fused.ply", "ws/logs/dense.rrd"], then=_dense_kept_previous,
         cleanup=_unmount),
    # 3. A full disk during `mocap mesh` (a coarse Poisson depth keeps it fast: 3 MB of files).
    Case("mesh-full-disk", _mesh("--mesh-option", "depth=7"),
         lambda d: _on_tmpfs("dense", MiB)(d), message=r"cannot write .*mesh.*: no space left",
         then=_mesh_failed_cleanly, cleanup=_unmount),
    Case("mesh-full-disk-keeps-previous", _mesh("--overwrite"),
         lambda d: _on_tmpfs("mesh", 2 * MiB)(d), message=r"no space left",
         inputs=["ws/mesh", "ws/logs/mesh.rrd"], then=_mesh_kept_previous, cleanup=_unmount,
         marks=[pytest.mark.slow]),
    # 4. A damaged dense/fused.ply is called damaged, not empty.
    Case("mesh-cloud-garbage", _mesh(), _damage_cloud("garbage", resign=False),
         message=r"fused\.ply", inputs=["ws/dense/fused.ply"], then=_dense_recomputes),
    Case("mesh-cloud-garbage-signed", _mesh(), _damage_cloud("garbage", resign=True),
         message=r"fused\.ply is not a usable point cloud: not a PLY file",
         then=_dense_overwrite_recomputes, marks=[pytest.mark.slow]),
    Case("mesh-cloud-truncated-signed", _mesh(), _damage_cloud("truncate", resign=True),
         message=r"fused\.ply is not a usable point cloud: truncated: the header declares "
                 r"vertex \d+", then=_dense_overwrite_recomputes),
    # 5. Scratch folders of a killed `mocap dense` are removed when the step next starts.
    Case("dense-stale-scratch", _dense(), _stale_scratch, rc=0, then=_scratch_gone),
]


@pytest.mark.parametrize("case", rows(CASES))
def test_dense_mesh(case: Case, tmp_path: Path) -> None:
    check_case(case, tmp_path)
