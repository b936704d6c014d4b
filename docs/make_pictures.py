"""The README's pictures: each step's recording in a headless Rerun viewer, default blueprint.

Not part of the test suite. Needs the venv's `rerun` viewer and a Vulkan driver (Mesa's
software llvmpipe will do, slowly). From the repository:

    .venv/bin/mocap demo --out /tmp/pics/demo
    .venv/bin/python docs/make_pictures.py --demo /tmp/pics/demo [--steps track report ...]

`fit` fits a synthetic body cloud (the one tests/tracking/fit uses) with `mocap fit --body
superquadric`. Writes docs/images/recording-<step>.png: the viewport only (panels hidden),
1920x1080 at 1.5x UI zoom scaled to 1280 wide, a palette PNG under 150 KB.
"""

import argparse
import io
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image

STEPS = {  # step: its recording in the demo workspace
    "features": "logs/features.rrd", "matches": "logs/matches.rrd", "mapping": "logs/mapping.rrd",
    "dense": "logs/dense.rrd", "mesh": "logs/mesh.rrd", "compare": "logs/compare.rrd",
    "synth": "motion/synth/logs/synth.rrd", "silhouettes": "motion/capture/logs/silhouettes.rrd",
    "track": "motion/capture/logs/track.rrd", "report": "motion/capture/logs/report.rrd",
}
HIDDEN_PANELS = ("ui.toggle_top_panel", "ui.toggle_blueprint_panel", "ui.toggle_selection_panel",
                 "recording.toggle_time_panel")  # the time panel collapses to its one-line bar
MAX_BYTES = 150_000
TOP_STRIP = 56  # pixels: the top panel, hidden, leaves an empty bar at 1.5x zoom


def fit_recording(work: Path) -> Path:
    import numpy as np
    import open3d as o3d

    from tracking.body.model import BodyModel, BodyShape
    from tracking.body.synthetic import body_cloud, random_pose

    rng = np.random.default_rng(3)
    points, _ = body_cloud(BodyModel(BodyShape.default(1.7)), random_pose(rng, spread=0.5), rng,
                           noise_m=0.005, hidden_fraction=0.3)
    cloud = work / "person.ply"
    cloud_3d = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    o3d.io.write_point_cloud(str(cloud), cloud_3d)
    mocap = Path(sys.executable).parent / "mocap"
    subprocess.run([mocap, "fit", "--cloud", cloud, "--out", work, "--body", "superquadric"],
                   check=True)
    return work / "fit.rrd"


def save_compact(png: bytes, path: Path) -> None:
    """Without the hidden top panel's empty strip, 1280 wide, in the most colours (of 256, 192,
    128, 96, 64) that fit MAX_BYTES."""
    image = Image.open(io.BytesIO(png)).convert("RGB")
    image = image.crop((0, TOP_STRIP, image.width, image.height))
    image = image.resize((1280, round(image.height * 1280 / image.width)), Image.LANCZOS)
    for colours in (256, 192, 128, 96, 64):
        palette = image.quantize(colours, method=Image.Quantize.FASTOCTREE)
        buffer = io.BytesIO()
        image.quantize(palette=palette, dither=Image.Dither.NONE).save(buffer, "PNG", optimize=True)
        if buffer.tell() <= MAX_BYTES:
            break
    path.write_bytes(buffer.getvalue())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo", type=Path, required=True, help="workspace of `mocap demo`")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "images")
    parser.add_argument("--steps", nargs="+", default=[*STEPS, "fit"])
    parser.add_argument("--port", type=int, default=9877)
    args = parser.parse_args()
    os.environ["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"
    from rerun.experimental import ViewerClient

    recordings = {step: args.demo / STEPS[step] for step in args.steps if step != "fit"}
    if "fit" in args.steps:
        recordings["fit"] = fit_recording(Path(tempfile.mkdtemp(prefix="mocap-fit-")))
    args.out.mkdir(parents=True, exist_ok=True)
    with ViewerClient.spawn(headless=True, port=args.port, hide_welcome_screen=True) as viewer:
        time.sleep(3)
        for _ in range(5):  # 1.5x: the 1920x1080 screenshot reads like a 1280x720 window
            viewer.run_command("ui.zoom_in_ui")
        for step, rrd in recordings.items():
            viewer.close("all")
            viewer.open(str(rrd.resolve()))
            time.sleep(6)  # the blueprint's views fill in
            for panel in HIDDEN_PANELS:  # per recording: each has its own panel state
                viewer.run_command(panel)
            time.sleep(2)
            path = args.out / f"recording-{step}.png"
            save_compact(viewer.take_screenshot(), path)
            print(f"{path}  {path.stat().st_size // 1024} KiB")
        viewer.quit()


if __name__ == "__main__":
    main()
