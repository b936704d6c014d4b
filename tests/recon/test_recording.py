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
