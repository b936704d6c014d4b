"""The real data's marker, enforced, and CI's promise that the real data is there.

Every test that reads ``../shared/data`` (or ``$MOCAP_SHARED_DATA``) does so through
`tests.helpers.shared_dataset` and carries ``@pytest.mark.shared_data``; the marker cannot be
forgotten:

* the helper fails a test that calls it, directly or from a fixture or helper, unmarked (the
  hooks below tell it which test is running);
* a test that reuses the cached value of a module- or session-scoped fixture which called the
  helper for an earlier test fails too (`pytest_runtest_setup`);
* tests/test_shared_data.py checks that no test builds the path to the data itself.

Without the data a marked test skips with the reason, as in a fresh clone. With ``CI`` set
(.ci/run sets it) the run stops before the first test when the data folder is missing and
a selected test needs it, and a test whose data set is missing fails: CI always has the data,
so a missing folder is a broken set-up, not 37 skips and a green run.
"""

from __future__ import annotations

from collections.abc import Generator

import pytest

from tests import helpers


def pytest_sessionstart(session: pytest.Session) -> None:
    helpers._session.append(session)


def pytest_sessionfinish(session: pytest.Session) -> None:
    if helpers._session and helpers._session[-1] is session:
        helpers._session.pop()


def pytest_collection_finish(session: pytest.Session) -> None:
    """With ``CI`` set, stop when the selected tests need the real data and it is missing."""
    root = helpers.shared_data_root()
    if not helpers.in_ci() or root.is_dir():
        return
    needing = [item for item in session.items
               if item.get_closest_marker(helpers.SHARED_DATA_MARK) is not None]
    if needing:
        raise pytest.UsageError(
            f"CI is set but the real data folder {root} is missing: {len(needing)} selected "
            f"tests need it (marked {helpers.SHARED_DATA_MARK}, e.g. {needing[0].nodeid}). CI "
            f"must have ../shared/data beside the project (or ${helpers.SHARED_DATA_ENV} "
            "pointing at it); without CI set these tests skip.")


HEAVY_FIRST = (
    "tests/tracking/track/test_suite.py",
    "tests/tracking/test_capture.py",
    "tests/recon/calibration/test_compare.py",
    "tests/tracking/track/test_bad_input.py",
    "tests/tracking/track/test_tracker.py",
    "tests/tracking/track/test_extremities.py",
    "tests/recon/sfm/test_pipeline.py",
)
"""Test files that `make test` starts first, the longest first: `make test` runs a file per
worker (``--dist loadfile --no-loadscope-reorder``), so one started last keeps the other
worker idle until it ends. xdist's default order (the files with the most tests first) started
the suite subset, one test of about 2-4 minutes, near the end."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`HEAVY_FIRST`'s files first, the rest in their order."""
    rank = {path: k for k, path in enumerate(HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None
                            ) -> Generator[None, object, object]:  # fmt: skip
    helpers._running.append(item)
    try:
        return (yield)
    finally:
        helpers._running.pop()


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef: pytest.FixtureDef[object], request: pytest.FixtureRequest
                         ) -> Generator[None, object, object]:  # fmt: skip
    helpers._fixtures.append(fixturedef)
    try:
        return (yield)
    finally:
        helpers._fixtures.pop()


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Fail an unmarked test that uses a fixture which read the real data for an earlier test
    (a cached fixture does not call `shared_dataset` again)."""
    if item.get_closest_marker(helpers.SHARED_DATA_MARK) is not None:
        return
    names = set(getattr(item, "fixturenames", ()))
    used = sorted(name for baseid, name in helpers.shared_fixtures
                  if name in names and _visible(baseid, item.nodeid))
    if used:
        pytest.fail(f"{item.nodeid} uses fixture {', '.join(used)}, which reads real data, "
                    f"without @pytest.mark.{helpers.SHARED_DATA_MARK}", pytrace=False)


def _visible(baseid: str, nodeid: str) -> bool:
    """Whether a fixture defined at `baseid` (a conftest's folder or a module, '' for the
    root) is the one that the test `nodeid` sees under its name."""
    return not baseid or nodeid == baseid or nodeid.startswith((f"{baseid}::", f"{baseid}/"))
