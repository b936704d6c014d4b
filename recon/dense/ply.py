"""PLY files of the dense and mesh steps, checked: header, declared counts and size.

Open3D's PLY writer (RPly) reports success when its writes fail (a full disk: issue 23), and its
reader returns an empty cloud for a file that is not a PLY or is cut short. So a written PLY is
read back here (its header, and its size against the one the header implies) before it is
trusted, and a PLY about to be read is checked the same way, so that a damaged file is called
damaged instead of "empty".

:func:`parse_header` and :func:`payload_size` are pure (bytes in, numbers out);
:func:`check_ply` and :func:`written_size` read or write the file system.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

__all__ = ["PlyError", "PlyHeader", "check_ply", "parse_header", "payload_size", "quiet_stderr"]

MAX_HEADER_BYTES = 64 * 1024
"""A PLY header longer than this is not one that Open3D, COLMAP or MeshLab write."""

_SCALAR_BYTES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}  # fmt: skip


class PlyError(ValueError):
    """A file that is not a readable PLY, or is cut short. The message is one line."""


@dataclass(frozen=True)
class PlyElement:
    name: str
    count: int
    properties: tuple[tuple[str, ...], ...]
    """Each property's type words: ``("double",)`` or ``("list", "uchar", "uint")``."""


@dataclass(frozen=True)
class PlyHeader:
    format: str
    """``ascii``, ``binary_little_endian`` or ``binary_big_endian``."""
    elements: tuple[PlyElement, ...]
    header_bytes: int
    """Length of the header up to and including the newline after ``end_header``."""

    def count(self, element: str) -> int:
        """The declared count of ``element`` (0 when the file has none)."""
        return next((e.count for e in self.elements if e.name == element), 0)


def parse_header(data: bytes) -> PlyHeader:
    """The header at the start of ``data`` (the first bytes of a file; at least the header).

    Raises :class:`PlyError` when ``data`` does not start with a complete, well-formed header.
    """
    if not data.startswith(b"ply"):
        raise PlyError("not a PLY file (it does not start with 'ply')")
    end = data.find(b"end_header")
    if end < 0:
        raise PlyError("not a readable PLY file (no end_header in its first "
                       f"{min(len(data), MAX_HEADER_BYTES)} bytes)")
    newline = data.find(b"\n", end)
    if newline < 0:
        raise PlyError("truncated PLY file (it ends in its header)")
    try:
        lines = data[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise PlyError("not a readable PLY file (its header is not text)") from None
    fmt = None
    elements: list[PlyElement] = []
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append(PlyElement(words[1], int(words[2]), ()))
        elif words[0] == "property" and elements and _property_type(words) is not None:
            last = elements[-1]
            elements[-1] = PlyElement(last.name, last.count,
                                      (*last.properties, _property_type(words)))
        else:
            raise PlyError(f"not a readable PLY file (header line {number}: {line[:60]!r})")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise PlyError(f"not a readable PLY file (format {fmt!r})")
    return PlyHeader(fmt, tuple(elements), newline + 1)


def _property_type(words: list[str]) -> tuple[str, ...] | None:
    if len(words) == 3 and words[1] in _SCALAR_BYTES:
        return (words[1],)
    if (len(words) == 5 and words[1] == "list" and words[2] in _SCALAR_BYTES
            and words[3] in _SCALAR_BYTES):
        return ("list", words[2], words[3])
    return None


def payload_size(header: PlyHeader, list_length: int = 3) -> int | None:
    """Bytes after the header of a binary PLY whose lists all have ``list_length`` items
    (triangles: 3), or None for an ASCII file, whose size the header does not fix."""
    if header.format == "ascii":
        return None
    size = 0
    for element in header.elements:
        row = 0
        for prop in element.properties:
            if prop[0] == "list":
                row += _SCALAR_BYTES[prop[1]] + list_length * _SCALAR_BYTES[prop[2]]
            else:
                row += _SCALAR_BYTES[prop[0]]
        size += element.count * row
    return size


def check_ply(path: Path, *, vertices: int | None = None, faces: int | None = None) -> PlyHeader:
    """The header of the PLY file ``path``, checked against its size (binary files, whose
    lists are triangles) and, when given, against the counts of ``vertices`` and ``faces``.

    Raises :class:`PlyError` (one line, without the path) for a file that is not a PLY, is
    cut short or longer than its header says, or declares other counts.
    """
    with open(path, "rb") as handle:
        head = handle.read(MAX_HEADER_BYTES)
    header = parse_header(head)
    for name, want in (("vertex", vertices), ("face", faces)):
        if want is not None and header.count(name) != want:
            raise PlyError(f"it declares {header.count(name)} {name} elements, not {want}")
    payload = payload_size(header)
    if payload is not None:
        actual = os.path.getsize(path) - header.header_bytes
        if actual != payload:
            declared = ", ".join(f"{e.name} {e.count}" for e in header.elements)
            state = "truncated" if actual < payload else "longer than its header says"
            raise PlyError(f"{state}: the header declares {declared} ({payload} bytes), the file "
                           f"holds {max(actual, 0)} bytes of them")
    return header


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Silence the process's stderr (file descriptor 2) within the block.

    For C writers that print every failed write (RPly prints one line per property of every
    vertex it fails to write, thousands on a full disk); their result is checked afterwards.
    """
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to silence
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
