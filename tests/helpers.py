"""Test helpers: paths to the real data in ../shared/data, recordings read back, the CLI."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA_ENV = "MOCAP_SHARED_DATA"
"""Environment variable that moves the real data from ``../shared/data`` (beside the project)."""
SHARED_DATA_MARK = "shared_data"

# Set by tests/conftest.py while pytest runs a test (its setup, call and teardown) and while
# it sets up a fixture: whom a call of `shared_dataset` is for.
_session: list[pytest.Session] = []
_running: list[pytest.Item] = []
_fixtures: list[pytest.FixtureDef[object]] = []
shared_fixtures: set[tuple[str, str]] = set()
"""(baseid, name) of every fixture that has called `shared_dataset`, for conftest's check of
the tests that reuse its cached value."""


def shared_data_root() -> Path:
    """The folder of the real data sets: ``$MOCAP_SHARED_DATA``, else ``../shared/data``."""
    override = os.environ.get(SHARED_DATA_ENV)
    return Path(override) if override else ROOT.parent / "shared" / "data"


def in_ci() -> bool:
    """Whether the environment says this is CI (``CI`` set, as CI services and .ci/run do),
    where missing real data is an error rather than a reason to skip."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def shared_dataset(name: str) -> Path:
    """Path of a folder of the real data (``shared_data_root() / name``), the one way tests reach
    it: call it in the test or one of its fixtures, and mark the test
    ``@pytest.mark.shared_data`` (a test that calls it unmarked fails, see tests/conftest.py).
    A missing folder skips the test with the reason; with ``CI`` set it fails it."""
    if _session:
        # (The innermost session's test: a test may run pytest in-process, as pytester does.)
        if not _running or _running[-1].session is not _session[-1]:
            raise RuntimeError(
                f"shared_dataset({name!r}) called outside a test (at import?): call it in the "
                f"test or a fixture, and mark the test @pytest.mark.{SHARED_DATA_MARK}")
        item = _running[-1]
        if item.get_closest_marker(SHARED_DATA_MARK) is None:
            pytest.fail(f"{item.nodeid} reads real data ({name}) without "
                        f"@pytest.mark.{SHARED_DATA_MARK}", pytrace=False)
        shared_fixtures.update((f.baseid, f.argname) for f in _fixtures)
    path = shared_data_root() / name
    if not path.is_dir():
        if in_ci():
            pytest.fail(f"real data {path} is absent but CI is set: CI must have it "
                        f"(../shared/data beside the project, or ${SHARED_DATA_ENV})",
                        pytrace=False)
        pytest.skip(f"real data {path} is absent (it sits beside the project in CI)")
    return path


def run_cli(
    *args: str | Path, cwd: Path | None = None, headless: bool = True
) -> subprocess.CompletedProcess[str]:
    """`mocap ARGS` in a subprocess, exactly as a user runs it (without a display by default)."""
    env = dict(os.environ)
    if headless:
        env.pop("DISPLAY", None)
        env.pop("WAYLAND_DISPLAY", None)
    return subprocess.run(
        [sys.executable, "-m", "recon.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
        timeout=900,
        env=env,
    )


def fake_entry_points(monkeypatch: pytest.MonkeyPatch, group: str, **targets: str) -> None:
    """Pretend a third-party distribution declared these entry points (``name="module:attr"``)
    in ``group``, beside the installed ones; for this process only (not for `run_cli`)."""
    from importlib.metadata import EntryPoint

    from plugins import registry

    fakes = [EntryPoint(name, value, group) for name, value in targets.items()]
    real = registry.entry_points

    def entry_points(*, group: str):
        found = list(real(group=group))
        return [*found, *(f for f in fakes if f.group == group)]

    monkeypatch.setattr(registry, "entry_points", entry_points)


def recording_entities(path: Path) -> set[str]:
    """'entity@Archetype:component' strings of a saved .rrd, read back with Rerun's own CLI."""
    rerun = Path(sys.executable).with_name("rerun")
    verify = subprocess.run([rerun, "rrd", "verify", path], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    out = subprocess.run(
        [rerun, "rrd", "print", "-v", path], capture_output=True, text=True, check=True
    ).stdout
    return set(re.findall(r"(/[\w/-]*@\w+:\w+)", out))


@dataclass(frozen=True)
class ReadRecording:
    """A saved .rrd read back with Rerun's own reader (`rerun.chunk.RrdReader`, rerun-sdk
    0.41): its recording store's chunks and its blueprint store's views and time panel."""

    application_id: str
    chunks: list[Any]
    """`rerun.chunk.Chunk` of the recording, in file order."""
    views: list[dict[str, str]]
    """The blueprint's views: ``kind`` (``3D``, ``2D``, ``TimeSeries``...), ``origin``, ``name``."""
    timeline: str | None
    """The timeline the blueprint's time panel shows (None: not set)."""

    def rows(self, entity: str, column: str, *, static: bool | None = None) -> list[Any]:
        """Every row of ``column`` (``Archetype:component``, or a timeline) logged at
        ``entity`` (``world/...``), in file order; only static or temporal ones when asked."""
        path = "/" + entity.strip("/")
        rows: list[Any] = []
        for chunk in self.chunks:
            if chunk.entity_path != path or (static is not None and chunk.is_static != static):
                continue
            batch = chunk.to_record_batch()
            if column in batch.schema.names:
                rows.extend(batch.column(column).to_pylist())
        return rows

    def entities(self, column: str) -> set[str]:
        """Entities (``/world/...``) with rows of ``column``."""
        return {chunk.entity_path for chunk in self.chunks
                if column in chunk.to_record_batch().schema.names}  # fmt: skip

    def layout_problems(self) -> list[str]:
        """Why the recording would not open right: no blueprint, a view of an entity without
        data, data over time that is not on the timeline the time panel shows."""
        if not self.views:
            return ["no blueprint"]
        problems = []
        logged = {chunk.entity_path for chunk in self.chunks if not chunk.is_empty}
        for view in self.views:
            origin = "/" + view["origin"].strip("/")
            if not any(e == origin or e.startswith(origin.rstrip("/") + "/") for e in logged):
                problems.append(f"view {view['name']!r} shows {origin}, which holds no data")
        for chunk in self.chunks:
            if not chunk.is_static and self.timeline not in chunk.timeline_names:
                problems.append(f"{chunk.entity_path} is on {chunk.timeline_names}, not on "
                                f"the time panel's timeline {self.timeline}")
        return sorted(set(problems))


def read_recording(path: Path) -> ReadRecording:
    """``path`` read back with Rerun's own reader; fails the test when it holds no recording."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    (recording,) = reader.recordings()
    views: dict[str, dict[str, str]] = {}
    timeline = None
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            columns = {name: batch.column(name).to_pylist()[-1] for name in batch.schema.names
                       if ":" in name}  # fmt: skip
            if "ViewBlueprint:class_identifier" in columns:
                views[chunk.entity_path] = {
                    "kind": columns["ViewBlueprint:class_identifier"][0],
                    "origin": columns["ViewBlueprint:space_origin"][0],
                    "name": (columns.get("ViewBlueprint:display_name") or [""])[0]}
            if columns.get("TimePanelBlueprint:timeline"):
                timeline = columns["TimePanelBlueprint:timeline"][0]
    return ReadRecording(recording.application_id, list(reader.stream(store=recording)),
                         list(views.values()), timeline)


def mount_small_disk(folder: Path, size_bytes: int) -> Path:
    """Mount a tmpfs of ``size_bytes`` at ``folder`` (made if missing): a disk that fills up.
    Skips the calling test with the reason when not root or the mount is refused (a container
    without CAP_SYS_ADMIN). Undo with :func:`unmount_small_disk`."""
    if os.geteuid() != 0:
        pytest.skip("a full disk is simulated with a tmpfs mount, which needs root")
    folder.mkdir(parents=True, exist_ok=True)
    size = f"size={max(size_bytes // 1024, 4)}k"
    if subprocess.run(["mount", "-t", "tmpfs", "-o", size, "tmpfs", str(folder)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs (a container without CAP_SYS_ADMIN?)")
    return folder


def unmount_small_disk(folder: Path) -> None:
    if os.path.ismount(folder):
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


@contextlib.contextmanager
def small_disk(folder: Path, size_bytes: int) -> Iterator[Path]:
    """:func:`mount_small_disk` for the duration of a block."""
    mount_small_disk(folder, size_bytes)
    try:
        yield folder
    finally:
        unmount_small_disk(folder)
