"""Photos logged for the viewer must have exactly the Pinhole's resolution and the same content."""

from __future__ import annotations

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
