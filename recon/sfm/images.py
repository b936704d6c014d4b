"""Find and check the photos of a source folder, and read what their EXIF says about focal length.

Only reads files. Corrupt or unreadable images are an error (naming the file); files that are
not images at all are skipped with a note.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from PIL import ExifTags, Image, UnidentifiedImageError

from recon.errors import UserError

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp"})
# Decompression-bomb protection would reject legitimate 100+ megapixel photos.
Image.MAX_IMAGE_PIXELS = None


def check_image(path: Path) -> tuple[int, int]:
    """(width, height) of a fully decodable image; UserError naming the file otherwise."""
    try:
        with Image.open(path) as im:
            size = im.size
            if im.format == "PNG":
                im.verify()  # every chunk's CRC, without inflating the pixels
            else:
                if im.format == "JPEG":
                    # Decoding at 1/8 scale (DCT scaling) still reads every entropy-coded byte,
                    # so truncation and corruption are caught at a fraction of the cost.
                    im.draft("RGB", (max(1, size[0] // 8), max(1, size[1] // 8)))
                im.load()
            return size
    except UnidentifiedImageError:
        raise UserError(f"{path}: not a readable image (unknown or corrupt format)") from None
    except (OSError, SyntaxError, ValueError) as exc:
        raise UserError(f"{path}: corrupt or unreadable image ({exc})") from None


def scan_images(
    source: Path, *, exclude: Path | None = None
) -> tuple[list[tuple[str, Path]], list[str]]:
    """Images under ``source`` as (COLMAP name, path), sorted, plus notes on skipped files."""
    if not source.exists():
        raise UserError(f"image folder {source} does not exist")
    if not source.is_dir():
        raise UserError(f"{source} is not a folder of images")
    excluded = exclude.resolve() if exclude is not None else None
    found: list[tuple[str, Path]] = []
    skipped: list[str] = []
    for path in sorted(source.rglob("*")):
        if excluded is not None and path.resolve().is_relative_to(excluded):
            continue
        if not path.is_file() or path.name.startswith("."):
            continue
        name = path.relative_to(source).as_posix()
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            skipped.append(name)
            continue
        check_image(path)
        found.append((name, path))
    notes = []
    if skipped:
        more = f" and {len(skipped) - 5} more" if len(skipped) > 5 else ""
        shown = ", ".join(skipped[:5]) + more
        notes.append(f"skipped {len(skipped)} non-image file(s): {shown}")
    if not found:
        raise UserError(f"no images in {source} (looked for {', '.join(sorted(IMAGE_SUFFIXES))})")
    if len(found) < 2:
        raise UserError(f"only one image in {source}: structure from motion needs at least 2")
    return found, notes


@dataclass(frozen=True)
class ExifFocal:
    focal_px: float
    source: str


def exif_focal_px(path: Path) -> ExifFocal | None:
    """Focal length in pixels from EXIF, or None when the tags are absent.

    Prefers the physical focal length with the focal-plane resolution (the sensor's pixel
    pitch); falls back to the 35 mm-equivalent focal length, which by the EXIF/CIPA definition
    refers to the 43.27 mm diagonal of a 36x24 mm frame.
    """
    with Image.open(path) as im:
        width, height = im.size
        exif = camera_exif(im)
    sub = exif.get_ifd(ExifTags.IFD.Exif)
    tags = {**exif, **sub}
    focal_mm = _positive(tags.get(ExifTags.Base.FocalLength))
    res_x = _positive(tags.get(ExifTags.Base.FocalPlaneXResolution))
    unit = tags.get(ExifTags.Base.FocalPlaneResolutionUnit, 2)
    mm_per_unit = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}.get(int(unit) if unit else 2)
    if focal_mm and res_x and mm_per_unit:
        # The resolution refers to the image as the camera wrote it; scale to this file's width.
        exif_width = _positive(tags.get(ExifTags.Base.ExifImageWidth)) or width
        px_per_mm = res_x / mm_per_unit * (width / exif_width)
        return ExifFocal(focal_mm * px_per_mm, f"EXIF {focal_mm:g} mm at {px_per_mm:.1f} px/mm")
    focal_35 = _positive(tags.get(ExifTags.Base.FocalLengthIn35mmFilm))
    if focal_35:
        diagonal_px = math.hypot(width, height)
        return ExifFocal(
            focal_35 * diagonal_px / math.hypot(36.0, 24.0),
            f"EXIF 35 mm-equivalent {focal_35:g} mm",
        )
    return None


def camera_exif(im: Image.Image) -> Image.Exif:
    """EXIF of an opened image; empty for formats whose EXIF would need a full decode (PNG)."""
    return im.getexif() if im.format in ("JPEG", "MPO", "TIFF", "WEBP") else Image.Exif()


def camera_key(path: Path) -> tuple:
    """What must agree for two photos to share intrinsics: size, camera body, focal length."""
    with Image.open(path) as im:
        exif = camera_exif(im)
        sub = exif.get_ifd(ExifTags.IFD.Exif)
        return (
            im.size,
            exif.get(ExifTags.Base.Make),
            exif.get(ExifTags.Base.Model),
            str(sub.get(ExifTags.Base.FocalLength)),
        )


def _positive(value: object) -> float | None:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if number > 0 and math.isfinite(number) else None
