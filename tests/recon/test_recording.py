"""Photos logged for the viewer must have exactly the Pinhole's resolution and the same content."""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.recording import MAX_LOGGED_IMAGE_SIZE, _display_scale, entity_name, thumbnail


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
@pytest.mark.parametrize("size", [(2501, 1667), (3072, 2048), (1500, 999)])
def test_thumbnail_matches_the_logged_pinhole(tmp_path, suffix, size):
    width, height = size
    yy, xx = np.mgrid[0:height, 0:width]
    # Smooth content, so JPEG and the resampling method barely matter.
    pixels = np.stack([(xx * 255 // width), (yy * 255 // height), (xx + yy) % 256 * 0], -1)
    path = tmp_path / f"photo{suffix}"
    cv2.imwrite(str(path), pixels.astype(np.uint8))
    scale = _display_scale(width, height)
    image = thumbnail(path, size, scale)
    expected = (round(height * scale), round(width * scale))
    assert image.shape[:2] == expected
    assert max(expected) == MAX_LOGGED_IMAGE_SIZE
    reference = cv2.resize(pixels.astype(np.uint8), expected[::-1], interpolation=cv2.INTER_AREA)
    assert np.abs(image.astype(int) - reference.astype(int)).mean() < 3.0  # grey levels


def test_entity_names_have_no_separators():
    assert entity_name("sub/dir/img.01.JPG") == "sub_dir_img_01_JPG"


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 1 MiB tmpfs (root only): a disk that fills up."""
    from tests.helpers import small_disk

    with small_disk(tmp_path / "disk", 1 << 20) as folder:
        yield folder


def _log_points(path, megabytes):
    from recon.recording import log_points, step_recording

    rng = np.random.default_rng(0)
    with step_recording(path, "test") as rec:
        for i in range(megabytes):  # about 1.2 MB each (random float32 xyz, incompressible)
            log_points(rec, rng.random((100_000, 3), dtype=np.float32), entity=f"world/p{i}")


def test_a_recording_is_complete_and_verifies(tmp_path):
    import subprocess

    from recon.recording import _RRD_FOOTER, viewer_command

    path = tmp_path / "logs" / "test.rrd"
    path.parent.mkdir()
    _log_points(path, 2)
    assert path.read_bytes()[-12:-4] == _RRD_FOOTER
    assert not list(path.parent.glob("*.partial*"))
    rerun = viewer_command([])[0]
    assert subprocess.run([rerun, "rrd", "verify", str(path)], capture_output=True).returncode == 0


@pytest.mark.parametrize("megabytes", [pytest.param(1, marks=pytest.mark.slow), 3,
                                       pytest.param(10, marks=pytest.mark.slow)])
def test_a_full_disk_fails_the_recording_in_one_line_without_hanging(small_tmpfs, megabytes):
    """rerun-sdk 0.41's own file sink hangs for ever in flush (and in drop) once a write fails;
    behind the FIFO the step fails at once with a UserError, and no partial file is left."""
    import time

    from recon.errors import UserError

    path = small_tmpfs / "test.rrd"
    path.write_bytes(b"previous recording")
    start = time.perf_counter()
    with pytest.raises(UserError, match=r"cannot write the recording .*no space left"):
        _log_points(path, megabytes)
    assert time.perf_counter() - start < 30.0  # seconds; the file sink hung for minutes
    assert path.read_bytes() == b"previous recording"
    assert [p.name for p in small_tmpfs.iterdir()] == ["test.rrd"]


# Default blueprints (issue 21) -----------------------------------------------------------------
def _steps_with_recordings() -> dict[str, Path]:
    """Every step name the code opens a recording for, found in the source (so that a new
    step without a blueprint fails here): {step: the file that opens it}."""
    from tests.helpers import ROOT

    steps = {}
    for path in [*(ROOT / "recon").rglob("*.py"), *(ROOT / "tracking").rglob("*.py")]:
        text = path.read_text()
        constant = re.search(r'^STEP = "([\w-]+)"', text, re.MULTILINE)
        for match in re.finditer(r'step_recording\([^,()]+(?:\([^()]*\))?,\s*("([\w-]+)"|STEP)\)',
                                 text):  # fmt: skip
            step = match.group(2) or (constant.group(1) if constant else None)
            assert step is not None, f"{path}: step_recording with an unknown step name"
            steps[step] = path
    return steps


def test_every_step_recording_has_a_default_blueprint():
    from recon.recording import BLUEPRINTS

    steps = _steps_with_recordings()
    assert {"features", "matches", "intrinsics", "mapping", "dense", "mesh", "compare", "synth",
            "silhouettes", "track", "report", "fit"} <= set(steps)  # the scan finds them
    assert sorted(set(steps) - set(BLUEPRINTS)) == []


def _saved(tmp_path: Path, step: str, cameras: int) -> Path:
    from recon.recording import log_camera_image, step_recording

    path = tmp_path / "ws" / "logs" / f"{step}.rrd"
    path.parent.mkdir(parents=True, exist_ok=True)
    K = np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]])
    with step_recording(path, step) as rec:
        for i in range(cameras):
            log_camera_image(rec, image_name=f"img.{i:03d}.jpg", image_path=None, K=K, width=64,
                             height=48, cam_from_world=np.eye(4)[:3])  # fmt: skip
    return path


def test_a_step_recording_carries_its_blueprint_under_its_own_application_id(tmp_path):
    """The viewer shares one blueprint between the recordings of an application id; `mocap
    view` opens a workspace's recordings together, so each step has its own."""
    from tests.helpers import read_recording

    rec = read_recording(_saved(tmp_path, "silhouettes", 3))
    assert rec.application_id == "mocap-silhouettes" and rec.timeline == "frame"
    views = {(v["kind"], v["origin"], v["name"]) for v in rec.views}
    # One 2D view per camera logged, in its image, named after it.
    assert {("2D", f"world/cameras/img_{i:03d}_jpg/image", f"img_{i:03d}_jpg")
            for i in range(3)} <= views  # fmt: skip
    assert ("TimeSeries", "silhouettes", "foreground fraction") in views
    assert read_recording(_saved(tmp_path, "mesh", 2)).application_id == "mocap-mesh"


def test_a_step_without_a_builder_gets_the_viewers_automatic_layout(tmp_path):
    from tests.helpers import read_recording

    rec = read_recording(_saved(tmp_path, "not-a-step", 1))
    assert rec.views == [] and rec.timeline is None
    assert rec.layout_problems() == ["no blueprint"]


def test_camera_views_are_capped_for_large_models(tmp_path):
    from recon.recording import MAX_CAMERA_VIEWS
    from tests.helpers import read_recording

    rec = read_recording(_saved(tmp_path, "features", MAX_CAMERA_VIEWS + 5))
    views = [v for v in rec.views if v["kind"] == "2D"]
    assert sorted(v["name"] for v in views) == [f"img_{i:03d}_jpg" for i in range(MAX_CAMERA_VIEWS)]
    assert rec.timeline == "image"


def test_the_viewer_listens_on_loopback_only(tmp_path):
    """Issue 21: started by hand, rerun 0.41's viewer served 0.0.0.0:9876. The command `mocap
    view` runs, started headless (no window: the same server) on a free port, listens on
    127.0.0.1 only."""
    import contextlib
    import signal
    import subprocess
    import time

    psutil = pytest.importorskip("psutil")
    from recon.recording import viewer_command

    path = tmp_path / "logs" / "test.rrd"
    path.parent.mkdir()
    _log_points(path, 0)
    command = [*viewer_command([path]), "--headless", "--port", "auto", "--web-viewer-port", "0"]
    # `rerun` of the wheel is a Python script that runs the binary as its child: both in a
    # session of their own, ended together.
    viewer = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              start_new_session=True,
                              env={**os.environ, "RERUN_ANALYTICS": "0"})  # fmt: skip
    try:
        addresses: set[str] = set()
        deadline = time.monotonic() + 30.0  # seconds; it listens after about 1 s here
        while not addresses and viewer.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
            with contextlib.suppress(psutil.NoSuchProcess):
                wrapper = psutil.Process(viewer.pid)
                addresses = {c.laddr.ip
                             for p in [wrapper, *wrapper.children(recursive=True)]
                             for c in p.net_connections("tcp") if c.status == psutil.CONN_LISTEN}
        if viewer.poll() is not None:
            pytest.skip("the headless viewer does not start here: "
                        + viewer.stderr.read().decode(errors="replace")[-300:])
        assert addresses == {"127.0.0.1"}
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(viewer.pid, signal.SIGKILL)
        viewer.wait(timeout=10)
