"""Robustness table: kill -9 at many points of sfm, dense and mesh, then the same command again
(issue 23). The rerun must succeed and give what a clean run gives, with nothing left over.

Kill points are found from what the step itself writes (its partial outputs, its SQLite
write-ahead log, its run record), polled every 2 ms, not from a sleep. A point the step got
past too fast to catch is retried on a fresh copy; one never reached fails the row.
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import json
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.helpers import ROOT, run_cli, shared_dataset
from tests.robustness.harness import assert_clean_success
from tests.robustness.scenes import workspace

pytestmark = pytest.mark.slow

Point = Callable[[Path], bool]


def _recorded(ws: Path, step: str) -> bool:
    try:
        return step in json.loads((ws / "run.json").read_text()).get("steps", {})
    except (OSError, ValueError):
        return False


def _exists(*patterns: str) -> Point:
    return lambda ws: any(any(ws.glob(p)) for p in patterns)


@dataclass(frozen=True)
class KillPoint:
    id: str
    command: str  # sfm, dense or mesh
    start: str  # the workspace stage it starts from
    reached: Point


POINTS = [
    KillPoint("sfm-during-features", "sfm", "init",
              lambda ws: (ws / "database.partial.db").exists() and not _recorded(ws, "features")),
    KillPoint("sfm-during-matching", "sfm", "init",
              lambda ws: (ws / "database.partial.db").exists() and _recorded(ws, "features")),
    KillPoint("sfm-with-write-ahead-log", "sfm", "init",
              lambda ws: (ws / "database.partial.db-wal").exists()),
    KillPoint("sfm-during-mapping", "sfm", "init", _exists("sparse.partial")),
    KillPoint("sfm-after-a-step-record", "sfm", "init", lambda ws: _recorded(ws, "intrinsics")),
    KillPoint("dense-during-undistortion", "dense", "sfm", _exists("dense/undistorted.partial")),
    KillPoint("dense-during-stereo", "dense", "sfm", _exists(".dense-*")),
    KillPoint("dense-writing-cloud", "dense", "sfm", _exists("dense/fused.partial.ply")),
    KillPoint("mesh-writing-files", "mesh", "dense", _exists("mesh/mesh.partial.*")),
]


def _kill_at(argv: list[str], ws: Path, reached: Point, timeout_s: float = 300) -> bool:
    """Run `mocap ARGV` and kill -9 it when ``reached(ws)``; False when it finished first."""
    proc = subprocess.Popen([sys.executable, "-m", "recon.cli", *argv], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + timeout_s
    try:
        while proc.poll() is None and time.monotonic() < deadline:
            if reached(ws):
                proc.kill()
                proc.wait()
                return True
            time.sleep(0.002)
        return False
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _database_figures(db: Path) -> dict[str, object]:
    with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as con:
        return {
            "integrity": con.execute("PRAGMA integrity_check").fetchone()[0],
            "images": con.execute("SELECT COUNT(*) FROM images").fetchone()[0],
            "keypoints": con.execute("SELECT SUM(rows) FROM keypoints").fetchone()[0],
            "pairs": con.execute("SELECT COUNT(*) FROM two_view_geometries WHERE rows > 0"
                                 ).fetchone()[0],
        }


def _figures(ws: Path, command: str) -> dict[str, object]:
    steps = json.loads((ws / "run.json").read_text())["steps"]
    if command == "sfm":
        return {"registered": steps["mapping"]["summary"]["registered"],
                **_database_figures(ws / "database.db")}
    if command == "dense":
        return {"points": steps["dense"]["summary"]["points"]}
    return {key: steps["mesh"]["summary"][key] for key in ("vertices", "faces")}


def _leftovers(ws: Path) -> list[str]:
    return sorted(str(p.relative_to(ws)) for p in ws.rglob("*")
                  if ".partial" in p.name or p.name.startswith(".dense-")
                  or p.name.endswith(".old") or p.name == ".mocap.lock")


_FLAGS = {"sfm": ["--num-threads", "1"], "dense": [], "mesh": []}
"""COLMAP's two-view verification is deterministic on one thread only (on two, this scene
gives 9 or 10 verified pairs run to run), so sfm is compared on one thread."""


@functools.cache
def _clean_run(command: str, start: str) -> Path:
    """The same command on an untouched copy, run to the end: what a rerun must give."""
    folder = Path(tempfile.mkdtemp(prefix="mocap-kill-clean-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    ws = workspace(folder, start)
    assert_clean_success(run_cli(command, ws, *_FLAGS[command]))
    return ws


def _model_bytes(ws: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((ws / "sparse" / "0").glob("*.bin"))}


@pytest.mark.parametrize("point", POINTS, ids=lambda p: p.id)
def test_a_killed_step_reruns_to_the_clean_result(point: KillPoint, tmp_path: Path) -> None:
    argv = [point.command, "WS", *_FLAGS[point.command]]
    for attempt in range(5):
        folder = tmp_path / f"try{attempt}"
        ws = workspace(folder, point.start)
        if _kill_at([str(ws) if a == "WS" else a for a in argv], ws, point.reached):
            break
        shutil.rmtree(folder)
    else:
        pytest.fail(f"{point.id}: the step finished 5 times before the kill point")
    result = run_cli(point.command, ws, *_FLAGS[point.command])
    assert_clean_success(result)
    assert _leftovers(ws) == []
    clean = _clean_run(point.command, point.start)
    assert _figures(ws, point.command) == _figures(clean, point.command)
    assert _model_bytes(ws) == _model_bytes(clean)


@pytest.mark.shared_data
def test_the_issues_killed_sequential_matching_on_the_temple(tmp_path: Path) -> None:
    """Issue 23's own repro: sfm on the temple, then sequential matching (overlap 5) killed
    0.7 s after its write-ahead log appears, then `--intrinsics kruppa`. It said 'matches
    (reused)' and registered 8 of 16 (another try 3) from a database holding 41 of 120 pairs.
    Now the rerun matches again and gives what the same command gives on a clean workspace."""
    temple = shared_dataset("temple_sparse_ring")
    ws = tmp_path / "ws"
    one = ("--num-threads", "1")  # deterministic verification, to compare with a clean run
    assert_clean_success(run_cli("sfm", ws, "--images", temple, *one))

    def after_wal(path: Path) -> bool:
        if not (path / "database.partial.db-wal").exists():
            return False
        time.sleep(0.7)
        return True

    assert _kill_at(["sfm", str(ws), "--matcher", "sequential", "--sequential-overlap", "5",
                     *one], ws, after_wal)
    result = run_cli("sfm", ws, "--intrinsics", "kruppa", *one)
    assert_clean_success(result)
    assert _leftovers(ws) == []

    clean = tmp_path / "clean"
    shutil.copytree(ws / "images", tmp_path / "photos", symlinks=False)
    assert_clean_success(run_cli("sfm", clean, "--images", tmp_path / "photos",
                                 "--intrinsics", "kruppa", *one))
    assert _figures(ws, "sfm") == _figures(clean, "sfm")
