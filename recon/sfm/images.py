"""Find and check the photos of a source folder, and read what their EXIF says about focal length.

Only reads files. Corrupt or unreadable images are an error (naming the file); files that are
not images at all, broken links and link loops are skipped with a note.
"""

from __future__ import annotations

import errno
import hashlib
import math
import os
import stat
from collections import defaultdict
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
    """Images under ``source`` as (COLMAP name, path), sorted, plus notes for the user.

    Links to files are followed; links to folders are not (as COLMAP's own recursive image
    listing does), so a link loop cannot recurse. Broken links and link loops are skipped with
    a note, as are non-image files. Notes also name byte-identical copies and images too small
    or very large for feature extraction (:func:`size_notes`).
    """
    if not source.exists():
        raise UserError(f"image folder {source} does not exist")
    if not source.is_dir():
        raise UserError(f"{source} is not a folder of images")
    excluded = exclude.resolve() if exclude is not None else None
    found: list[tuple[str, Path]] = []
    sizes: dict[str, tuple[int, int]] = {}
    skipped: list[str] = []
    broken: list[str] = []
    folder_links: list[str] = []
    for path in sorted(source.rglob("*")):
        if path.name.startswith("."):
            continue
        name = path.relative_to(source).as_posix()
        if path.is_symlink():
            try:
                target = path.stat()  # follows the link
            except OSError as exc:
                why = "a link loop" if exc.errno == errno.ELOOP else "its target is missing"
                broken.append(f"{name} -> {os.readlink(path)} ({why})")
                continue
            if stat.S_ISDIR(target.st_mode):
                folder_links.append(name)
                continue
        if excluded is not None and path.resolve().is_relative_to(excluded):
            continue
        if not path.is_file():
            continue
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            skipped.append(name)
            continue
        sizes[name] = check_image(path)
        found.append((name, path))
    notes = []
    if skipped:
        notes.append(f"skipped {len(skipped)} non-image file(s): {_listed(skipped)}")
    if broken:
        notes.append(f"skipped {len(broken)} broken link(s): {_listed(broken)}")
    if folder_links:
        notes.append(f"did not follow {len(folder_links)} link(s) to folders: "
                     f"{_listed(folder_links)}")
    if not found:
        raise UserError(f"no images in {source} (looked for {', '.join(sorted(IMAGE_SUFFIXES))})")
    copies = identical_files(found)
    distinct = len(found) - sum(len(group) - 1 for group in copies)
    if distinct < 2:
        if len(found) < 2:
            raise UserError(f"only one image in {source}: structure from motion needs at "
                            "least 2")
        raise UserError(f"the images in {source} are identical files "
                        f"({_listed(copies[0])}): structure from motion needs at least 2 "
                        "different photos")
    for group in copies:
        notes.append(f"{_listed(group)} are identical files: the copies add nothing to the "
                     "reconstruction")
    notes += size_notes(sizes)
    return found, notes


# COLMAP registers an image from at least 30 inlier matches (abs_pose_min_num_inliers). Measured
# on a photo of the synthetic room scaled down, COLMAP's SIFT finds 0 keypoints at 12 px, 2 at
# 16 px and 15 at 32 px (50 at 48 px): under 32 px on a side an image cannot be registered. (The
# Harris-NCC front end's 15 px windows and their border leave even less.)
MIN_IMAGE_SIDE_PX = 32
# COLMAP decodes every image at full size before scaling it to --max-image-size: measured with
# one extraction thread, a 20000 x 20000 PNG or JPEG of no features peaks at 2.0 GB, about
# 5 bytes a pixel (SIFT on a 3200 px image takes about 2.1 GB on its own, whatever the input
# size). Above 100 Mpx, more than any camera but medium-format backs give, the decode alone
# takes over 0.5 GB per image in flight, and COLMAP reads one per extraction thread.
LARGE_IMAGE_PIXELS = 100_000_000
DECODE_BYTES_PER_PIXEL = 5


def size_notes(sizes: dict[str, tuple[int, int]]) -> list[str]:
    """Notes on images too small to hold a feature and on very large ones (name → (w, h))."""
    notes = []
    small = [f"{n} ({w}x{h})" for n, (w, h) in sizes.items() if min(w, h) < MIN_IMAGE_SIDE_PX]
    if small:
        notes.append(f"{_listed(small)}: under {MIN_IMAGE_SIDE_PX} px on a side, too small "
                     "for features; such an image will not be registered")
    large = {n: (w, h) for n, (w, h) in sizes.items() if w * h > LARGE_IMAGE_PIXELS}
    if large:
        w, h = max(large.values(), key=lambda size: size[0] * size[1])
        shown = _listed([f"{n} ({w}x{h})" for n, (w, h) in large.items()])
        peak_gb = w * h * DECODE_BYTES_PER_PIXEL / 1e9
        notes.append(f"{shown}: very large; COLMAP decodes each at full size before scaling "
                     f"it down for features, up to {peak_gb:.1f} GB of memory per image read")
    return notes


def identical_files(found: list[tuple[str, Path]]) -> list[list[str]]:
    """Groups of names whose files hold the same bytes (only same-size files are read)."""
    by_size: dict[int, list[tuple[str, Path]]] = defaultdict(list)
    for name, path in found:
        by_size[path.stat().st_size].append((name, path))
    groups: list[list[str]] = []
    for candidates in by_size.values():
        if len(candidates) < 2:
            continue
        by_digest: dict[bytes, list[str]] = defaultdict(list)
        for name, path in candidates:
            digest = hashlib.sha256()
            with path.open("rb") as file:
                while chunk := file.read(1 << 20):
                    digest.update(chunk)
            by_digest[digest.digest()].append(name)
        groups += [names for names in by_digest.values() if len(names) > 1]
    return sorted(groups)


def _listed(names: list[str], shown: int = 5) -> str:
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


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
