"""Finding the photos of a folder (recon.sfm.images): links, copies and image sizes."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PIL import Image

from recon.errors import UserError
from recon.sfm.images import (
    LARGE_IMAGE_PIXELS,
    MIN_IMAGE_SIDE_PX,
    scan_images,
    size_notes,
)
from recon.sfm.twoview import median_parallax_px


def _photo(path, seed, size=(64, 48)):
    rng = np.random.default_rng(seed)
    Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(path)


def test_links_loops_and_broken_links_are_skipped_with_notes(tmp_path):
    for i in range(2):
        _photo(tmp_path / f"p{i}.png", i)
    os.symlink("p0.png", tmp_path / "alias.png")  # a link to a photo: followed
    os.symlink("self.jpg", tmp_path / "self.jpg")
    os.symlink("missing.jpg", tmp_path / "gone.jpg")
    os.symlink(".", tmp_path / "here")  # a folder link to its own folder
    found, notes = scan_images(tmp_path)
    assert [name for name, _ in found] == ["alias.png", "p0.png", "p1.png"]
    assert notes[0] == ("skipped 2 broken link(s): gone.jpg -> missing.jpg (its target is "
                        "missing), self.jpg -> self.jpg (a link loop)")
    assert notes[1] == "did not follow 1 link(s) to folders: here"
    assert "alias.png, p0.png are identical files" in notes[2]


def test_only_copies_of_one_photo_are_refused(tmp_path):
    _photo(tmp_path / "a.png", 0)
    (tmp_path / "b.png").write_bytes((tmp_path / "a.png").read_bytes())
    with pytest.raises(UserError, match=r"identical files \(a\.png, b\.png\)"):
        scan_images(tmp_path)
    _photo(tmp_path / "c.png", 1)  # one different photo is enough
    found, notes = scan_images(tmp_path)
    assert len(found) == 3 and notes == ["a.png, b.png are identical files: the copies add "
                                         "nothing to the reconstruction"]


def test_size_notes_bounds():
    side = MIN_IMAGE_SIDE_PX
    assert size_notes({"a": (side, side), "b": (4000, 3000)}) == []
    assert "b (4000x31)" in size_notes({"a": (side, side), "b": (4000, side - 1)})[0]
    assert size_notes({"a": (10_000, 10_000)}) == []  # exactly the bound: no note
    (note,) = size_notes({"a": (10_000, 10_001), "b": (20_000, 20_000)})
    assert note.startswith("a (10000x10001), b (20000x20000): very large")
    assert "up to 2.0 GB" in note  # the largest one's decode, at 5 bytes a pixel
    assert LARGE_IMAGE_PIXELS == 10_000 * 10_000


def test_median_parallax():
    keypoints = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    matches = np.array([[0, 0], [1, 1], [2, 2]])
    assert median_parallax_px(keypoints, keypoints, matches) == 0.0
    assert median_parallax_px(keypoints, keypoints + [3.0, 4.0], matches) == pytest.approx(5.0)
