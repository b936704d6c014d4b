"""`make test`'s schedule (tests/conftest.py): the files it starts first exist."""

from __future__ import annotations

from tests.conftest import HEAVY_FIRST
from tests.helpers import ROOT


def test_the_files_started_first_exist():
    missing = [path for path in HEAVY_FIRST if not (ROOT / path).is_file()]
    assert not missing, f"renamed or removed: update HEAVY_FIRST in tests/conftest.py: {missing}"
    assert len(set(HEAVY_FIRST)) == len(HEAVY_FIRST)
