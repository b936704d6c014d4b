"""Robustness table, photo and SfM inputs (issue 23): identical photos, link loops and broken
links among the photos, images too small or very large for features, options COLMAP would abort
on, and COLMAP's own error lines.

Every row runs `mocap` as a user does (see :mod:`tests.robustness.harness`); inputs are the six
320x240 photos of :mod:`tests.robustness.scenes` (sfm on them takes about 2 s).
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import pytest
from PIL import Image

from tests.helpers import run_cli
from tests.robustness.harness import (
    Case,
    Setup,
    assert_clean_success,
    assert_one_line_error,
    check_case,
    rows,
)
from tests.robustness.scenes import photos, workspace

Result = subprocess.CompletedProcess[str]


# Inputs --------------------------------------------------------------------------------------
def _copies(count: int) -> Setup:
    """``photos/`` of ``count`` byte-identical files of one photo."""

    def setup(d: Path) -> None:
        source = photos(d / "all") / "view_000.png"
        (d / "photos").mkdir()
        for i in range(count):
            shutil.copyfile(source, d / "photos" / f"copy_{i}.png")

    return setup


def _reencoded(count: int) -> Setup:
    """``photos/`` of ``count`` files of one photo's pixels, each PNG-compressed differently (so
    no two files are byte-identical)."""

    def setup(d: Path) -> None:
        pixels = Image.open(photos(d / "all") / "view_000.png")
        pixels.load()
        (d / "photos").mkdir()
        for i in range(count):
            pixels.save(d / "photos" / f"copy_{i}.png", compress_level=i + 1)
        assert len({p.read_bytes() for p in (d / "photos").iterdir()}) == count

    return setup


def _with_copy(d: Path) -> None:
    shutil.copyfile(photos(d) / "view_002.png", d / "photos" / "view_002_copy.png")


def _with_link_loops(d: Path) -> None:
    folder = photos(d)
    os.symlink("loop.jpg", folder / "loop.jpg")  # a link to itself
    os.symlink("ping.jpg", folder / "pong.jpg")  # two links to each other
    os.symlink("pong.jpg", folder / "ping.jpg")
    os.symlink("..", folder / "parent")  # a folder link to the folder above
    (folder / "sub").mkdir()
    os.symlink("../sub", folder / "sub" / "again")  # a folder link to its own folder


def _with_dangling_link(d: Path) -> None:
    os.symlink("deleted.jpg", photos(d) / "gone.jpg")


def _with_tiny_image(d: Path) -> None:
    Image.new("RGB", (1, 1), (128, 128, 128)).save(photos(d) / "tiny.png")


def _write_blank_png(path: Path, width: int, height: int) -> None:
    """A valid black 1-bit PNG of ``width`` x ``height``, compressed row by row: a few hundred
    kB on disk, never the full image in memory."""
    row = b"\x00" + bytes((width + 7) // 8)  # filter type 0, then the packed bits
    deflate = zlib.compressobj(9)
    data = b"".join(deflate.compress(row) for _ in range(height)) + deflate.flush()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(
            ">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)  # 1 bit, grey
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data)
                     + chunk(b"IEND", b""))


def _with_huge_image(d: Path) -> None:
    _write_blank_png(photos(d) / "huge.png", 20000, 20000)


def _with_webp(d: Path) -> None:
    import pycolmap

    folder = photos(d)
    Image.open(folder / "view_000.png").save(folder / "extra.webp")
    if pycolmap.Bitmap.read(str(folder / "extra.webp"), True) is not None:
        pytest.skip("this pycolmap reads WebP; the row needs an image it cannot read")


def _ws_init(d: Path) -> None:
    workspace(d, "init")


def _batch_ws(d: Path) -> None:
    from recon.workspace import Workspace

    _reencoded(2)(d)
    Workspace.create(d / "ws", d / "photos")


# What a later step makes of it ---------------------------------------------------------------
def _no_workspace(d: Path, _: Result) -> None:
    assert not (d / "ws").exists(), "a refused run left a workspace behind"


def _no_database(d: Path, _: Result) -> None:
    assert not (d / "ws" / "database.db").exists(), "COLMAP ran on a refused option"
    assert_clean_success(run_cli("sfm", d / "ws", cwd=d))  # the defaults then work


def _images(d: Path) -> list[str]:
    return sorted(p.name for p in (d / "ws" / "images").iterdir())


def _reconstructed(d: Path, _: Result) -> None:
    assert (d / "ws" / "sparse" / "0").is_dir(), "the run did not go on to a model"


def _seven_images(d: Path, _: Result) -> None:
    assert len(_images(d)) == 7, _images(d)


def _six_images(d: Path, _: Result) -> None:
    assert _images(d) == [f"view_00{i}.png" for i in range(6)]


def _links_skipped(d: Path, result: Result) -> None:
    _six_images(d, result)
    _reconstructed(d, result)


def _tiny_imported(d: Path, result: Result) -> None:
    assert "tiny.png" in _images(d)
    _reconstructed(d, result)


def _identical_refused_then_fixed(d: Path, result: Result) -> None:
    ws = d / "ws"
    assert not (ws / "sparse").exists(), "a failed mapping left a model"
    # Rerun: the same refusal, from the recorded features and matches.
    assert_one_line_error(again := run_cli("sfm", ws, cwd=d), r"identical")
    assert again.returncode == 2
    # Real photos instead: the workspace recomputes and maps.
    photos(d / "real")
    assert_clean_success(run_cli("init", ws, "--images", d / "real" / "photos", "--overwrite",
                                 cwd=d))
    assert_clean_success(run_cli("sfm", ws, cwd=d))
    _reconstructed(d, result)


def _unread_named_then_fixed(d: Path, result: Result) -> None:
    ws = d / "ws"
    assert not (ws / "database.db").exists(), "a failed extraction left a database"
    (d / "photos" / "extra.webp").unlink()
    assert_clean_success(run_cli("init", ws, "--images", d / "photos", "--overwrite", cwd=d))
    assert_clean_success(run_cli("sfm", ws, cwd=d))
    _reconstructed(d, result)


def _colmap_line_shown_with_verbose(d: Path, result: Result) -> None:
    assert "Failed to create any sparse model" not in result.stderr
    verbose = run_cli("-v", "sfm", d / "ws", cwd=d)
    assert verbose.returncode == 2
    assert "Failed to create any sparse model" in verbose.stderr, verbose.stderr
    assert not (d / "ws" / "sparse").exists()


def _batch_says_why(d: Path, result: Result) -> None:
    assert "TypeError" not in result.stdout + result.stderr
    failed = [line for line in result.stdout.splitlines() if "FAILED" in line]
    assert len(failed) == 1 and "FAILED at sfm: the photos" in failed[0], result.stdout
    assert "identical" in failed[0], failed[0]


def _sfm(*flags: str):
    return lambda d: ["sfm", d / "ws", "--images", d / "photos", *flags]


def _init(d: Path) -> list[str | Path]:
    return ["init", d / "ws", "--images", d / "photos"]


CASES = [
    # Identical photos: byte-identical files are caught when the photos are read; the same
    # pixels in different files when the matches do not move.
    Case("sfm-two-identical-files", _sfm(), setup=_copies(2), message=r"identical files",
         inputs=["photos"], then=_no_workspace),
    Case("sfm-three-identical-files", _sfm(), setup=_copies(3), message=r"identical files",
         inputs=["photos"], then=_no_workspace),
    Case("sfm-two-identical-pixels", _sfm(), setup=_reencoded(2),
         message=r"copy_0\.png and copy_1\.png are identical", inputs=["photos"],
         then=_identical_refused_then_fixed),
    # Three or more photos go through COLMAP's mapper, whose own ERROR line is hidden (and
    # shown with -v).
    Case("sfm-three-identical-pixels", _sfm(), setup=_reencoded(3),
         message=r"registered no images .*copies of one view", inputs=["photos"],
         then=_colmap_line_shown_with_verbose),
    Case("batch-two-identical-pixels",
         lambda d: ["batch", d / "ws", "--steps", "sfm", "--workers", "1"],
         setup=_batch_ws, message=r"1 of 1 workspaces failed", inputs=["photos"],
         then=_batch_says_why),
    Case("init-a-copy-among-photos", _init, setup=_with_copy, rc=0,
         message=r"note: view_002\.png, view_002_copy\.png are identical files",
         inputs=["photos"], then=_seven_images),
    # Links: loops and broken links are skipped with a note, folder links are not followed
    # (as COLMAP's own image listing does); the run goes on.
    Case("sfm-symlink-loops", _sfm(), setup=_with_link_loops, rc=0,
         message=r"(?s)note: skipped 3 broken link\(s\): loop\.jpg -> loop\.jpg \(a link "
                 r"loop\), ping\.jpg.*note: did not follow 2 link\(s\) to folders: parent, "
                 r"sub/again",
         inputs=["photos"], then=_links_skipped),
    Case("init-dangling-jpg-link", _init, setup=_with_dangling_link, rc=0,
         message=r"note: skipped 1 broken link\(s\): gone\.jpg -> deleted\.jpg \(its target "
                 r"is missing\)",
         inputs=["photos"], then=_six_images),
    # Image sizes, read from the headers only.
    Case("sfm-1x1-image", _sfm(), setup=_with_tiny_image, rc=0,
         message=r"note: tiny\.png \(1x1\): under 32 px on a side, too small for features",
         inputs=["photos"], then=_tiny_imported),
    Case("init-20000x20000-image", _init, setup=_with_huge_image, rc=0,
         message=r"note: huge\.png \(20000x20000\): very large; .* up to 2\.0 GB of memory",
         inputs=["photos"], then=_seven_images),
    # An image we read but COLMAP cannot (this pycolmap's FreeImage has no WebP): named, since
    # COLMAP names it only in a WARNING line, hidden by default.
    Case("sfm-image-colmap-cannot-read", _sfm(), setup=_with_webp,
         message=r"COLMAP could not read 1 of 7 images in .*: extra\.webp", inputs=["photos"],
         then=_unread_named_then_fixed),
    # Options COLMAP would abort or fail obscurely on are refused before it runs.
    Case("sfm-max-num-features-0", _sfm("--max-num-features", "0"), setup=photos,
         message=r"--max-num-features 0: give at least 1", inputs=["photos"],
         then=_no_workspace),
    Case("sfm-max-num-features-negative", lambda d: ["sfm", d / "ws", "--max-num-features", "-1"],
         setup=_ws_init, message=r"--max-num-features -1: give at least 1", inputs=["ws/images"],
         then=_no_database),
    Case("sfm-sequential-overlap-0",
         lambda d: ["sfm", d / "ws", "--matcher", "sequential", "--sequential-overlap", "0"],
         setup=_ws_init, message=r"--sequential-overlap 0: give at least 1",
         inputs=["ws/images"], then=_no_database),
]


@pytest.mark.parametrize("case", rows(CASES))
def test_sfm_input(case: Case, tmp_path: Path) -> None:
    check_case(case, tmp_path)
