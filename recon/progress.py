"""Console progress bars for long pycolmap calls.

pycolmap's extraction and matching release the GIL and report nothing back, so their progress
is read from the database they are writing (row counts), by a thread that polls it.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from tqdm import tqdm


def bar(total: int, desc: str, unit: str, enabled: bool = True) -> tqdm:
    # disable=None: no bar when stderr is not a terminal (CI logs, pipes).
    return tqdm(total=total, desc=desc, unit=unit, disable=None if enabled else True,
                leave=False, dynamic_ncols=True)


def count_rows(database: Path, table: str) -> Callable[[], int]:
    def read() -> int:
        try:
            with contextlib.closing(
                sqlite3.connect(f"file:{database}?mode=ro", uri=True, timeout=0.1)
            ) as con:
                return int(con.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0])
        except sqlite3.Error:
            return 0  # table not created yet, or locked by the writer: try again later

    return read


@contextlib.contextmanager
def polled(total: int, desc: str, unit: str, read: Callable[[], int]) -> Iterator[None]:
    """Show a bar whose position is ``read()``, sampled a few times a second."""
    progress = bar(total, desc, unit)
    done = threading.Event()

    def poll() -> None:
        while not done.wait(0.3):
            progress.n = min(read(), total)
            progress.refresh()

    thread = threading.Thread(target=poll, daemon=True)
    if not progress.disable:
        thread.start()
    try:
        yield
    finally:
        done.set()
        if thread.is_alive():
            thread.join()
        progress.close()
