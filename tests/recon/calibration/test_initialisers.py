"""The built-in intrinsic initialisers against focal lengths known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

import plugins
from plugins.protocols import CameraInfo, IntrinsicsContext
from recon.errors import UserError
from recon.sfm.images import exif_focal_px


def _jpeg(path, *, size=(400, 300), **tags):
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    for tag, value in tags.items():
        sub[{"focal_mm": 0x920A, "res_x": 0xA20E, "unit": 0xA210, "f35": 0xA405,
             "exif_width": 0xA002}[tag]] = value
    pixels = np.random.default_rng(0).integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
    Image.fromarray(pixels).save(path, exif=exif)
    return path


def _context(tmp_path, names):
    camera = CameraInfo(camera_id=1, model="SIMPLE_RADIAL", width=400, height=300,
                        image_names=tuple(names))
    return IntrinsicsContext(database_path=tmp_path / "db", images_dir=tmp_path, cameras=(camera,))


def test_exif_focal_from_focal_plane_resolution(tmp_path):
    # 4.5 mm lens, 250 px/mm at the 4000 px original, file downscaled to 400 px: 112.5 px.
    path = _jpeg(tmp_path / "a.jpg", focal_mm=4.5, res_x=250.0, unit=4, exif_width=4000)
    assert exif_focal_px(path).focal_px == pytest.approx(4.5 * 250 * 400 / 4000)
    # Resolution unit inches (2): 6350 px/inch = 250 px/mm.
    path = _jpeg(tmp_path / "b.jpg", focal_mm=4.5, res_x=6350.0, unit=2, exif_width=400)
    assert exif_focal_px(path).focal_px == pytest.approx(4.5 * 250)


def test_exif_focal_from_35mm_equivalent(tmp_path):
    path = _jpeg(tmp_path / "a.jpg", f35=28)
    expected = 28 * math.hypot(400, 300) / math.hypot(36, 24)
    assert exif_focal_px(path).focal_px == pytest.approx(expected)


def test_exif_plugin_gives_priors_or_a_clear_error(tmp_path):
    _jpeg(tmp_path / "a.jpg", f35=28)
    _jpeg(tmp_path / "none.jpg")
    exif = plugins.create("intrinsics", "exif")
    result = exif.initialise(_context(tmp_path, ["none.jpg", "a.jpg"]))
    assert result.priors[0].focal_px == pytest.approx(28 * 500 / math.hypot(36, 24))
    assert result.refine_focal is True
    with pytest.raises(UserError, match="no EXIF focal length in .*none.jpg"):
        exif.initialise(_context(tmp_path, ["none.jpg"]))


def test_fixed_and_default(tmp_path):
    ctx = _context(tmp_path, ["x.jpg"])
    fixed = plugins.create("intrinsics", "fixed", ["focal_px=321"]).initialise(ctx)
    assert fixed.priors[0].focal_px == 321 and fixed.refine_focal is False
    default = plugins.create("intrinsics", "colmap-default").initialise(ctx)
    assert default.priors[0].focal_px is None and default.refine_focal is True
