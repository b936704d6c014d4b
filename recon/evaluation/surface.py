"""Surface quality against a known truth, and a picture of a mesh made without OpenGL.

Scores follow Knapitsch et al. 2017 (Tanks and Temples): with a distance threshold tau,
*precision* is the fraction of the reconstruction within tau of the truth, *recall* the fraction
of the truth within tau of the reconstruction, and F their harmonic mean. Meshes are sampled
uniformly by area; where the *target* of a distance is a mesh, the distance is the exact
point-to-triangle distance (Open3D's RaycastingScene) rather than the distance to the nearest
of its samples, so the scores do not depend on how densely the target was sampled. Where the
target is a point set, the nearest-point distance (KD-tree) is used, as in Tanks and Temples.

Everything is pure except :func:`render_mesh_png`, which writes one file atomically.
Distance queries run in float32 (Embree); the geometry is shifted to its bounding-box centre
first, so the precision does not depend on where in the world the model is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from recon.workspace import atomic_output

Surface = o3d.geometry.TriangleMesh | np.ndarray
"""A triangle mesh, or an (N, 3) array of points, in the frame of the comparison."""


@dataclass(frozen=True)
class SurfaceScores:
    """A reconstruction compared with the truth; distances in the units of the inputs."""

    accuracy: float  # mean distance from reconstruction samples to the truth
    accuracy_median: float
    completeness: float  # mean distance from truth samples to the reconstruction
    completeness_median: float
    chamfer: float  # (accuracy + completeness) / 2, DTU's "overall"
    precision: float  # fraction of reconstruction samples within `threshold` of the truth
    recall: float  # fraction of truth samples within `threshold` of the reconstruction
    f_score: float  # 2 P R / (P + R), 0 when both are 0
    threshold: float  # tau


def _triangles_in(mesh: o3d.geometry.TriangleMesh) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 triangles; raises ValueError without faces."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    if len(triangles) == 0:
        raise ValueError("the mesh has no triangles")
    return vertices, triangles


def sample_surface(mesh: o3d.geometry.TriangleMesh, n: int, seed: int = 0) -> np.ndarray:
    """``n`` points (n, 3) float64 uniformly distributed by area on ``mesh``, in its frame.

    Deterministic for a given ``seed`` (NumPy's generator, not Open3D's global one).
    """
    vertices, triangles = _triangles_in(mesh)
    corners = vertices[triangles]  # (F, 3 corners, 3)
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    total = areas.sum()
    if not total > 0:
        raise ValueError("the mesh has zero area")
    rng = np.random.default_rng(seed)
    cumulative = np.cumsum(areas)
    face = np.searchsorted(cumulative, rng.random(n) * total, side="right")
    face = np.minimum(face, len(areas) - 1)  # guards against rounding at the very end
    # Square root of one uniform variable makes the barycentric coordinates uniform by area.
    root = np.sqrt(rng.random(n))
    second = rng.random(n)
    w0, w1, w2 = 1.0 - root, root * (1.0 - second), root * second
    c = corners[face]
    return w0[:, None] * c[:, 0] + w1[:, None] * c[:, 1] + w2[:, None] * c[:, 2]


def _scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)),
    )
    return scene


def points_to_mesh_distance(points: np.ndarray, mesh: o3d.geometry.TriangleMesh) -> np.ndarray:
    """Unsigned distance (N,) float64 from each of ``points`` (N, 3) to the surface of ``mesh``.

    Both in the same frame. Exact point-to-triangle distances, evaluated in float32 about the
    mesh's bounding-box centre (relative error about 1e-7 of the mesh's size).
    """
    vertices, triangles = _triangles_in(mesh)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return np.zeros(0)
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    scene = _scene(vertices - centre, triangles)
    query = o3d.core.Tensor(np.ascontiguousarray(points - centre, dtype=np.float32))
    return scene.compute_distance(query).numpy().astype(np.float64)


def _distances_to(points: np.ndarray, target: Surface) -> np.ndarray:
    """(N,) distances from ``points`` to a mesh (exact) or to the nearest point of a point set."""
    if isinstance(target, o3d.geometry.TriangleMesh):
        return points_to_mesh_distance(points, target)
    target_points = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    if len(target_points) == 0:
        return np.full(len(points), np.inf)
    distances, _ = cKDTree(target_points).query(points, workers=-1)
    return np.asarray(distances, dtype=np.float64)


def _samples_of(surface: Surface, n: int, seed: int) -> np.ndarray:
    if isinstance(surface, o3d.geometry.TriangleMesh):
        if len(surface.triangles) == 0:
            return np.zeros((0, 3))
        return sample_surface(surface, n, seed)
    return np.asarray(surface, dtype=np.float64).reshape(-1, 3)


def _is_empty(surface: Surface) -> bool:
    if isinstance(surface, o3d.geometry.TriangleMesh):
        return len(surface.triangles) == 0
    return np.asarray(surface).size == 0


def surface_scores(
    reconstruction: Surface,
    truth: Surface,
    *,
    threshold: float,
    samples: int = 200_000,
    seed: int = 0,
) -> SurfaceScores:
    """Accuracy, completeness, chamfer, precision, recall and F-score at ``threshold``.

    ``reconstruction`` and ``truth`` are meshes (sampled with ``samples`` points each) or (N, 3)
    point arrays (used as given), in the same frame and units. An empty reconstruction scores
    infinite distances and zero precision, recall and F. Raises ValueError for an empty truth
    or a threshold that is not positive.
    """
    if not threshold > 0:
        raise ValueError(f"threshold must be positive, got {threshold}")
    if _is_empty(truth):
        raise ValueError("the truth is empty")
    truth_samples = _samples_of(truth, samples, seed + 1)
    if _is_empty(reconstruction):
        return SurfaceScores(
            accuracy=math.inf,
            accuracy_median=math.inf,
            completeness=math.inf,
            completeness_median=math.inf,
            chamfer=math.inf,
            precision=0.0,
            recall=0.0,
            f_score=0.0,
            threshold=float(threshold),
        )
    reconstruction_samples = _samples_of(reconstruction, samples, seed)
    to_truth = _distances_to(reconstruction_samples, truth)
    to_reconstruction = _distances_to(truth_samples, reconstruction)
    precision = float(np.mean(to_truth < threshold))
    recall = float(np.mean(to_reconstruction < threshold))
    f_score = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    accuracy = float(np.mean(to_truth))
    completeness = float(np.mean(to_reconstruction))
    return SurfaceScores(
        accuracy=accuracy,
        accuracy_median=float(np.median(to_truth)),
        completeness=completeness,
        completeness_median=float(np.median(to_reconstruction)),
        chamfer=0.5 * (accuracy + completeness),
        precision=precision,
        recall=recall,
        f_score=float(f_score),
        threshold=float(threshold),
    )


# ---------------------------------------------------------------------------------------------
# Rendering without OpenGL


@dataclass(frozen=True, kw_only=True)
class RenderView:
    """Where the camera of :func:`render_mesh` stands, relative to the mesh's bounding box."""

    azimuth_deg: float = field(
        default=30.0,
        metadata={
            "help": "camera direction around the up axis, degrees: 0 looks from the world axis "
            "least parallel to up (+x for up +z), 90 from up × that axis (+y)"
        },
    )
    elevation_deg: float = field(
        default=20.0,
        metadata={"help": "camera height above the horizontal plane, degrees (-89 to 89)"},
    )
    up: tuple[float, float, float] = field(
        default=(0.0, 0.0, 1.0),
        metadata={"help": "the world's up direction, shown upwards in the picture"},
    )
    fov_deg: float = field(
        default=40.0, metadata={"help": "horizontal field of view of the camera, degrees"}
    )
    margin: float = field(
        default=1.1,
        metadata={"help": "bounding sphere radius × margin fills the narrower image side"},
    )


@dataclass(frozen=True)
class Rendering:
    """A picture of a mesh and the camera that took it (the conventions of
    recon.cameras)."""

    image_rgb: np.ndarray  # (H, W, 3) uint8
    hit: np.ndarray  # (H, W) bool, pixels whose ray hit the mesh
    K: np.ndarray  # (3, 3) float64, pixel (i, j) has its centre at (i + 0.5, j + 0.5)
    cam_from_world: np.ndarray  # (3, 4) float64 [R | t], RDF camera axes


BACKGROUND_RGB = (40, 44, 52)
"""Colour of pixels that see no surface: dark, so that light and white surfaces stand out."""

_AMBIENT = 0.25  # share of light that reaches surfaces facing away from the camera
_UNCOLOURED = 0.8  # grey of meshes without vertex colours


def _basis_around(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors that span the plane perpendicular to unit ``up``."""
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]  # the axis least parallel to up
    first = helper - up * (helper @ up)
    first /= np.linalg.norm(first)
    return first, np.cross(up, first)


def framing_camera(
    mesh: o3d.geometry.TriangleMesh, *, width: int, height: int, view: RenderView = RenderView()
) -> tuple[np.ndarray, np.ndarray]:
    """A pinhole camera that looks at the centre of ``mesh``'s bounding box and sees all of it.

    Returns ``K`` (3, 3) and ``cam_from_world`` (3, 4) with RDF camera axes (x right, y down,
    z forward), the world being the mesh's frame.
    """
    vertices, _ = _triangles_in(mesh)
    up = np.asarray(view.up, dtype=np.float64)
    if not np.linalg.norm(up) > 0:
        raise ValueError("view.up must not be zero")
    up = up / np.linalg.norm(up)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    centre = 0.5 * (low + high)
    radius = max(0.5 * float(np.linalg.norm(high - low)), 1e-9)
    focal = 0.5 * width / math.tan(math.radians(view.fov_deg) / 2)
    half_angle = min(math.atan(0.5 * width / focal), math.atan(0.5 * height / focal))
    distance = view.margin * radius / math.sin(half_angle)

    first, second = _basis_around(up)
    azimuth = math.radians(view.azimuth_deg)
    elevation = math.radians(float(np.clip(view.elevation_deg, -89.0, 89.0)))
    towards_eye = (
        math.cos(elevation) * (math.cos(azimuth) * first + math.sin(azimuth) * second)
        + math.sin(elevation) * up
    )
    eye = centre + distance * towards_eye
    forward = -towards_eye
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])  # rows: camera axes in the world
    cam_from_world = np.column_stack([rotation, -rotation @ eye])
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    return K, cam_from_world


def render_mesh(
    mesh: o3d.geometry.TriangleMesh,
    *,
    width: int = 800,
    height: int = 600,
    view: RenderView = RenderView(),
    camera: tuple[np.ndarray, np.ndarray] | None = None,
) -> Rendering:
    """Ray-cast picture of ``mesh`` from :func:`framing_camera`, on the CPU, without OpenGL.

    ``camera`` = (K (3, 3) for ``width`` x ``height``, cam_from_world (3, 4)) renders from a
    given camera instead, for example one of the photos' (the picture then matches it).

    Each pixel's colour is the vertex colours (grey without them) interpolated at the hit point,
    times ``ambient + (1 - ambient) |cos|`` of the angle between the face normal and the ray: a
    Lambert term for a light at the camera, which lights both sides of a face.
    """
    vertices, triangles = _triangles_in(mesh)
    if camera is None:
        K, cam_from_world = framing_camera(mesh, width=width, height=height, view=view)
    else:
        K, cam_from_world = (np.asarray(m, dtype=np.float64) for m in camera)
    rotation, translation = cam_from_world[:, :3], cam_from_world[:, 3]
    eye = -rotation.T @ translation
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))  # float32 about here

    cols, rows = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    pixels = np.stack([cols, rows, np.ones_like(cols)], axis=-1)  # (H, W, 3) homogeneous
    directions = pixels @ np.linalg.inv(K).T @ rotation  # world directions, R.T K^-1 x
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    rays = np.concatenate([np.broadcast_to(eye - centre, directions.shape), directions], axis=-1)
    hits = _scene(vertices - centre, triangles).cast_rays(
        o3d.core.Tensor(np.ascontiguousarray(rays, dtype=np.float32))
    )
    hit = np.isfinite(hits["t_hit"].numpy())
    face = hits["primitive_ids"].numpy()[hit].astype(np.int64)
    uv = hits["primitive_uvs"].numpy()[hit].astype(np.float64)

    corners = vertices[triangles[face]]  # (K, 3 corners, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    lambert = np.abs(np.sum(normals * directions[hit], axis=1))
    shade = _AMBIENT + (1.0 - _AMBIENT) * lambert
    if mesh.has_vertex_colors():
        # Embree's barycentrics: the hit is (1 - u - v) p0 + u p1 + v p2.
        weights = np.column_stack([1.0 - uv.sum(axis=1), uv[:, 0], uv[:, 1]])
        vertex_colors = np.clip(np.asarray(mesh.vertex_colors), 0.0, 1.0)
        color = np.einsum("kc,kcd->kd", weights, vertex_colors[triangles[face]])
    else:
        color = np.full((len(face), 3), _UNCOLOURED)
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = BACKGROUND_RGB
    image[hit] = np.clip(np.rint(255.0 * color * shade[:, None]), 0, 255).astype(np.uint8)
    return Rendering(image_rgb=image, hit=hit, K=K, cam_from_world=cam_from_world)


def render_mesh_png(
    mesh: o3d.geometry.TriangleMesh,
    path: Path,
    *,
    width: int = 800,
    height: int = 600,
    view: RenderView = RenderView(),
    camera: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write :func:`render_mesh`'s picture of ``mesh`` to ``path`` (.png), atomically."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"render_mesh_png: {path} must end in .png")
    rendering = render_mesh(mesh, width=width, height=height, view=view, camera=camera)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as partial:
        if not cv2.imwrite(str(partial), cv2.cvtColor(rendering.image_rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"OpenCV could not write {partial}")
    return path
