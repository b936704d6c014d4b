"""Robustness table: the workspace contract under faults (issue 23).

A second writer, a read-only workspace, outputs damaged behind the pipeline's back, and a
killed run's SQLite leftovers. Each row runs `mocap` as a user does (tests.robustness.harness).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import ROOT, run_cli
from tests.robustness.harness import (
    Case,
    assert_clean_success,
    assert_one_line_error,
    check_case,
    rows,
)
from tests.robustness.scenes import built_workspace, workspace

_holders: dict[Path, subprocess.Popen[str]] = {}


def _hold_lock(folder: Path) -> None:
    """Another process holds the workspace's lock (as a running `mocap` step does)."""
    workspace(folder, "sfm")
    code = ("import sys, time; from recon.workspace import workspace_lock\n"
            "with workspace_lock(sys.argv[1], 'mocap sfm (test holder)'):\n"
            "    print('locked', flush=True); time.sleep(120)\n")
    holder = subprocess.Popen([sys.executable, "-c", code, str(folder / "ws")], cwd=ROOT,
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
    _holders[folder] = holder


def _release_lock(folder: Path) -> None:
    if (holder := _holders.pop(folder, None)) is not None:
        holder.kill()
        holder.wait()


def _second_writer_then(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    # The refused run wrote nothing; once the holder is gone (killed: the kernel drops its
    # flock), the same command runs and reuses every step.
    _release_lock(folder)
    result = run_cli("sfm", folder / "ws")
    assert_clean_success(result)
    assert result.stdout.count("(reused)") == 4, result.stdout
    assert not (folder / "ws" / ".mocap.lock").exists()


def _read_only(stage: str):
    def setup(folder: Path) -> None:
        ws = workspace(folder, stage)
        if os.geteuid() != 0:
            for path in [ws, *ws.rglob("*")]:
                if path.is_dir():
                    path.chmod(0o555)
            return
        # root ignores permission bits: make it a read-only bind mount, as a read-only share.
        for args in (["mount", "--bind", ws, ws], ["mount", "-o", "remount,bind,ro", ws]):
            if subprocess.run(args, capture_output=True).returncode != 0:
                pytest.skip(f"cannot make a read-only bind mount ({' '.join(map(str, args))})")
    return setup


def _writable_again(folder: Path) -> None:
    ws = folder / "ws"
    if os.geteuid() == 0:
        subprocess.run(["umount", ws], capture_output=True)
    else:
        for path in [ws, *ws.rglob("*")]:
            if path.is_dir():
                path.chmod(0o755)


def _dense_after_read_only(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    _writable_again(folder)
    assert not list((folder / "ws").glob(".dense-*"))
    assert json.loads((folder / "ws" / "run.json").read_text())["steps"].keys() == {
        "features", "matches", "intrinsics", "mapping"}


def _truncate(relative: str, size: int | None = None):
    def setup(folder: Path) -> None:
        path = workspace(folder, "dense") / relative
        with path.open("r+b") as handle:
            handle.truncate(size if size is not None else path.stat().st_size // 2)
    return setup


def _points(folder: Path) -> int:
    return json.loads((folder / "ws" / "run.json").read_text())["steps"]["dense"]["summary"][
        "points"]


def _dense_recomputed(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    assert "reused" not in result.stdout, result.stdout
    clean = _clean_dense_points()
    assert _points(folder) == clean
    assert f"{clean} points" in result.stdout


def _clean(stage: str, step: str, figure: str) -> int:
    """A figure of the clean run's ``step`` (the cached workspace the cases copy)."""
    return json.loads((built_workspace(stage) / "run.json").read_text())["steps"][step]["summary"][
        figure]


def _clean_dense_points() -> int:
    return _clean("dense", "dense", "points")


def _registered_as_clean(result: subprocess.CompletedProcess[str]) -> None:
    registered = _clean("sfm", "mapping", "registered")
    assert f"registered  {registered} of 6 images" in result.stdout, result.stdout


def _mesh_refused_then_dense_recomputes(folder: Path, _: subprocess.CompletedProcess[str]
                                        ) -> None:
    assert not (folder / "ws" / "mesh").exists()
    result = run_cli("dense", folder / "ws")
    assert_clean_success(result)
    _dense_recomputed(folder, result)


def _delete_model_file(folder: Path) -> None:
    (workspace(folder, "dense") / "sparse" / "0" / "points3D.bin").unlink()


def _sfm_remaps(folder: Path, _: subprocess.CompletedProcess[str]) -> None:
    result = run_cli("sfm", folder / "ws")
    assert_clean_success(result)
    _registered_as_clean(result)
    # Only mapping reruns: features, matches and intrinsics are intact.
    assert result.stdout.count("(reused)") == 3, result.stdout
    assert (folder / "ws" / "sparse" / "0" / "points3D.bin").is_file()


def _damage_database(folder: Path) -> None:
    db = workspace(folder, "sfm") / "database.db"
    with db.open("r+b") as handle:
        handle.truncate(db.stat().st_size // 2)


def _sfm_from_scratch(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    # The database is made anew and matched again (the matches went with the old one); mapping
    # is reused only when the new database has the old content (its chain is by content).
    _registered_as_clean(result)
    times = result.stdout.split("time", 1)[1].split("\n", 1)[0]
    assert "features" in times and not re.search(r"(features|matches)\S* \S+ \(reused", times)


def _stale_write_ahead_log(folder: Path) -> None:
    """What a killed matching run leaves: its partial database and a write-ahead log that
    SQLite would replay into the next copy (issue 23 point 1)."""
    ws = workspace(folder, "sfm")
    (ws / "database.partial.db").write_bytes((ws / "database.db").read_bytes())
    (ws / "database.partial.db-wal").write_bytes(os.urandom(70_000))
    (ws / "database.partial.db-shm").write_bytes(bytes(32768))


def _rematched_cleanly(folder: Path, result: subprocess.CompletedProcess[str]) -> None:
    _registered_as_clean(result)
    left = sorted(p.name for p in (folder / "ws").iterdir() if "partial" in p.name)
    assert left == [], left
    pairs = subprocess.run(
        ["sqlite3", folder / "ws" / "database.db", "SELECT COUNT(*) FROM two_view_geometries"],
        capture_output=True, text=True)
    if pairs.returncode == 0:
        assert int(pairs.stdout) == 15  # 6 images: every pair of the exhaustive matcher


CASES = [
    Case("second-writer-refused", argv=lambda d: ["sfm", d / "ws", "--overwrite"],
         setup=_hold_lock, cleanup=_release_lock,
         message=r"is in use by another mocap run \(pid \d+: mocap sfm", inputs=["ws"],
         then=_second_writer_then),
    Case("read-only-workspace-sfm", argv=lambda d: ["sfm", d / "ws"],
         setup=_read_only("init"), cleanup=_writable_again,
         message=r"workspace .* is not writable", inputs=["ws"]),
    Case("read-only-workspace-dense", argv=lambda d: ["dense", d / "ws"],
         setup=_read_only("sfm"), cleanup=_writable_again,
         message=r"workspace .* is not writable", inputs=["ws"],
         then=_dense_after_read_only),
    Case("truncated-fused-ply-dense-recomputes", argv=lambda d: ["dense", d / "ws"],
         setup=_truncate("dense/fused.ply"), rc=0, then=_dense_recomputed),
    Case("truncated-fused-ply-mesh-refuses", argv=lambda d: ["mesh", d / "ws"],
         setup=_truncate("dense/fused.ply"),
         message=r"the dense step changed since it wrote dense/fused.ply; run `mocap dense",
         then=_mesh_refused_then_dense_recomputes),
    Case("deleted-model-file-dense-refuses", argv=lambda d: ["dense", d / "ws"],
         setup=_delete_model_file,
         message=r"the mapping step changed since it wrote sparse/0; run `mocap sfm",
         then=_sfm_remaps),
    Case("truncated-database-sfm-recomputes", argv=lambda d: ["sfm", d / "ws"],
         setup=_damage_database, rc=0, then=_sfm_from_scratch),
    Case("stale-write-ahead-log-ignored",
         argv=lambda d: ["sfm", d / "ws", "--matcher", "exhaustive"],
         setup=_stale_write_ahead_log, rc=0, then=_rematched_cleanly),
]


@pytest.mark.parametrize("case", rows(CASES))
def test_workspace_fault(case: Case, tmp_path: Path) -> None:
    check_case(case, tmp_path)


def test_the_lock_of_a_killed_run_does_not_block_the_next(tmp_path: Path) -> None:
    """flock is released by the kernel when its holder dies (kill -9 included): no stale lock
    file to delete by hand, unlike a PID file."""
    _hold_lock(tmp_path)
    _holders[tmp_path].kill()
    _holders.pop(tmp_path).wait()
    time.sleep(0.05)
    # The dead holder's lock file is still there, but nobody holds it.
    assert (tmp_path / "ws" / ".mocap.lock").exists()
    result = run_cli("sfm", tmp_path / "ws")
    assert_clean_success(result)
    assert not (tmp_path / "ws" / ".mocap.lock").exists()


def test_a_refused_command_on_a_new_folder_leaves_nothing(tmp_path: Path) -> None:
    result = run_cli("sfm", tmp_path / "new" / "ws")
    assert_one_line_error(result, "is not a workspace")
    assert not (tmp_path / "new").exists()
