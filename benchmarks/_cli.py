"""What the benchmark scripts share: running `mocap` as a user would, in its own process, and
the bare pycolmap calls it is measured against, and where the real data sets are."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

SHARED_DATA = Path(os.environ.get("MOCAP_SHARED_DATA")
                   or Path(__file__).resolve().parents[2] / "shared" / "data")
"""The real data sets: ``$MOCAP_SHARED_DATA`` when set (as the tests read it), else
``../shared/data`` beside the repository."""

# COLMAP's defaults through pycolmap, as a user would call them without `mocap` (one shared
# camera, exhaustive matching, incremental mapping): `python -c BARE_COLMAP IMAGES OUT` writes
# the largest model to OUT/best and prints its number of registered images.
BARE_COLMAP = """
import sys
from pathlib import Path
import pycolmap
pycolmap.logging.minloglevel = 2
images, out = Path(sys.argv[1]), Path(sys.argv[2])
names = sorted(p.name for p in images.iterdir()
               if p.suffix.lower() in {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"})
db = out / "database.db"
pycolmap.set_random_seed(0)
pycolmap.extract_features(db, images, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
                          device=pycolmap.Device.cpu)
pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
options = pycolmap.IncrementalPipelineOptions()
options.random_seed = 0
(out / "sparse").mkdir()
models = pycolmap.incremental_mapping(db, images, out / "sparse", options=options)
best = max(models, key=lambda i: models[i].num_reg_images())
(out / "best").mkdir()
models[best].write(out / "best")
print(models[best].num_reg_images())
"""


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
