"""A synthetic textured room with known cameras, for the SfM demo and for tests.

The scene is a closed room (floor, four walls, ceiling) with a few boxes standing in its middle.
Every planar face carries its own procedurally generated, non-repetitive texture (smooth
multi-octave colour noise plus thousands of random blobs, bars and strokes at several scales) so
that SIFT finds many distinctive features. Cameras stand on a rough arc around the boxes at
varying heights, each aimed at a different jittered point with a small roll, so that their
optical axes are not coplanar (coplanar axes make two-view focal self-calibration degenerate).

Rendering is exact ray casting of textured quads, done per quad with homographies: inverse
depth and the quad's two texture coordinates divided by depth are affine in pixel coordinates,
so coverage, clipping behind the camera and the z-buffer reduce to sign tests of affine
functions, and the texture is resampled with ``cv2.warpPerspective``. Images are rendered at
``supersample`` times the resolution and reduced with ``cv2.INTER_AREA`` (anti-aliasing);
depth is rendered directly at the final resolution, exact at each pixel centre.

Conventions (the same as COLMAP and OpenCV; see also :mod:`recon.cameras`):

* World: metres, z up, floor at z = 0, room centred on the z axis.
* Camera axes RDF: x right, y down, z forward. ``cam_from_world`` is 3x4 ``[R | t]`` with
  ``x_cam = R @ x_world + t``.
* ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with ``cx = width / 2``, ``cy = height / 2``:
  pixel (i, j) covers [i, i + 1) x [j, j + 1) and has its centre at (i + 0.5, j + 0.5).
* ``depth`` is the z coordinate in the camera frame (along the optical axis, not the ray
  length) of the surface seen through each pixel centre.

:func:`render_scene` is pure; :func:`write_scene` writes the PNGs and the ground-truth JSON.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from recon.cameras import Camera, look_at, write_cameras_json
from recon.workspace import output_mode

# Room extent in metres: x in [-3.5, 3.5], y in [-3, 3], z in [0, 2.8].
ROOM_MIN = np.array([-3.5, -3.0, 0.0])
ROOM_MAX = np.array([3.5, 3.0, 2.8])

# Boxes standing on the floor: (centre x, centre y, size x, size y, height, yaw in degrees).
# Different sizes and yaws give occlusions and many non-parallel planes; footprints are apart.
BOXES: tuple[tuple[float, float, float, float, float, float], ...] = (
    (0.0, 0.3, 0.8, 0.6, 0.9, 15.0),
    (-0.9, -0.2, 0.5, 0.5, 0.5, -20.0),
    (0.9, 0.1, 0.6, 0.4, 1.3, 35.0),
    (0.3, -0.7, 0.45, 0.35, 0.3, 60.0),
    (-0.7, 1.1, 0.7, 0.5, 0.65, -40.0),
)

# Cameras: an arc of the ring around the room centre, aimed near the boxes.
_RING_RADIUS_M = (1.9, 2.4)
_CAMERA_HEIGHT_M = (1.2, 1.9)
_MAX_ARC_DEG = 150.0
_MAX_SPACING_DEG = 20.0  # consecutive views must overlap strongly for SIFT matching
_LOOK_AT_M = np.array([0.0, 0.1, 0.45])
# Each camera aims at its own point: up to this far sideways and up or down from _LOOK_AT_M, so
# that no two optical axes meet and they do not all lie in one plane.
_LOOK_AT_JITTER_M = 0.4
_LOOK_AT_JITTER_Z_M = 0.25
_MAX_ROLL_DEG = 8.0

# Texture coordinates may overshoot a quad's edge by this fraction so that rounding never leaves
# a pixel centre on a shared edge uncovered; the overshoot is hidden by the z-buffer or is
# a sub-millimetre sliver.
_EDGE_TOLERANCE = 1e-5


@dataclass(frozen=True, kw_only=True)
class SyntheticSceneConfig:
    """What to render; every field has a default good for the SfM demo."""

    # Number of photos, on an arc of at most 150 degrees around the boxes.
    num_views: int = 12
    # Image size in pixels.
    width: int = 640
    height: int = 480
    # Focal length in pixels (square pixels, zero skew, principal point at the centre).
    focal_px: float = 600.0
    # Seeds the textures and the camera placement; equal seeds give identical images.
    seed: int = 0
    # Render at this many times the resolution and average down (anti-aliasing).
    supersample: int = 2

    def __post_init__(self) -> None:
        if not 2 <= self.num_views <= 50:
            raise ValueError(f"num_views must be between 2 and 50, got {self.num_views}")
        for name in ("width", "height"):
            size = getattr(self, name)
            if not 16 <= size <= 8192:
                raise ValueError(f"{name} must be between 16 and 8192 pixels, got {size}")
        if not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"focal_px must be positive and finite, got {self.focal_px}")
        if self.seed < 0:
            raise ValueError(f"seed must be non-negative, got {self.seed}")
        if not 1 <= self.supersample <= 4:
            raise ValueError(f"supersample must be between 1 and 4, got {self.supersample}")

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsics with the principal point at the image centre."""
        return np.array(
            [
                [self.focal_px, 0.0, self.width / 2],
                [0.0, self.focal_px, self.height / 2],
                [0.0, 0.0, 1.0],
            ]
        )


@dataclass(frozen=True)
class SyntheticView:
    name: str  # image file name, e.g. "view_000.png" (the COLMAP image name)
    cam_from_world: np.ndarray  # (3, 4) [R | t], x_cam = R x_world + t
    image_rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 camera z in metres at pixel centres, inf where empty


@dataclass(frozen=True)
class SyntheticScene:
    config: SyntheticSceneConfig
    K: np.ndarray  # (3, 3) shared by all views
    views: list[SyntheticView]

    def truth(self) -> list[Camera]:
        """Ground-truth cameras, named by their images, in view order."""
        return [
            Camera(v.name, self.config.width, self.config.height, self.K.copy(),
                   v.cam_from_world.copy())
            for v in self.views
        ]


@dataclass(frozen=True)
class SceneQuad:
    """A textured rectangle: points ``origin + u * edge_u + v * edge_v`` for u, v in [0, 1]."""

    name: str  # e.g. "floor", "wall_+x", "box2_top"
    origin: np.ndarray  # (3,) corner, world metres
    edge_u: np.ndarray  # (3,) first side, world metres
    edge_v: np.ndarray  # (3,) second side, perpendicular to edge_u
    texels_per_m: float  # texture resolution
    base_rgb: tuple[float, float, float]  # mean colour of the texture, 0..255
    shade: float  # brightness factor baked into the texture (cheap fixed lighting)

    @property
    def normal(self) -> np.ndarray:
        """(3,) unit normal ``edge_u x edge_v``, pointing to the side the quad is seen from."""
        n = np.cross(self.edge_u, self.edge_v)
        return n / np.linalg.norm(n)

    @property
    def corners_in_world(self) -> np.ndarray:
        """(4, 3) corners in order origin, +u, +u+v, +v."""
        o, u, v = self.origin, self.edge_u, self.edge_v
        return np.array([o, o + u, o + u + v, o + v])

    def point_in_world(self, u: float, v: float) -> np.ndarray:
        """(3,) the point at texture coordinates (u, v) in [0, 1]^2."""
        return self.origin + u * self.edge_u + v * self.edge_v


def _oriented_quad(
    name: str,
    origin: np.ndarray | tuple[float, float, float],
    edge_a: np.ndarray,
    edge_b: np.ndarray,
    facing: np.ndarray,
    texels_per_m: float,
    base_rgb: tuple[float, float, float],
    shade: float,
) -> SceneQuad:
    """Quad whose normal points along ``facing`` (swaps the edges if needed)."""
    if np.dot(np.cross(edge_a, edge_b), facing) < 0:
        edge_a, edge_b = edge_b, edge_a
    return SceneQuad(
        name=name,
        origin=np.asarray(origin, dtype=np.float64),
        edge_u=np.asarray(edge_a, dtype=np.float64),
        edge_v=np.asarray(edge_b, dtype=np.float64),
        texels_per_m=texels_per_m,
        base_rgb=base_rgb,
        shade=shade,
    )


_BOX_COLOURS: tuple[tuple[float, float, float], ...] = (
    (70.0, 110.0, 190.0),
    (190.0, 80.0, 70.0),
    (80.0, 160.0, 90.0),
    (210.0, 180.0, 60.0),
    (150.0, 90.0, 170.0),
)


def scene_quads() -> list[SceneQuad]:
    """Every face of the scene (fixed geometry; the seed only changes textures and cameras).

    Room faces are seen from inside, box faces from outside; box bottoms are omitted.
    """
    lo, hi = ROOM_MIN, ROOM_MAX
    sx, sy, sz = hi - lo
    ex, ey, ez = np.eye(3)
    # (name, corner, edge, edge, facing, texels per metre, colour, shade). The floor is seen
    # closest and the ceiling hardly at all, hence their texture resolutions.
    room = (
        ("floor", lo, sx * ex, sy * ey, ez, 320.0, (150, 115, 85), 0.95),
        ("ceiling", (lo[0], lo[1], hi[2]), sx * ex, sy * ey, -ez, 100.0, (215, 215, 220), 1.0),
        ("wall_-x", lo, sy * ey, sz * ez, ex, 220.0, (190, 185, 160), 0.8),
        ("wall_+x", (hi[0], lo[1], 0.0), sy * ey, sz * ez, -ex, 220.0, (170, 190, 185), 0.85),
        ("wall_-y", lo, sx * ex, sz * ez, ey, 220.0, (185, 170, 190), 0.9),
        ("wall_+y", (lo[0], hi[1], 0.0), sx * ex, sz * ez, -ey, 220.0, (200, 190, 170), 0.75),
    )
    quads = [_oriented_quad(*spec) for spec in room]
    for index, (cx, cy, size_x, size_y, size_z, yaw_deg) in enumerate(BOXES):
        yaw = math.radians(yaw_deg)
        ax = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # box's local x axis
        ay = np.array([-math.sin(yaw), math.cos(yaw), 0.0])  # box's local y axis
        base = np.array([cx, cy, 0.0])  # centre of the footprint
        colour = _BOX_COLOURS[index % len(_BOX_COLOURS)]
        corner = base - ax * size_x / 2 - ay * size_y / 2
        faces = (
            ("top", corner + size_z * ez, size_x * ax, size_y * ay, ez, 1.0),
            ("+x", corner + size_x * ax, size_y * ay, size_z * ez, ax, 0.8),
            ("-x", corner, size_y * ay, size_z * ez, -ax, 0.6),
            ("+y", corner + size_y * ay, size_x * ax, size_z * ez, ay, 0.7),
            ("-y", corner, size_x * ax, size_z * ez, -ay, 0.9),
        )
        for face, origin, edge_a, edge_b, facing, shade in faces:
            quads.append(
                _oriented_quad(
                    f"box{index}_{face}", origin, edge_a, edge_b, facing, 450.0, colour, shade
                )
            )
    return quads


# ---------------------------------------------------------------------------------------------
# Textures


def _add_smooth_noise(
    rng: np.random.Generator, image: np.ndarray, cells: tuple[int, int], mixing: np.ndarray
) -> None:
    """Add to (h, w, 3) float32 ``image`` smooth noise with ``cells`` (x, y) random values across.

    A random grid is mixed between channels (``grid @ mixing``; cheap at grid size) and upsampled
    bicubically; the grid extends one cell beyond each border, where the interpolation would
    otherwise flatten out.
    """
    h, w = image.shape[:2]
    cx, cy = cells
    grid = rng.standard_normal((cy + 2, cx + 2, 3)).astype(np.float32) @ mixing
    big_w = max(w + 2, round(w * (cx + 2) / cx))
    big_h = max(h + 2, round(h * (cy + 2) / cy))
    big = cv2.resize(grid, (big_w, big_h), interpolation=cv2.INTER_CUBIC)
    oy = (big_h - h) // 2
    ox = (big_w - w) // 2
    image += big[oy : oy + h, ox : ox + w]


def make_texture(
    rng: np.random.Generator, width_m: float, height_m: float, quad: SceneQuad
) -> np.ndarray:
    """(Th, Tw, 3) uint8 RGB texture for a face of ``width_m`` x ``height_m`` metres.

    Smooth colour noise at four scales (1.2 m down to 5 cm) under random filled discs,
    ellipses, rotated rectangles, rings and strokes whose size is log-uniform between 6 mm and
    9 cm. Nothing is periodic, so every patch is distinctive for a feature matcher.
    """
    density = quad.texels_per_m
    tw = max(16, round(width_m * density))
    th = max(16, round(height_m * density))
    colour = np.array(quad.base_rgb, dtype=np.float32)
    image = np.empty((th, tw, 3), dtype=np.float32)
    image[:] = colour
    # Mostly brightness variation (what SIFT sees) with a little colour variation.
    # Channel c gets n_0 + 0.35 n_c for independent unit noises n_0..n_2.
    brightness_and_colour = 0.35 * np.eye(3, dtype=np.float32)
    brightness_and_colour[0, :] += 1.0
    for cell_m, amplitude in ((1.2, 30.0), (0.4, 20.0), (0.13, 14.0), (0.045, 8.0)):
        cells = (max(1, math.ceil(width_m / cell_m)), max(1, math.ceil(height_m / cell_m)))
        _add_smooth_noise(rng, image, cells, amplitude * brightness_and_colour)
    np.clip(image, 0, 255, out=image)
    texture = image.astype(np.uint8)

    # Blobs: count per square metre chosen so a 640x480 view at 2-4 m holds thousands of them.
    count = int(round(150 * width_m * height_m))
    kinds = rng.integers(0, 6, count)
    centers = rng.uniform((0, 0), (tw, th), (count, 2))
    radii = np.exp(rng.uniform(math.log(0.006), math.log(0.09), count)) * density
    aspects = rng.uniform(0.3, 1.0, count)
    angles = rng.uniform(0, 180, count)
    # Mostly darker or lighter shades of the face colour (SIFT sees luminance; a face keeps its
    # character for a person), with a few freely coloured shapes for extra distinctiveness.
    lightness = np.exp(rng.uniform(math.log(0.3), math.log(1.7), (count, 1)))
    colours = np.clip(lightness * colour + rng.normal(0, 18, (count, 3)), 0, 255)
    free = rng.random(count) < 0.12
    colours[free] = rng.uniform(0, 255, (int(free.sum()), 3))
    shift = 4  # shape coordinates are fixed point with 1/16 texel precision
    unit = 1 << shift
    for kind, (x, y), r, aspect, angle, rgb in zip(
        kinds, centers, radii, aspects, angles, colours, strict=True
    ):
        c = tuple(float(v) for v in rgb)
        center = (int(x * unit), int(y * unit))
        radius = max(1, int(r * unit))
        if kind <= 1:
            cv2.circle(texture, center, radius, c, -1, cv2.LINE_AA, shift)
        elif kind == 2:
            axes = (radius, max(1, int(r * aspect * unit)))
            cv2.ellipse(texture, center, axes, float(angle), 0, 360, c, -1, cv2.LINE_AA, shift)
        elif kind == 3:
            box = cv2.boxPoints(((float(x), float(y)), (2 * r, 2 * r * aspect), float(angle)))
            corners = np.round(box * unit).astype(np.int32)
            cv2.fillConvexPoly(texture, corners, c, cv2.LINE_AA, shift)
        elif kind == 4:
            cv2.circle(texture, center, radius, c, max(1, int(r * 0.3)), cv2.LINE_AA, shift)
        else:
            dx = math.cos(math.radians(angle)) * r * 1.5
            dy = math.sin(math.radians(angle)) * r * 1.5
            p0 = (int((x - dx) * unit), int((y - dy) * unit))
            p1 = (int((x + dx) * unit), int((y + dy) * unit))
            cv2.line(texture, p0, p1, c, max(1, int(r * 0.25)), cv2.LINE_AA, shift)
    if quad.shade != 1.0:
        texture = cv2.convertScaleAbs(texture, alpha=quad.shade)
    return texture


# ---------------------------------------------------------------------------------------------
# Cameras


def camera_poses(config: SyntheticSceneConfig) -> list[np.ndarray]:
    """(3, 4) ``cam_from_world`` of each view, on an arc around the boxes (seeded)."""
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 0]))
    n = config.num_views
    arc = math.radians(min(_MAX_ARC_DEG, _MAX_SPACING_DEG * (n - 1)))
    spacing = arc / (n - 1)
    poses = []
    for i in range(n):
        # Azimuth 0 is the -y side of the room, so the far wall +y is behind the boxes.
        azimuth = -arc / 2 + i * spacing + rng.uniform(-0.15, 0.15) * spacing
        radius = rng.uniform(*_RING_RADIUS_M)
        height = rng.uniform(*_CAMERA_HEIGHT_M)
        center = np.array([radius * math.sin(azimuth), -radius * math.cos(azimuth), height])
        jitter_radius = _LOOK_AT_JITTER_M * math.sqrt(rng.uniform())  # uniform in a disc
        jitter_angle = rng.uniform(0, 2 * math.pi)
        target = _LOOK_AT_M + [
            jitter_radius * math.cos(jitter_angle),
            jitter_radius * math.sin(jitter_angle),
            rng.uniform(-_LOOK_AT_JITTER_Z_M, _LOOK_AT_JITTER_Z_M),
        ]
        roll = rng.uniform(-_MAX_ROLL_DEG, _MAX_ROLL_DEG)
        poses.append(look_at(center, target, (0.0, 0.0, 1.0), roll))
    return poses


# ---------------------------------------------------------------------------------------------
# Rendering


def _clip_near(points_in_cam: np.ndarray, z_near: float) -> np.ndarray:
    """(M, 3) convex polygon (N, 3) clipped to z >= z_near (Sutherland-Hodgman, one plane)."""
    out = []
    n = len(points_in_cam)
    for i in range(n):
        a, b = points_in_cam[i], points_in_cam[(i + 1) % n]
        a_in, b_in = a[2] >= z_near, b[2] >= z_near
        if a_in:
            out.append(a)
        if a_in != b_in:
            out.append(a + (z_near - a[2]) / (b[2] - a[2]) * (b - a))
    return np.array(out).reshape(-1, 3)


def _affine_image(row: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(h, w) float32 values ``row . (x, y, 1)`` over the grid xs (w,) by ys (h,)."""
    # float32 halves the memory traffic; the edge tolerance covers its rounding.
    column = np.float32(row[1]) * ys + np.float32(row[2])
    return np.float32(row[0]) * xs[None, :] + column[:, None]


def rasterize(
    quads: list[SceneQuad],
    textures: list[np.ndarray] | None,
    K: np.ndarray,
    cam_from_world: np.ndarray,
    width: int,
    height: int,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Ray-cast the quads into one camera: ((H, W, 3) uint8 image or None, (H, W) inverse depth).

    Inverse depth is 0 where nothing is seen. Without textures only depth is computed.
    For a quad, ``H = K [R e_u | R e_v | R o + t]`` maps (u, v, 1) to z * (x, y, 1); so
    ``H^-1 (x, y, 1) = (u, v, 1) / z``: inverse depth and u/z, v/z are affine in the pixel
    coordinates. A pixel centre sees the quad where 1/z > 0 and 0 <= u, v <= 1, which also
    handles quads that cross the camera plane without clipping them.
    """
    R = cam_from_world[:, :3]
    t = cam_from_world[:, 3]
    center = -R.T @ t
    inv_depth = np.zeros((height, width), dtype=np.float32)
    image = None if textures is None else np.zeros((height, width, 3), dtype=np.uint8)
    eps = _EDGE_TOLERANCE
    for index, quad in enumerate(quads):
        # A face seen from behind is hidden by the closed scene; seen edge-on it covers no
        # pixel centre and its H is singular.
        if np.dot(quad.normal, center - quad.origin) <= 1e-9:
            continue
        corners_in_cam = quad.corners_in_world @ R.T + t
        polygon = _clip_near(corners_in_cam, 1e-4)
        if len(polygon) < 3:
            continue
        projected = polygon @ K.T
        xy = projected[:, :2] / projected[:, 2:3]
        # Pixels whose centres may be covered, plus a margin of one for the edge tolerance.
        x0 = max(0, math.floor(min(xy[:, 0].min(), width)) - 1)
        x1 = min(width, math.ceil(max(xy[:, 0].max(), 0)) + 1)
        y0 = max(0, math.floor(min(xy[:, 1].min(), height)) - 1)
        y1 = min(height, math.ceil(max(xy[:, 1].max(), 0)) + 1)
        if x1 <= x0 or y1 <= y0:
            continue
        H = K @ np.column_stack([R @ quad.edge_u, R @ quad.edge_v, R @ quad.origin + t])
        # Pixel index (i, j) of the window -> continuous coordinates of its centre.
        window_to_image = np.array([[1.0, 0.0, x0 + 0.5], [0.0, 1.0, y0 + 0.5], [0.0, 0.0, 1.0]])
        G = np.linalg.inv(H) @ window_to_image  # rows: u/z, v/z, 1/z
        xs = np.arange(x1 - x0, dtype=np.float32)
        ys = np.arange(y1 - y0, dtype=np.float32)
        iz = _affine_image(G[2], xs, ys)
        zbuffer = inv_depth[y0:y1, x0:x1]
        mask = iz > zbuffer  # zbuffer >= 0, so this also keeps only points in front
        for row in (
            G[0] + eps * G[2],
            (1 + eps) * G[2] - G[0],
            G[1] + eps * G[2],
            (1 + eps) * G[2] - G[1],
        ):
            mask &= _affine_image(row, xs, ys) >= 0
        np.copyto(zbuffer, iz, where=mask)
        if image is not None and textures is not None:
            texture = textures[index]
            th, tw = texture.shape[:2]
            # (u, v) -> texel index coordinates; texel (a, b) has its centre at ((a+.5)/tw, ..).
            uv_to_texel = np.array([[tw, 0.0, -0.5], [0.0, th, -0.5], [0.0, 0.0, 1.0]])
            warped = cv2.warpPerspective(
                texture,
                uv_to_texel @ G,
                (x1 - x0, y1 - y0),
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REPLICATE,
            )
            np.copyto(image[y0:y1, x0:x1], warped, where=mask[:, :, None])
    return image, inv_depth


def scene_textures(config: SyntheticSceneConfig, quads: list[SceneQuad]) -> list[np.ndarray]:
    """One seeded texture per quad (each from its own random stream, so they are independent)."""
    textures = []
    for index, quad in enumerate(quads):
        rng = np.random.default_rng(np.random.SeedSequence([config.seed, 1, index]))
        width_m = float(np.linalg.norm(quad.edge_u))
        height_m = float(np.linalg.norm(quad.edge_v))
        textures.append(make_texture(rng, width_m, height_m, quad))
    return textures


def render_view(
    quads: list[SceneQuad],
    textures: list[np.ndarray],
    K: np.ndarray,
    cam_from_world: np.ndarray,
    width: int,
    height: int,
    supersample: int,
) -> tuple[np.ndarray, np.ndarray]:
    """One view: ((H, W, 3) uint8 RGB image, (H, W) float32 depth in metres, inf where empty).

    The image is rendered at ``s = supersample`` times the size with ``diag(s, s, 1) K``: fine
    pixel k covers [k / s, (k + 1) / s) in final pixel units, so the s x s fine pixels that
    INTER_AREA averages into final pixel i tile exactly [i, i + 1) (box-filter anti-aliasing
    without shifting the image). Depth is cast at the final resolution, so that it is exact at
    each final pixel centre rather than an average across depth edges.
    """
    s = supersample
    K_fine = np.diag([s, s, 1.0]) @ K
    fine, _ = rasterize(quads, textures, K_fine, cam_from_world, width * s, height * s)
    assert fine is not None
    image = fine if s == 1 else cv2.resize(fine, (width, height), interpolation=cv2.INTER_AREA)
    _, inv_depth = rasterize(quads, None, K, cam_from_world, width, height)
    depth = np.full(inv_depth.shape, np.inf, dtype=np.float32)
    seen = inv_depth > 0
    depth[seen] = 1.0 / inv_depth[seen]
    return image, depth


def render_scene(config: SyntheticSceneConfig) -> SyntheticScene:
    """Render every view of the scene: images, exact depth maps and true cameras. No I/O."""
    quads = scene_quads()
    textures = scene_textures(config, quads)
    K = config.K
    views = []
    for index, cam_from_world in enumerate(camera_poses(config)):
        image, depth = render_view(
            quads, textures, K, cam_from_world, config.width, config.height, config.supersample
        )
        views.append(
            SyntheticView(
                name=f"view_{index:03d}.png",
                cam_from_world=cam_from_world,
                image_rgb=image,
                depth=depth,
            )
        )
    return SyntheticScene(config=config, K=K, views=views)


# ---------------------------------------------------------------------------------------------
# Files


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    # A hidden temporary (not `atomic_output`'s ``.partial`` sibling): the folder is a photo
    # folder, whose scan skips hidden files, so a killed run leaves no photo behind. mkstemp
    # makes it 0600; it gets the mode of any new file before it takes the photo's name.
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp_name, output_mode())
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def write_scene(scene: SyntheticScene, images_dir: Path, truth_path: Path) -> None:
    """Write each view as ``images_dir/<view name>`` (PNG) and the cameras to ``truth_path``.

    Every file is written to a temporary sibling and renamed into place. Depth maps are not
    written.
    """
    images_dir = Path(images_dir)
    images_dir.mkdir(parents=True, exist_ok=True)
    for view in scene.views:
        ok, encoded = cv2.imencode(".png", cv2.cvtColor(view.image_rgb, cv2.COLOR_RGB2BGR))
        if not ok:
            raise OSError(f"could not encode {view.name} as PNG")
        _write_bytes_atomic(images_dir / view.name, encoded.tobytes())
    write_cameras_json(Path(truth_path), scene.truth())


def visible_surface_points(scene: SyntheticScene, *, step: int = 2, min_views: int = 2,
                           rel_depth_tol: float = 0.005) -> np.ndarray:
    """(N, 3) world points of the scene surface seen by at least ``min_views`` cameras.

    The ground truth a multi-view reconstruction can be scored against: every ``step``-th pixel
    of each view's true depth map, back-projected, kept when at least ``min_views - 1`` other
    views see the same point (it projects inside them and their true depth agrees within
    ``rel_depth_tol``), so surfaces only one camera saw do not count as missing.
    """
    K, K_inv = scene.K, np.linalg.inv(scene.K)
    height, width = scene.views[0].depth.shape
    v, u = np.mgrid[0:height:step, 0:width:step]
    # Pixel centres at +0.5, COLMAP's convention (as the renderer's K).
    rays = np.stack([u.ravel() + 0.5, v.ravel() + 0.5, np.ones(u.size)]) 
    kept = []
    for i, view in enumerate(scene.views):
        depth = view.depth[v.ravel(), u.ravel()].astype(np.float64)
        ok = np.isfinite(depth)
        points_cam = (K_inv @ rays[:, ok]) * depth[ok]
        R, t = view.cam_from_world[:, :3], view.cam_from_world[:, 3]
        points = (R.T @ (points_cam - t[:, None])).T
        seen = np.zeros(len(points), dtype=int)
        for j, other in enumerate(scene.views):
            if j == i:
                continue
            Ro, to = other.cam_from_world[:, :3], other.cam_from_world[:, 3]
            cam = points @ Ro.T + to
            z = cam[:, 2]
            pix = cam @ K.T
            with np.errstate(divide="ignore", invalid="ignore"):
                x, y = pix[:, 0] / z, pix[:, 1] / z
            inside = (z > 0) & (x >= 0) & (x < width) & (y >= 0) & (y < height)
            xi = np.clip(np.floor(x[inside]).astype(int), 0, width - 1)
            yi = np.clip(np.floor(y[inside]).astype(int), 0, height - 1)
            agree = np.abs(other.depth[yi, xi] - z[inside]) < rel_depth_tol * z[inside]
            seen[np.flatnonzero(inside)[agree]] += 1
        kept.append(points[seen >= min_views - 1])
    return np.concatenate(kept)
