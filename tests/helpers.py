"""Test helpers: paths to the real data in ../shared/data, recordings read back, the CLI."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"



def shared_dataset(name: str) -> Path:
    """Path of a folder of ../shared/data, or skip the test with the reason."""
    path = SHARED_DATA / name
    if not path.is_dir():
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


def recording_entities(path: Path) -> set[str]:
    """'entity@Archetype:component' strings of a saved .rrd, read back with Rerun's own CLI."""
    rerun = Path(sys.executable).with_name("rerun")
    verify = subprocess.run([rerun, "rrd", "verify", path], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    out = subprocess.run(
        [rerun, "rrd", "print", "-v", path], capture_output=True, text=True, check=True
    ).stdout
    return set(re.findall(r"(/[\w/-]*@\w+:\w+)", out))
