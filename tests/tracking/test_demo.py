"""The demo of all three modules (`tracking.demo`): its capture part against the truth, its
flags, and (slow) the whole demo end to end."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from recon.demo import DemoConfig
from recon.errors import UserError
from tracking.commands import DemoCommand, add_demo_arguments
from tracking.demo import MotionDemoConfig, run_capture_demo, run_demo


def test_demo_flags_are_the_photo_demos_and_the_new_ones():
    parser = argparse.ArgumentParser()
    add_demo_arguments(parser)  # argparse refuses a flag defined twice
    args = parser.parse_args(["--out", "x", "--num-views", "10", "--no-mesh", "--no-compare",
                              "--capture-frames", "14", "--matcher", "sequential",
                              "--overwrite"])
    assert (args.out, args.num_views, args.mesh) == (Path("x"), 10, False)
    assert (args.compare, args.capture, args.capture_frames) == (False, None, 14)
    assert args.matcher == "sequential" and args.overwrite
    with pytest.raises(UserError, match="--capture-frames 9: the report needs at least 10"):
        MotionDemoConfig(capture_frames=9)
    from plugins.protocols import Command

    assert isinstance(DemoCommand(), Command)


@pytest.mark.slow  # its path is covered faster elsewhere (make test's 10-minute budget)
def test_capture_part_of_the_demo_scores_against_the_truth(tmp_path: Path):
    """The demo's synthetic walk, filmed and captured (what `test_capture.py` checks step by
    step); here: the demo's scores, files and lines, and a second run that reuses it all."""
    config = MotionDemoConfig(capture_frames=10)
    motion = run_capture_demo(tmp_path / "motion", config, progress=False)
    # Measured 10.8 mm and 0.93 on test_capture.py's walk (see it for the bounds).
    assert motion.scores.mpjpe_mm < 30.0 and motion.scores.silhouette_iou > 0.8
    saved = json.loads((tmp_path / "motion" / "evaluation.json").read_text())
    assert saved["scores"]["mpjpe_mm"] == pytest.approx(motion.scores.mpjpe_mm)
    # mocap synth's default subject on the 1.68 m walk: 1.55 m, tracked to within 5 cm.
    assert saved["subject_height_m"] == pytest.approx(1.547, abs=0.005)
    assert abs(saved["tracked_height_m"] - saved["subject_height_m"]) < 0.05
    lines = motion.lines()
    assert lines[0].startswith("synth       10 frames x 4 cameras 320x240")
    assert any(re.match(r"truth +MPJPE \d+\.\d mm over 10 frames", line) for line in lines)
    again = run_capture_demo(tmp_path / "motion", config, progress=False)
    assert again.synth.reused and all(step.reused for step in again.capture.steps)
    assert again.scores == motion.scores


@pytest.mark.slow
def test_the_whole_demo(tmp_path: Path):
    """Photos → mesh, the focal initialisers compared, and the capture of a walk, all against
    the truth; every file the summary points at exists; a second run reuses every step."""
    out = tmp_path / "demo"
    report = run_demo(DemoConfig(out=out), progress=False)
    assert abs(report.photos.focal_rel_error) < 0.01
    assert report.photos.mesh is not None and report.photos.mesh["f_score"] >= 0.9
    assert report.comparison is not None
    for name in ("kruppa", "colmap-default+ba"):
        entry = report.comparison.methods[name]
        assert entry["registered"] == 12 and abs(entry["rel_error"]) < 0.01
    assert report.motion is not None and report.motion.scores.mpjpe_mm < 30.0
    where = report.where()
    for line in where:
        kind, text = line.split(maxsplit=1)
        path = Path(text.split(" (")[0])
        assert path.exists(), line
        if kind == "recording":
            assert all((path / name).is_file() for name in text.split(" (")[1][:-1].split(", "))
    assert any(line.endswith("/motion/capture/report/index.html") for line in where)
    again = run_demo(DemoConfig(out=out), progress=False)
    assert again.motion is not None and all(s.reused for s in again.motion.capture.steps)
