"""The real data's guard rails (tests/conftest.py): unmarked use fails, CI without the data stops
the run with the missing path, a fresh clone skips with the reason."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests import helpers

pytest_plugins = ["pytester"]

TRUTH_TEST = "tests/recon/evaluation/test_truth.py::test_read_middlebury_temple_ring"


def _pytest(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """This project's pytest in a subprocess, as CI runs it, with `env` over a copy of ours
    without CI and MOCAP_SHARED_DATA."""
    base = {k: v for k, v in os.environ.items()
            if k not in ("CI", helpers.SHARED_DATA_ENV)}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          capture_output=True, text=True, cwd=helpers.ROOT, timeout=300,
                          env={**base, **env})  # fmt: skip


def test_ci_without_the_data_stops_the_run_naming_the_path(tmp_path: Path) -> None:
    absent = tmp_path / "absent"
    run = _pytest(TRUTH_TEST, env={"CI": "true", helpers.SHARED_DATA_ENV: str(absent)})
    assert run.returncode == pytest.ExitCode.USAGE_ERROR, run.stdout + run.stderr
    assert f"CI is set but the real data folder {absent} is missing" in run.stderr
    assert "passed" not in run.stdout and "skipped" not in run.stdout


def test_ci_with_a_data_set_missing_fails_the_test_and_without_ci_it_skips(tmp_path: Path
                                                                          ) -> None:  # fmt: skip
    # The folder exists (so the run starts) but holds no temple_sparse_ring.
    env = {helpers.SHARED_DATA_ENV: str(tmp_path)}
    run = _pytest(TRUTH_TEST, env={"CI": "1", **env})
    assert run.returncode == pytest.ExitCode.TESTS_FAILED, run.stdout + run.stderr
    assert f"real data {tmp_path / 'temple_sparse_ring'} is absent but CI is set" in run.stdout
    run = _pytest("-rs", TRUTH_TEST, env=env)
    assert run.returncode == pytest.ExitCode.OK, run.stdout + run.stderr
    assert "1 skipped" in run.stdout
    assert f"real data {tmp_path / 'temple_sparse_ring'} is absent" in run.stdout


def test_unmarked_use_of_the_real_data_fails(pytester: pytest.Pytester,
                                            monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    (pytester.path / "data" / "demo").mkdir(parents=True)
    monkeypatch.setenv(helpers.SHARED_DATA_ENV, str(pytester.path / "data"))
    monkeypatch.delenv("CI", raising=False)
    pytester.makeini("[pytest]\nmarkers =\n    shared_data: reads the real data\n")
    pytester.makeconftest("from tests.conftest import *  # noqa: F403\n")
    pytester.makepyfile(test_uses="""
        import pytest
        from tests.helpers import shared_dataset

        @pytest.fixture(scope="module")
        def data():
            return shared_dataset("demo")

        @pytest.mark.shared_data
        def test_marked(data):
            assert data.is_dir() and shared_dataset("demo") == data

        def test_unmarked_direct():
            shared_dataset("demo")

        def test_unmarked_reusing_the_cached_fixture(data):
            pass

        def _through_a_helper():
            return shared_dataset("demo")

        def test_unmarked_through_a_helper():
            _through_a_helper()
        """, test_at_import="""
        from tests.helpers import shared_dataset

        DATA = shared_dataset("demo")

        def test_nothing():
            pass
        """)
    recorded = set(helpers.shared_fixtures)
    try:
        result = pytester.runpytest("-p", "no:cacheprovider", "-p", "no:dash",
                                    "--continue-on-collection-errors")
    finally:  # the inner run's fixtures are not this session's
        helpers.shared_fixtures.intersection_update(recorded)
    result.assert_outcomes(passed=1, failed=2, errors=2)
    out = result.stdout.str()
    assert "test_uses.py::test_unmarked_direct reads real data (demo) without" in out
    assert "test_uses.py::test_unmarked_through_a_helper reads real data (demo) without" in out
    assert ("test_uses.py::test_unmarked_reusing_the_cached_fixture uses fixture data, which "
            "reads real data, without @pytest.mark.shared_data") in out
    assert "shared_dataset('demo') called outside a test (at import?)" in out


def test_no_test_builds_the_path_to_the_real_data_itself() -> None:
    # Only tests/helpers.py knows where the data is (and its override); a module that builds
    # the path itself bypasses the skip, CI's check and the marker's enforcement.
    tests = helpers.ROOT / "tests"
    own = {tests / "helpers.py", tests / "conftest.py", Path(__file__).resolve()}
    pattern = re.compile(r"""["'][^"'\n]*shared/data|["']shared["']|MOCAP_SHARED_DATA""")
    offenders = [f"{path.relative_to(helpers.ROOT)}:{number}"
                 for path in sorted(tests.rglob("*.py")) if path not in own
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if pattern.search(line)]  # fmt: skip
    assert not offenders, f"use tests.helpers.shared_dataset instead: {offenders}"
