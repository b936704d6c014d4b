"""The robustness suite's table runner (issue 23): one `Case` per hostile input or fault.

Every case runs `mocap` in a subprocess, exactly as a user does, and checks the README's
promises for it:

* the exit code (2 for bad input, 0 where the input is fine and only a note is due);
* for exit code 2, exactly one error line, ``mocap CMD: error: ...``, matching ``message``, and
  no other line on stderr but notes and warnings (no traceback, no COLMAP log line);
* every file under ``inputs`` byte-identical before and after;
* ``then``: what a later step does with what is left (it recomputes, or refuses in one line).

A test module lists its cases in a table and runs each with :func:`check_case`, parametrized
by :func:`rows`.
"""

from __future__ import annotations

import hashlib
import re
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.helpers import run_cli

Argv = Callable[[Path], Sequence[str | Path]]
Setup = Callable[[Path], None]
Then = Callable[[Path, subprocess.CompletedProcess[str]], None]

_ALLOWED_PREFIXES = ("note:", "warning:")
"""Lines a failing command may print on stderr besides its one error line."""


@dataclass(frozen=True)
class Case:
    """One row of the robustness table."""

    id: str
    argv: Argv
    """`mocap` arguments, from the case's own folder."""
    setup: Setup | None = None
    """Makes the case's inputs in its folder (a workspace, a broken file, ...)."""
    rc: int = 2
    message: str = ""
    """Regular expression the error line must match (searched) when ``rc`` is 2; for other
    codes, a regular expression stderr must match (searched), if given."""
    inputs: Sequence[str] = ()
    """Paths (relative to the case's folder, or absolute) whose files must not change."""
    then: Then | None = None
    """What a later step makes of the result: it must recompute, or refuse in one line."""
    cleanup: Setup | None = None
    """Undoes what ``setup`` did outside the folder (a mount, a process), pass or fail."""
    marks: Sequence[object] = field(default=())


def rows(cases: Sequence[Case]) -> list[Any]:
    """The table as pytest parameters: each case with its id and marks (``slow``)."""
    import pytest

    return [pytest.param(case, id=case.id, marks=case.marks) for case in cases]


def snapshot(paths: Sequence[Path]) -> dict[str, str]:
    """SHA-256 of every file under ``paths`` (symlinks by their target text, not followed)."""
    digests: dict[str, str] = {}
    for root in paths:
        files = [root] if not root.is_dir() or root.is_symlink() else sorted(root.rglob("*"))
        for path in files:
            if path.is_symlink():
                digests[str(path)] = "link:" + str(path.readlink())
            elif path.is_file():
                digests[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
    return digests


def assert_one_line_error(result: subprocess.CompletedProcess[str], message: str = "") -> str:
    """The single ``mocap CMD: error: ...`` line of a failed run, checked: no traceback, no
    other line on stderr but notes and warnings, and ``message`` found in it."""
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if re.match(r"mocap [\w-]+: error: ", line)]
    assert len(errors) == 1, f"want one error line, got:\n{result.stderr}"
    others = [line for line in lines if line not in errors
              and not line.startswith(_ALLOWED_PREFIXES)]
    assert not others, f"stray lines on stderr:\n{result.stderr}"
    assert re.search(message, errors[0]), f"{message!r} not in {errors[0]!r}"
    return errors[0]


def assert_clean_success(result: subprocess.CompletedProcess[str], message: str = "") -> None:
    """A run that succeeded: exit 0, no traceback, no error line, ``message`` on stderr."""
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    assert not re.search(r"^mocap [\w-]+: error: ", result.stderr, re.M), result.stderr
    if message:
        assert re.search(message, result.stderr), result.stderr


def check_case(case: Case, folder: Path) -> subprocess.CompletedProcess[str]:
    """Run one row in ``folder`` (empty, the test's own) and check every promise."""
    try:
        return _check(case, folder)
    finally:
        if case.cleanup is not None:
            case.cleanup(folder)


def _check(case: Case, folder: Path) -> subprocess.CompletedProcess[str]:
    if case.setup is not None:
        case.setup(folder)
    inputs = [p if Path(p).is_absolute() else folder / p for p in map(Path, case.inputs)]
    before = snapshot(inputs)
    result = run_cli(*case.argv(folder), cwd=folder)
    if case.rc == 2:
        assert result.returncode == 2, (result.returncode, result.stderr)
        assert_one_line_error(result, case.message)
    elif case.rc == 0:
        assert_clean_success(result, case.message)
    else:
        assert result.returncode == case.rc, (result.returncode, result.stderr)
        assert "Traceback" not in result.stderr, result.stderr
        if case.message:
            assert re.search(case.message, result.stderr), result.stderr
    assert snapshot(inputs) == before, "an input file changed"
    if case.then is not None:
        case.then(folder, result)
    return result
