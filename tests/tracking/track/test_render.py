"""Silhouette renderers: against analytic sphere silhouettes, a brute-force rasteriser, and
each other on the body model (pinhole, distorted and pyramid cameras)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugins import registry
from plugins.protocols import SilhouetteRenderer
from plugins.registry import PluginError
from recon.cameras import Camera, look_at
from tracking.body.model import LOWER_LIMITS, UPPER_LIMITS, BodyModel, BodyShape, Pose, superquadric
from tracking.rig.cameras import ring_cameras
from tracking.track import render
from tracking.track.render import rasterize_triangles

NAMES = ("cpu-raster", "open3d-raycast", "open3d-filament")
# Filament on the CPU (lavapipe) renders a frame in 0.04-0.5 s but stalls for 25-50 s on some
# first frames of a new camera, so its tests run with `make test-all` (about 40 s).
SLOW_FILAMENT = pytest.param("open3d-filament", marks=pytest.mark.slow)
RENDERER_PARAMS = ("cpu-raster", "open3d-raycast", SLOW_FILAMENT)
DIST = np.array([-0.2, 0.05, 0.001, -0.002, 0.0])
# Filament's one render target per process must hold every test image (and the slightly
# larger pinhole canvas of the distorted camera).
FILAMENT_OPTIONS = ["canvas_px=800"]


@pytest.fixture(scope="module")
def renderers() -> dict[str, object]:
    """Renderers made on first use; the PluginError of those that cannot start here."""
    return {}


def _renderer(renderers: dict[str, object], name: str):
    if name not in renderers:
        options = FILAMENT_OPTIONS if name == "open3d-filament" else []
        try:
            renderers[name] = registry.create("renderer", name, options)
        except PluginError as exc:
            renderers[name] = exc
    made = renderers[name]
    if isinstance(made, PluginError):
        pytest.skip(str(made))
    return made


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel(BodyShape.default())


# ---------------------------------------------------------------------------------------------
# Registry


def test_renderers_are_plugins_of_their_own_kind(renderers):
    assert set(NAMES) <= set(registry.available("renderer"))
    assert registry.KINDS["renderer"].choose_flag == "--renderer"
    assert registry.KINDS["renderer"].option_flag == "--renderer-option"
    for name in ("cpu-raster", "open3d-raycast"):
        assert isinstance(_renderer(renderers, name), SilhouetteRenderer)
    raster = registry.create("renderer", "cpu-raster", ["cull_back_faces=false", "near_m=0.1"])
    assert raster.options.cull_back_faces is False and raster.options.near_m == 0.1
    assert render.DEFAULT_RENDERER in registry.available("renderer")


def test_filament_that_cannot_start_fails_with_one_line(monkeypatch):
    monkeypatch.setattr(render, "_filament_status", "Filament cannot start here (no Vulkan)")
    with pytest.raises(PluginError, match=r"^open3d-filament: Filament cannot start") as info:
        registry.create("renderer", "open3d-filament")
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------------------------
# The rasteriser alone, against brute force


def _brute_force(uv: np.ndarray, faces: np.ndarray, width: int, height: int):
    """Inside test of every pixel centre against every triangle; also the pixels within
    1e-7 px of an edge, where the two may legitimately differ."""
    x, y = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    inside = np.zeros((height, width), bool)
    near = np.zeros((height, width), bool)
    for tri in uv[faces]:
        (ax, ay), (bx, by) = tri[1] - tri[0], tri[2] - tri[0]
        area = ax * by - ay * bx
        if area == 0:
            continue
        e = [np.sign(area) * ((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]))
             / np.hypot(*(b - a)) for a, b in zip(tri, np.roll(tri, -1, axis=0), strict=True)]
        inside |= (e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)
        near |= np.min(np.abs(e), axis=0) < 1e-7
    return inside, near


def test_rasteriser_matches_brute_force_on_random_triangles():
    rng = np.random.default_rng(0)
    uv = rng.uniform(-20, 100, (300, 2))  # some triangles stick out of the 80x60 image
    faces = rng.integers(0, 300, (150, 3))
    got = rasterize_triangles(uv, faces, 80, 60)
    expected, near = _brute_force(uv, faces, 80, 60)
    assert expected.sum() > 1000
    assert np.array_equal(got[~near], expected[~near])


def test_rasteriser_pixel_centre_rule_and_shared_edges():
    # The square [10, 20]^2 as two triangles (either diagonal, either winding) covers
    # exactly the 10 x 10 pixels whose centres 10.5 .. 19.5 lie inside: no gap on the diagonal.
    square = np.array([[10.0, 10.0], [20.0, 10.0], [20.0, 20.0], [10.0, 20.0]])
    expected = np.zeros((32, 32), bool)
    expected[10:20, 10:20] = True
    for faces in ([[0, 1, 2], [0, 2, 3]], [[0, 2, 1], [0, 3, 2]], [[0, 1, 3], [1, 2, 3]]):
        assert np.array_equal(rasterize_triangles(square, np.array(faces), 32, 32), expected)
    # Overlapping copies are a union, not an even-odd fill.
    twice = rasterize_triangles(square, np.array([[0, 1, 2], [0, 1, 2], [0, 2, 3]]), 32, 32)
    assert np.array_equal(twice, expected)
    # Off-image and non-finite triangles draw nothing.
    far = np.array([[-50.0, -50.0], [-40.0, -50.0], [np.nan, 5.0]])
    assert not rasterize_triangles(far, np.array([[0, 1, 2]]), 32, 32).any()


# ---------------------------------------------------------------------------------------------
# Sphere: analytic silhouette


def _sphere(center, radius, rings=96, around=192):
    vertices, faces = superquadric(np.full(3, radius), n_rings=rings, n_around=around)
    return vertices + center, faces


def _sphere_truth(camera: Camera, center, radius) -> np.ndarray:
    """A pixel sees the sphere when the angle between its ray and the centre's direction is
    below asin(r / distance): exact, distortion included (through the camera's rays)."""
    rays = camera.pixel_rays_in_camera
    rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    c = camera.R @ center + camera.t
    distance = np.linalg.norm(c)
    return rays @ (c / distance) >= math.sqrt(1.0 - (radius / distance) ** 2)


K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
SPHERE_CAMERAS = {
    "pinhole": Camera("pinhole", 640, 480, K, np.column_stack([np.eye(3), [0, 0, 3.0]])),
    "oblique": Camera("oblique", 640, 480, K, look_at([2.0, 1.0, 2.5], [0.6, -0.3, 0.0])),
    "distorted": Camera("distorted", 640, 480, K, look_at([2.0, 1.0, 2.5], [0.6, -0.3, 0.0]),
                        DIST),
}
# Allowed disagreement along the outline, in pixels of outline: the 192-gon inscribed in the
# sphere sags 0.05 px inwards at this size; Filament resamples distorted images by bilinear
# interpolation of a pinhole mask, whose edges are only known to half a pixel.
EDGE_PX = {"cpu-raster": 0.1, "open3d-raycast": 0.1, "open3d-filament": 0.1}
EDGE_PX_DISTORTED = {"cpu-raster": 0.1, "open3d-raycast": 0.1, "open3d-filament": 0.6}


@pytest.mark.parametrize("name", RENDERER_PARAMS)
@pytest.mark.parametrize("view", SPHERE_CAMERAS)
def test_sphere_silhouette_is_the_analytic_one(renderers, name, view):
    renderer = _renderer(renderers, name)
    camera = SPHERE_CAMERAS[view]
    vertices, faces = _sphere(np.zeros(3), 0.5)
    mask = renderer.render(vertices, faces, camera)
    assert mask.shape == (480, 640) and mask.dtype == bool
    truth = _sphere_truth(camera, np.zeros(3), 0.5)
    outline_px = 2 * math.sqrt(math.pi * truth.sum())  # 2 pi R of a disc of that area
    edge = (EDGE_PX_DISTORTED if camera.has_distortion else EDGE_PX)[name]
    assert np.count_nonzero(mask ^ truth) <= edge * outline_px + 3
    if view == "pinhole":
        # On the axis the silhouette is a disc of radius f r / sqrt(d^2 - r^2) = 84.5 px.
        analytic = math.pi * 500.0**2 * 0.25 / (9.0 - 0.25)
        assert abs(mask.sum() - analytic) <= 0.1 * 2 * math.pi * 84.5 + 3


@pytest.mark.parametrize("name", ("cpu-raster", "open3d-raycast"))
def test_mesh_behind_the_camera_draws_nothing(renderers, name):
    renderer = _renderer(renderers, name)
    vertices, faces = _sphere(np.array([0.0, 0.0, -6.0]), 0.5, 16, 32)  # camera at z=-3 looks +z
    assert not renderer.render(vertices, faces, SPHERE_CAMERAS["pinhole"]).any()


# ---------------------------------------------------------------------------------------------
# Body model: all renderers agree


def _poses() -> list[Pose]:
    rng = np.random.default_rng(7)
    poses = [Pose.neutral()]
    for _ in range(2):
        params = rng.uniform(np.maximum(LOWER_LIMITS, -np.pi), np.minimum(UPPER_LIMITS, np.pi))
        params[:6] = [0.1, 0.0, -0.1, 0.0, 0.0, params[5]]  # upright, any heading
        poses.append(Pose(params))
    return poses


def _body_cameras() -> list[Camera]:
    ring = ring_cameras(3, 3.5, 0.3, (0.0, 0.0, 0.0), 640, 480, 520.0)
    distorted = Camera("distorted", 640, 480, ring[1].K, ring[1].cam_from_world, DIST)
    return [*ring, distorted, ring[0].scaled(0.25)]


# XOR allowed against the ray caster, as a fraction of its silhouette area: cpu-raster and
# Filament sample the same pixel centres (observed: 0 and a few pixels); Filament's resampling
# of distorted images moves edges by up to half a pixel (observed ~1%).
AGREEMENT = {"cpu-raster": 0.002, "open3d-filament": 0.005}
AGREEMENT_DISTORTED = {"cpu-raster": 0.002, "open3d-filament": 0.02}


@pytest.mark.parametrize("name", ("cpu-raster", SLOW_FILAMENT))
def test_renderers_agree_with_the_ray_caster_on_the_body(renderers, body, name):
    reference = _renderer(renderers, "open3d-raycast")
    renderer = _renderer(renderers, name)
    for pose in _poses():
        vertices = body.posed_vertices(pose)
        for camera in _body_cameras():
            truth = reference.render(vertices, body.faces, camera)
            mask = renderer.render(vertices, body.faces, camera)
            assert truth.sum() > 0.01 * truth.size, camera.name  # the body is in view
            allowed = (AGREEMENT_DISTORTED if camera.has_distortion else AGREEMENT)[name]
            assert np.count_nonzero(mask ^ truth) <= allowed * truth.sum() + 2, (
                camera.name, pose.params)


def test_back_face_culling_does_not_change_a_closed_mesh(body):
    culled = registry.create("renderer", "cpu-raster")
    full = registry.create("renderer", "cpu-raster", ["cull_back_faces=false"])
    vertices = body.posed_vertices(_poses()[1])
    for camera in _body_cameras():
        assert np.array_equal(culled.render(vertices, body.faces, camera),
                              full.render(vertices, body.faces, camera))


def test_culling_keeps_triangles_counter_clockwise_from_the_camera():
    camera = SPHERE_CAMERAS["pinhole"]  # at z = -3 looking along +z, image y down
    # Centre -> right -> up on screen: counter-clockwise as the camera sees it, normal (b - a)
    # x (c - a) pointing back at the camera (-z): a front face.
    front = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, -0.3, 0.0]])
    faces = np.array([[0, 1, 2]])
    assert np.cross(front[1] - front[0], front[2] - front[0])[2] < 0
    culled = registry.create("renderer", "cpu-raster")
    full = registry.create("renderer", "cpu-raster", ["cull_back_faces=false"])
    assert culled.render(front, faces, camera).sum() > 500
    assert not culled.render(front, faces[:, ::-1], camera).any()
    assert np.array_equal(full.render(front, faces[:, ::-1], camera),
                          culled.render(front, faces, camera))


@pytest.mark.parametrize("cull", [True, False])
def test_the_count_from_the_outline_is_the_drawn_masks_sum(body, cull):
    """`render.covered_gains` (the compiled count, from the outline of the kept triangles:
    `tracking.track.raster.covered_gains`) equals the gains summed over the drawn masks, with
    culling and without: on the body in random poses and on part of it (an open mesh), and on
    a triangle soup of few vertices (edges of up to a dozen faces, both windings, faces given
    twice, faces with a vertex behind the camera, triangles off the image)."""
    options = [] if cull else ["cull_back_faces=false"]
    renderer = registry.create("renderer", "cpu-raster", options)
    rng = np.random.default_rng(11)
    cameras = _body_cameras()  # a distorted view and a small one among them
    views = render.ViewGains(cameras)
    for gain in views.gains:
        gain[...] = rng.integers(-1, 2, gain.shape)
    soup = rng.integers(0, 40, (300, 3))
    soup = np.vstack([soup, soup[:20]])  # 20 faces twice
    meshes = [(body.posed_vertices(pose), body.faces) for pose in _poses()]
    meshes.append((meshes[1][0], body.faces[: len(body.faces) // 3]))
    for camera in cameras[:2]:  # 40 points near the body, 3 of them behind this camera
        points = camera.center_in_world + rng.normal(0.0, 0.6, (40, 3)) + 0.8 * (
            body.posed_vertices(_poses()[0]).mean(axis=0) - camera.center_in_world)
        points[:3] = camera.center_in_world - camera.R[2] * [[0.5], [1.0], [2.0]]
        meshes.append((points, soup))
    covered = 0
    for vertices, faces in meshes:
        drawn = render.render_views(renderer, vertices, faces, cameras)
        expected = [int(g[m].sum()) for g, m in zip(views.gains, drawn, strict=True)]
        assert render.covered_gains(renderer, vertices, faces, views).tolist() == expected
        covered += sum(np.count_nonzero(m) for m in drawn)
    assert covered > 50_000


def test_bad_meshes_are_refused(renderers):
    renderer = _renderer(renderers, "cpu-raster")
    camera = SPHERE_CAMERAS["pinhole"]
    with pytest.raises(ValueError, match="faces index"):
        renderer.render(np.zeros((3, 3)), np.array([[0, 1, 3]]), camera)
    with pytest.raises(ValueError, match=r"\(V, 3\)"):
        renderer.render(np.zeros((3, 2)), np.array([[0, 1, 2]]), camera)
    # The count checks a read-only face array once (`ViewGains.edges`), the vertices every
    # time; a writeable one every time: changed in place, it is counted as it is now.
    views = render.ViewGains([camera])
    faces = np.array([[0, 1, 2]])
    faces.flags.writeable = False
    assert render.covered_gains(renderer, np.eye(3), faces, views).tolist() == [0]
    with pytest.raises(ValueError, match="faces index"):
        render.covered_gains(renderer, np.eye(3)[:2], faces, views)
    with pytest.raises(ValueError, match="faces index"):
        render.covered_gains(renderer, np.eye(3), np.array([[0, -1, 2]]), views)
    square = np.array([[-0.3, -0.3, 0.0], [0.3, -0.3, 0.0], [0.3, 0.3, 0.0], [-0.3, 0.3, 0.0]])
    views.gains[0][...] = 1
    two = np.array([[0, 2, 1], [0, 3, 2]])  # facing the camera
    both = render.covered_gains(renderer, square, two, views)[0]
    two[1] = [0, 3, 3]  # the second triangle gone (a line), in place
    assert 0 < render.covered_gains(renderer, square, two, views)[0] < both
    two[1] = [0, 3, 4]
    with pytest.raises(ValueError, match="faces index"):
        render.covered_gains(renderer, square, two, views)
