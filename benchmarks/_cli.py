"""What the benchmark scripts share: running `mocap` as a user would, in its own process."""

from __future__ import annotations

import subprocess
import sys
import time


def mocap(*args: str, echo: bool = True) -> float:
    """Run `mocap ARGS` in a fresh process; exit with its stderr when it fails; wall seconds."""
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "recon.cli", *args], capture_output=True,
                            text=True)  # fmt: skip
    if result.returncode != 0:
        sys.exit(f"mocap {' '.join(args)} failed:\n{result.stderr}")
    if echo:
        print(result.stdout.strip())
    return time.perf_counter() - start
