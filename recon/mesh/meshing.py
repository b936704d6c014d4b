"""Oriented point cloud → triangle mesh (screened Poisson or ball pivoting), clean-up, and files.

The two mesher functions are the ``poisson`` and ``ball-pivoting`` mesh backends. Both take an
Open3D point cloud in the world frame of the reconstruction (COLMAP's), with oriented normals
and, usually, colours (COLMAP's stereo fusion writes both), and return a mesh in the same frame
with per-vertex colours. They are pure: geometry in, geometry out; the input is not modified.

Decisions:

* **Missing normals are an error**, not estimated here. Poisson and ball pivoting need
  *consistently oriented* normals; estimating them from the points alone gives a sign that
  flips between patches, and the right orientation (towards the cameras that saw each point)
  needs the cameras, which a mesher does not have. :class:`MeshingError` says so in one line.
* **No blobs beyond the cloud.** Poisson returns a closed surface, and where the cloud is open
  (the soles of the feet, the top of the head seen from no camera, a plane patch) it closes it
  with extrapolated sheets. The guarantee is a *distance trim*: every face with a vertex
  farther than ``max_distance_factor`` × (mean point spacing) from the nearest input point is
  removed, so no face lies much farther than that from the cloud (measured on a noisy
  hemisphere and a plane patch with holes: no mesh sample farther than 3.6 spacings with the
  default 3; without the trim, 27 % and 22 % of the area were farther than 3 spacings, up to
  73 spacings away). Holes in the cloud wider than about twice that distance stay holes.
* **The density trim is off by default** (``density_quantile = 0``). Removing the vertices of
  lowest Poisson density (the usual recipe) removes that fraction of vertices *wherever they
  are*: on a well-sampled, noisy closed sphere a 2 % quantile punched dozens of holes several
  spacings wide (2,100 boundary edges, 1.2 % of all edges; recall at 1 % of the size 0.996
  instead of 1.000; 0.983 on a box), while on open clouds it still left 1-9 % of the area
  farther than 3 spacings, which the distance trim removes anyway. It stays available for
  clouds whose weakly supported regions should go.
* **Small components** are counted in faces: a component with fewer than
  ``min_component_fraction`` × (all faces) is removed. The fraction of faces, not of the
  bounding-box diagonal, because the diagonal is itself set by the floaters it should judge.

Files (:func:`write_mesh`): ``.ply`` is binary with per-vertex colours (8 bits a channel).
``.obj`` has no standard vertex colour; it is written as ``v x y z r g b`` with ``r g b`` in
[0, 1], the de-facto extension that Blender (3.5 and later) and MeshLab read; readers that do
not know it ignore the extra numbers. ``.glb`` is written by a small writer here, because
Open3D 0.20 writes ``.glb`` files that its own reader rejects ("Buffer view ... out of range"):
positions, normals and ``COLOR_0`` as float32, indices as uint32, and a non-metallic material.
glTF defines ``COLOR_0`` as *linear* RGB, so the sRGB colours of photos are converted to linear
on writing (:func:`srgb_to_linear`); viewers then show the colours of the photos. The ``.glb``
keeps the world frame as it is (glTF viewers assume +Y up, so the model may lie on its side).
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d
import pymeshlab
from scipy.spatial import cKDTree

from recon.dense.ply import PlyError, check_ply, quiet_stderr
from recon.errors import UserError
from recon.mesh.normals import vertex_normals
from recon.workspace import partial_path

MIN_POINTS = 100
"""Fewest points a cloud must have to be meshed."""

MESH_SUFFIXES = (".ply", ".obj", ".glb")
"""File formats that :func:`write_mesh` writes."""


class MeshingError(UserError, ValueError):
    """A cloud or mesh that cannot be meshed or written: too few points, no normals, nothing left.

    The message is one line. A :class:`~recon.errors.UserError`, so the CLI prints it and exits
    with code 2, and a ``ValueError`` for callers that treat it as bad input.
    """


# ---------------------------------------------------------------------------------------------
# Configs


@dataclass(frozen=True, kw_only=True)
class PoissonConfig:
    """Screened Poisson reconstruction (Kazhdan and Hoppe 2013) and its trimming."""

    depth: int = field(
        default=9,
        metadata={
            "help": "octree depth: the finest grid has at most 2^depth cells a side (9 ≈ 4 mm "
            "cells on a 2 m person; each +1 is about 4x the time and memory)"
        },
    )
    density_quantile: float = field(
        default=0.0,
        metadata={
            "help": "remove mesh vertices whose Poisson density is below this quantile (0 keeps "
            "all): weakly supported parts, but also holes in well-sampled ones"
        },
    )
    max_distance_factor: float = field(
        default=3.0,
        metadata={
            "help": "remove faces with a vertex farther than this many mean point spacings from "
            "the nearest input point, so no surface grows beyond the cloud (0: no distance trim)"
        },
    )
    scale: float = field(
        default=1.1,
        metadata={"help": "ratio of the reconstruction cube's size to the cloud's bounding cube"},
    )
    linear_fit: bool = field(
        default=False,
        metadata={"help": "place iso-vertices by linear interpolation (sharper, can be noisier)"},
    )
    samples_per_node: float = field(
        default=1.5,
        metadata={
            "help": "minimum points per octree node; larger smooths noisy clouds more (1-5 "
            "for clean clouds, 15-20 for noisy ones)"
        },
    )
    point_weight: float = field(
        default=2.0,
        metadata={"help": "screening weight: how strongly the surface is pulled to the points"},
    )


@dataclass(frozen=True, kw_only=True)
class BallPivotingConfig:
    """Ball pivoting (Bernardini et al. 1999): interpolates the points themselves."""

    radii_factors: tuple[float, ...] = field(
        default=(1.0, 2.0, 4.0),
        metadata={
            "help": "ball radius in mean nearest-neighbour spacings; one pass per radius, "
            "smallest first, larger ones fill gaps (repeatable)",
            "metavar": "FACTOR",
        },
    )


@dataclass(frozen=True, kw_only=True)
class CleanupConfig:
    """Mesh clean-up with MeshLab's filters, and optional decimation."""

    min_component_fraction: float = field(
        default=0.01,
        metadata={
            "help": "remove connected components with fewer than this fraction of all faces "
            "(0 keeps all)"
        },
    )
    target_faces: int | None = field(
        default=None,
        metadata={
            "help": "decimate to about this many faces by quadric edge collapse, keeping "
            "vertex colours (unset: no decimation)"
        },
    )
    preserve_boundary: bool = field(
        default=True,
        metadata={"help": "keep open boundaries in place while decimating"},
    )


# ---------------------------------------------------------------------------------------------
# Meshers


def mean_point_spacing(points: np.ndarray) -> float:
    """Mean distance from each point of ``points`` (N, 3) to its nearest other point.

    Coincident points (distance 0) are left out of the mean, so duplicates do not shrink it.
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 2:
        raise MeshingError(f"the cloud has {len(points)} points; at least 2 are needed")
    distances, _ = cKDTree(points).query(points, k=2, workers=-1)
    nearest = distances[:, 1]
    nearest = nearest[nearest > 0]
    if len(nearest) == 0:
        raise MeshingError("all points of the cloud coincide; there is no surface to mesh")
    return float(nearest.mean())


def _check_cloud(cloud: o3d.geometry.PointCloud, backend: str) -> tuple[np.ndarray, float]:
    """Raise :class:`MeshingError` unless ``cloud`` can be meshed; return its points and spacing.

    Returns the points (N, 3) float64 in the cloud's frame and the mean point spacing.
    """
    points = np.asarray(cloud.points)
    if len(points) < MIN_POINTS:
        raise MeshingError(
            f"{backend}: the cloud has {len(points)} points, at least {MIN_POINTS} are needed "
            "(is the dense reconstruction empty?)"
        )
    if not cloud.has_normals():
        raise MeshingError(
            f"{backend}: the cloud has no normals; meshing needs oriented normals (COLMAP's "
            "stereo fusion writes them; or estimate and orient them towards the cameras)"
        )
    normals = np.asarray(cloud.normals)
    if not (np.isfinite(points).all() and np.isfinite(normals).all()):
        raise MeshingError(f"{backend}: the cloud has non-finite points or normals")
    if np.count_nonzero(np.linalg.norm(normals, axis=1) > 0) < MIN_POINTS:
        raise MeshingError(f"{backend}: fewer than {MIN_POINTS} points have a non-zero normal")
    try:
        spacing = mean_point_spacing(points)
    except MeshingError as error:
        raise MeshingError(f"{backend}: {error}") from None
    return points, spacing


def poisson_mesh(
    cloud: o3d.geometry.PointCloud, config: PoissonConfig = PoissonConfig()
) -> o3d.geometry.TriangleMesh:
    """Screened Poisson surface of an oriented ``cloud``, trimmed to where the cloud is.

    ``cloud`` has N ≥ 100 points with oriented normals and, optionally, colours (world frame).
    The mesh is in the same frame, with vertex colours interpolated from the points' (when the
    cloud has colours) and vertex normals. See the module docstring for the two trims.
    Raises :class:`MeshingError` for a cloud that cannot be meshed or a mesh trimmed to nothing.
    """
    if not 0.0 <= config.density_quantile < 1.0:
        raise MeshingError(
            f"poisson: density_quantile must be in [0, 1), got {config.density_quantile}"
        )
    points, spacing = _check_cloud(cloud, "poisson")
    # PoissonRecon prints its own warnings to stderr, past Open3D's logger ("[WARNING] ...
    # bad average roots"): stray lines under a one-line error (a `make test` run failed the
    # full-disk mesh test on them, session 35). The mesh is checked below.
    with quiet_stderr():
        mesh, densities_vector = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            cloud,
            depth=config.depth,
            scale=config.scale,
            linear_fit=config.linear_fit,
            samples_per_node=config.samples_per_node,
            point_weight=config.point_weight,
            # One thread: Open3D's multi-threaded Poisson differs in the last digits from run
            # to run and can crash under full CPU load (Open3D issues #7229, #6828); one
            # thread was not slower here (4.7 s vs 5.4 s at depth 9 on 2 cores).
            n_threads=1,
        )
    densities = np.asarray(densities_vector)
    vertices = np.asarray(mesh.vertices)
    triangles = np.asarray(mesh.triangles)
    if len(triangles) == 0:
        raise MeshingError("poisson: the reconstruction has no faces (is the cloud degenerate?)")

    keep_vertex = np.ones(len(vertices), dtype=bool)
    if config.density_quantile > 0:
        keep_vertex &= densities >= np.quantile(densities, config.density_quantile)
    keep_face = keep_vertex[triangles].all(axis=1)
    if config.max_distance_factor > 0:
        max_distance = config.max_distance_factor * spacing
        vertex_distance, _ = cKDTree(points).query(
            vertices, workers=-1, distance_upper_bound=max_distance
        )
        # Poisson's faces are an octree cell (about a point spacing) wide, so a face whose
        # vertices are near the cloud is near it all over (measured: within 3.6 spacings).
        keep_face &= (vertex_distance <= max_distance)[triangles].all(axis=1)
    if not keep_face.any():
        raise MeshingError("poisson: trimming left no faces (the cloud may be too sparse)")
    mesh.remove_triangles_by_mask(~keep_face)
    mesh.remove_unreferenced_vertices()
    return mesh


def ball_pivoting_mesh(
    cloud: o3d.geometry.PointCloud, config: BallPivotingConfig = BallPivotingConfig()
) -> o3d.geometry.TriangleMesh:
    """Ball-pivoting mesh of an oriented ``cloud``: its vertices are the input points.

    ``cloud`` has N ≥ 100 points with oriented normals and, optionally, colours (world frame);
    ball radii are ``radii_factors`` × the mean nearest-neighbour spacing. The mesh keeps the
    points' colours and normals; points no ball reached are removed. It has holes where the
    cloud is sparser than the largest ball. Raises :class:`MeshingError` if no face is made.
    """
    if not config.radii_factors or min(config.radii_factors) <= 0:
        raise MeshingError("ball-pivoting: radii_factors must be positive and not empty")
    _, spacing = _check_cloud(cloud, "ball-pivoting")
    radii = o3d.utility.DoubleVector(sorted(f * spacing for f in config.radii_factors))
    mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_ball_pivoting(cloud, radii)
    if len(mesh.triangles) == 0:
        raise MeshingError(
            "ball-pivoting: no faces were made; try larger radii_factors (the cloud may be "
            "too sparse or its normals inconsistent)"
        )
    mesh.remove_unreferenced_vertices()
    return mesh


# ---------------------------------------------------------------------------------------------
# Clean-up


def _to_pymeshlab(mesh: o3d.geometry.TriangleMesh) -> pymeshlab.Mesh:
    arrays: dict[str, np.ndarray] = {
        "vertex_matrix": np.asarray(mesh.vertices, dtype=np.float64),
        "face_matrix": np.asarray(mesh.triangles, dtype=np.int32),
    }
    if mesh.has_vertex_colors():
        rgb = np.clip(np.asarray(mesh.vertex_colors, dtype=np.float64), 0.0, 1.0)
        # MeshLab stores 8 bits a channel and truncates (0.999 → 254): hand it the middle of the
        # nearest level instead, so that colours come back rounded, within half a level.
        rgb = np.minimum((np.rint(rgb * 255.0) + 0.5) / 255.0, 1.0)
        arrays["v_color_matrix"] = np.column_stack([rgb, np.ones(len(rgb))])  # RGBA in [0, 1]
    return pymeshlab.Mesh(**arrays)


def _from_pymeshlab(mesh: pymeshlab.Mesh, *, with_colors: bool) -> o3d.geometry.TriangleMesh:
    mesh.compact()  # filters only flag removed elements; the matrices must not include them
    result = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.ascontiguousarray(mesh.vertex_matrix(), dtype=np.float64)),
        o3d.utility.Vector3iVector(np.ascontiguousarray(mesh.face_matrix(), dtype=np.int32)),
    )
    if with_colors and mesh.has_vertex_color():
        rgb = np.ascontiguousarray(mesh.vertex_color_matrix()[:, :3], dtype=np.float64)
        result.vertex_colors = o3d.utility.Vector3dVector(rgb)
    return result


def clean_mesh(
    mesh: o3d.geometry.TriangleMesh, config: CleanupConfig = CleanupConfig()
) -> o3d.geometry.TriangleMesh:
    """A cleaned copy of ``mesh`` (any frame; the result is in the same frame).

    In order: merge duplicate vertices; remove duplicate and zero-area faces; remove faces on
    non-manifold edges; remove components with fewer than ``min_component_fraction`` of the
    faces; decimate to ``target_faces`` if set; split non-manifold vertices; remove unreferenced
    vertices. Vertex colours are kept (MeshLab stores 8 bits a channel, so they come back
    rounded to 1/255; a vertex that survives an edge collapse keeps its own colour). Vertex
    normals are recomputed from the faces. Raises :class:`MeshingError` if nothing is left.
    """
    if len(mesh.triangles) == 0:
        raise MeshingError("clean-up: the mesh has no faces")
    if config.target_faces is not None and config.target_faces < 1:
        raise MeshingError(f"clean-up: target_faces must be positive, got {config.target_faces}")
    meshset = pymeshlab.MeshSet()
    meshset.add_mesh(_to_pymeshlab(mesh))
    meshset.meshing_remove_duplicate_vertices()
    meshset.meshing_remove_duplicate_faces()
    meshset.meshing_remove_null_faces()
    meshset.meshing_repair_non_manifold_edges(method="Remove Faces")
    if config.min_component_fraction > 0:
        face_count = meshset.current_mesh().face_number()
        min_faces = math.ceil(config.min_component_fraction * face_count)
        meshset.meshing_remove_connected_component_by_face_number(
            mincomponentsize=min_faces, removeunref=True
        )
    current_faces = meshset.current_mesh().face_number()
    if config.target_faces is not None and config.target_faces < current_faces:
        meshset.meshing_decimation_quadric_edge_collapse(
            targetfacenum=config.target_faces,
            preserveboundary=config.preserve_boundary,
            preservenormal=True,  # no face flips: the surface stays consistently oriented
            optimalplacement=True,
            autoclean=True,
        )
        # Edge collapses can pinch the surface into new non-manifold edges.
        meshset.meshing_repair_non_manifold_edges(method="Remove Faces")
    # Splitting a non-manifold vertex makes coincident copies, so this comes after the merge.
    meshset.meshing_repair_non_manifold_vertices(vertdispratio=0.0)
    meshset.meshing_remove_unreferenced_vertices()
    result = _from_pymeshlab(meshset.current_mesh(), with_colors=mesh.has_vertex_colors())
    if len(result.triangles) == 0:
        raise MeshingError("clean-up: no faces are left")
    result.compute_vertex_normals()
    return result


# ---------------------------------------------------------------------------------------------
# Files


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] (any shape) → linear RGB (IEC 61966-2-1)."""
    srgb = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear RGB values in [0, 1] (any shape) → sRGB encoding; inverse of srgb_to_linear."""
    linear = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(linear <= 0.0031308, linear * 12.92, 1.055 * linear ** (1 / 2.4) - 0.055)


def _unit_vertex_normals(mesh: o3d.geometry.TriangleMesh) -> np.ndarray:
    """(V, 3) float32 unit vertex normals: the mesh's own, else area-weighted face normals."""
    if mesh.has_vertex_normals():
        normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    else:
        normals = vertex_normals(np.asarray(mesh.vertices), np.asarray(mesh.triangles))
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    # glTF requires unit normals; an isolated vertex has none, so give it any unit vector.
    ok = (length[:, 0] > 1e-12) & np.isfinite(length[:, 0])
    unit = np.tile(np.array([0.0, 0.0, 1.0]), (len(normals), 1))
    unit[ok] = normals[ok] / length[ok]
    return unit.astype(np.float32)


def _padded(data: bytes, pad: bytes) -> bytes:
    return data + pad * (-len(data) % 4)


def _write_glb(path: Path, mesh: o3d.geometry.TriangleMesh) -> None:
    """Write ``mesh`` as binary glTF 2.0: one primitive, positions, normals, COLOR_0, indices."""
    positions = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    normals = _unit_vertex_normals(mesh)
    indices = np.ascontiguousarray(mesh.triangles, dtype=np.uint32)
    attributes = [("POSITION", positions), ("NORMAL", normals)]
    if mesh.has_vertex_colors():
        linear = srgb_to_linear(np.asarray(mesh.vertex_colors)).astype(np.float32)
        attributes.append(("COLOR_0", linear))

    blobs: list[bytes] = []
    buffer_views: list[dict[str, int]] = []
    accessors: list[dict[str, object]] = []
    offset = 0
    for name, array in attributes:
        blob = np.ascontiguousarray(array).tobytes()
        buffer_views.append(
            {"buffer": 0, "byteOffset": offset, "byteLength": len(blob), "target": 34962}
        )
        accessor: dict[str, object] = {
            "bufferView": len(buffer_views) - 1,
            "componentType": 5126,  # FLOAT
            "count": len(array),
            "type": "VEC3",
        }
        if name == "POSITION":  # the spec requires the bounds of positions
            accessor["min"] = array.min(axis=0).astype(float).tolist()
            accessor["max"] = array.max(axis=0).astype(float).tolist()
        accessors.append(accessor)
        blobs.append(blob)
        offset += len(blob)  # float32 triples keep every view 4-byte aligned
    index_blob = indices.tobytes()
    buffer_views.append(
        {"buffer": 0, "byteOffset": offset, "byteLength": len(index_blob), "target": 34963}
    )
    accessors.append(
        {
            "bufferView": len(buffer_views) - 1,
            "componentType": 5125,  # UNSIGNED_INT
            "count": int(indices.size),
            "type": "SCALAR",
        }
    )
    blobs.append(index_blob)
    binary = _padded(b"".join(blobs), b"\x00")

    document = {
        "asset": {"version": "2.0", "generator": "mocap-recon recon.mesh.meshing"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": path.stem.removesuffix(".partial")}],
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {name: i for i, (name, _) in enumerate(attributes)},
                        "indices": len(accessors) - 1,
                        "material": 0,
                        "mode": 4,  # TRIANGLES
                    }
                ]
            }
        ],
        # glTF's default material is fully metallic, which renders vertex colours almost black.
        "materials": [
            {
                "pbrMetallicRoughness": {
                    "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
                "doubleSided": True,
            }
        ],
        "accessors": accessors,
        "bufferViews": buffer_views,
        "buffers": [{"byteLength": len(binary)}],
    }
    json_chunk = _padded(json.dumps(document, separators=(",", ":")).encode(), b" ")
    total = 12 + 8 + len(json_chunk) + 8 + len(binary)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(json_chunk), b"JSON"))
        f.write(json_chunk)
        f.write(struct.pack("<I4s", len(binary), b"BIN\x00"))
        f.write(binary)
    if os.path.getsize(path) != total:  # written in full (a full disk raises, or cuts it short)
        raise OSError(errno.EIO, f"{path} is incomplete")


def _write_obj(path: Path, mesh: o3d.geometry.TriangleMesh) -> None:
    """Write ``mesh`` as Wavefront OBJ: ``v x y z r g b`` (colours when present) and ``f``."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.triangles, dtype=np.int64) + 1  # OBJ indices start at 1
    with open(path, "w", encoding="ascii") as f:
        f.write(f"# mocap-recon mesh: {len(vertices)} vertices, {len(faces)} triangles\n")
        if mesh.has_vertex_colors():
            f.write("# vertex colours as 'v x y z r g b', sRGB in [0, 1] (Blender, MeshLab)\n")
            colors = np.clip(np.asarray(mesh.vertex_colors, dtype=np.float64), 0.0, 1.0)
            rows = np.column_stack([vertices, colors])
            np.savetxt(f, rows, fmt="v %.9g %.9g %.9g %.6g %.6g %.6g")
        else:
            np.savetxt(f, vertices, fmt="v %.9g %.9g %.9g")
        np.savetxt(f, faces, fmt="f %d %d %d")


def _write_ply(path: Path, mesh: o3d.geometry.TriangleMesh) -> None:
    # Open3D's writer (RPly) reports success when its writes fail, printing a line for each
    # value (issue 23): silence it and check the file's header and size instead.
    with quiet_stderr():
        ok = o3d.io.write_triangle_mesh(
            str(path),
            mesh,
            write_ascii=False,
            write_vertex_normals=mesh.has_vertex_normals(),
            write_vertex_colors=mesh.has_vertex_colors(),
            write_triangle_uvs=False,
        )
    if not ok:
        raise OSError(errno.EIO, f"Open3D could not write {path}")
    try:
        check_ply(path, vertices=len(mesh.vertices), faces=len(mesh.triangles))
    except PlyError as exc:
        free = shutil.disk_usage(path.parent).free
        raise OSError(errno.ENOSPC if free < 1 << 20 else errno.EIO,
                      f"{path} is incomplete ({exc})") from None


_WRITERS: dict[str, Callable[[Path, o3d.geometry.TriangleMesh], None]] = {
    ".ply": _write_ply,
    ".obj": _write_obj,
    ".glb": _write_glb,
}


def write_mesh(
    mesh: o3d.geometry.TriangleMesh,
    path_ply: Path,
    *,
    also: Sequence[str] = (".obj", ".glb"),
    before_replace: Callable[[], None] | None = None,
) -> list[Path]:
    """Write ``mesh`` to ``path_ply`` and to siblings with the suffixes in ``also``; atomically.

    Every file is first written as ``<stem>.partial<suffix>`` beside its target, and only when
    all are complete are they renamed into place, so a failure leaves no new file and no
    ``.partial`` file, and existing targets untouched. Returns the written paths, ``.ply``
    first. ``before_replace`` runs when every file is written and checked, before any target
    is replaced; when it raises, nothing is replaced either. Formats: see the module docstring.
    Raises :class:`MeshingError` for a mesh with no faces, ``ValueError`` for an unknown suffix,
    ``OSError`` when a file cannot be written (or is found incomplete after writing).
    """
    path_ply = Path(path_ply)
    if path_ply.suffix.lower() != ".ply":
        raise ValueError(f"write_mesh: {path_ply} must end in .ply")
    suffixes = [".ply"] + [s.lower() if s.startswith(".") else f".{s.lower()}" for s in also]
    unknown = sorted(set(suffixes) - set(_WRITERS))
    if unknown:
        raise ValueError(f"write_mesh: cannot write {', '.join(unknown)}; use {MESH_SUFFIXES}")
    if len(mesh.triangles) == 0:
        raise MeshingError(f"write_mesh: the mesh for {path_ply} has no faces")
    targets = [path_ply.with_suffix(s) for s in dict.fromkeys(suffixes)]
    partials = [partial_path(t) for t in targets]
    path_ply.parent.mkdir(parents=True, exist_ok=True)
    try:
        for target, partial in zip(targets, partials, strict=True):
            _WRITERS[target.suffix](partial, mesh)
        if before_replace is not None:
            before_replace()
        for target, partial in zip(targets, partials, strict=True):
            os.replace(partial, target)
    except BaseException:
        for partial in partials:
            partial.unlink(missing_ok=True)
        raise
    return targets
