"""Silhouette renderers (plugin kind ``renderer``): a mesh and a camera in, a boolean mask out.

Registered in ``pyproject.toml`` under ``mocap.renderer`` like any third-party plugin, and
chosen with ``--renderer NAME`` (options ``--renderer-option KEY=VALUE``). Every renderer has
the same pixel rule, so their masks agree up to ties and numerical noise: a pixel is True when
its *centre* ``(i + 0.5, j + 0.5)`` (see :mod:`tracking.rig.cameras`) sees the mesh, and lens
distortion is honoured through :class:`~tracking.rig.cameras.Camera`.

* ``cpu-raster`` (ours, the default: 1.7 ms per 640x480 view, 3-6x faster than the ray
  caster in ``benchmarks/renderers.py``, and pixel-identical to it on the body model): the
  silhouette of a closed mesh is the union of its projected triangles, so no depth buffer is
  needed. Vertices are projected with ``Camera.project``'s arithmetic (distortion included;
  triangle edges stay straight between distorted vertices: exact for a pinhole camera, far
  below a pixel for small triangles) and a scanline fill marks every covered pixel centre,
  both compiled by numba in one call per view (`tracking.track.raster`). For the energy it
  counts rather than draws (`covered_gains`: a per-pixel gain summed over the covered
  pixels, every view in one call), from the mesh's outline in each row rather than from
  every triangle: the same integers, 1.1-1.8x faster than visiting each triangle's pixels
  (`benchmarks/xor_count.py`; session 34).
  Triangles with a vertex behind the near plane (``near_m``) are dropped, not clipped.
* ``open3d-raycast``: Open3D's Embree ray caster on the CPU, one ray through every pixel
  centre (the undistorted ray, so distortion is exact). The reference of the agreement tests.
* ``open3d-filament``: Open3D's Filament ``OffscreenRenderer`` (unlit, no anti-aliasing); a
  distorted image is resampled from a pinhole render. On a CPU-only machine it runs on Mesa's
  lavapipe: 0.04-0.5 s per frame, with one-off stalls of 25-50 s on some first frames of a
  new camera (measured; presumably a pipeline being JIT-compiled). It fails with a one-line
  :class:`PluginError` when it cannot start.
"""

from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import sys
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from plugins.protocols import Plugin
from plugins.registry import PluginError
from recon.cameras import Camera

DEFAULT_RENDERER = "cpu-raster"
"""The renderer tracking uses unless told otherwise (``benchmarks/renderers.py`` chose it)."""



def _check_mesh(vertices_in_world: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    tris, top = _checked_faces(faces)
    return _checked_vertices(vertices_in_world, tris, top), tris


def _checked_faces(faces: Any) -> tuple[np.ndarray, int]:
    """(F, 3) int64 faces, and their largest vertex index (-1 for none); one-line errors."""
    tris = np.asarray(faces)
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"need faces (F, 3), got {tris.shape}")
    if not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"faces must be integers, got {tris.dtype}")
    if tris.size and tris.min() < 0:
        raise ValueError("faces index a vertex below 0")
    return tris.astype(np.int64, copy=False), int(tris.max()) if tris.size else -1


def _checked_vertices(vertices_in_world: Any, tris: np.ndarray, top: int) -> np.ndarray:
    """(V, 3) float64 vertices, which the faces' largest index `top` must be within."""
    vertices = np.asarray(vertices_in_world, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"need vertices (V, 3) and faces (F, 3), got {vertices.shape} and "
                         f"{tris.shape}")
    if top >= len(vertices):
        raise ValueError(f"faces index vertices outside 0..{len(vertices) - 1}")
    return vertices


# ---------------------------------------------------------------------------------------------
# cpu-raster (its numba kernel is in tracking.track.raster: `mocap plugins` imports this module
# to describe the renderers, and importing numba alone takes longer than the rest of it)


def rasterize_triangles(uv: np.ndarray, faces: np.ndarray, width: int, height: int,
                        out: np.ndarray | None = None, keep_winding: int = 0,
                        ) -> np.ndarray:  # fmt: skip
    """(H, W) bool union of 2-D triangles: True where a pixel centre lies inside one.

    uv: (V, 2) pixel coordinates (pixel centres at +0.5); faces: (F, 3) indices. Points on an
    edge count as inside, so triangles sharing an edge leave no gap; either winding works;
    triangles with a non-finite vertex are skipped. `out`: an (H, W) bool mask to draw into
    (it is returned), e.g. the silhouette of the parts that did not move. keep_winding: 0
    fills every triangle; +1 (-1) only those with a positive (negative) signed area in the
    image, i.e. counter-clockwise (clockwise) on screen (y down).

    A scanline fill compiled by numba: every row whose centre line crosses a triangle is
    filled between its two edges, with no depth test (a silhouette is the union of the
    triangles). About 20 times faster than the vectorised numpy version it replaced, with the
    same pixel rule (`tests/tracking/test_render.py` checks it against Open3D's ray caster).
    """
    mask = np.zeros((height, width), dtype=bool) if out is None else out
    if mask.shape != (height, width) or mask.dtype != bool:
        raise ValueError(f"out must be a ({height}, {width}) bool array")
    if len(faces):
        from tracking.track.raster import fill_triangles

        fill_triangles(np.ascontiguousarray(uv, dtype=np.float64),
                        np.ascontiguousarray(faces, dtype=np.int64), mask,
                        float(np.sign(keep_winding)))  # fmt: skip
    return mask


class CpuRasterRenderer(Plugin):
    description = ("ours: union of projected triangles, pixel-centre rule, a scanline fill "
                   "compiled by numba on the CPU (no depth buffer; distortion through "
                   "Camera.project)")

    @dataclass(frozen=True, kw_only=True)
    class Options:
        cull_back_faces: bool = field(
            default=True, metadata={"help": "skip triangles facing away from the camera: the "
                                    "silhouette is unchanged for a closed mesh with outward "
                                    "normals (counter-clockwise faces), and the work halves"})
        near_m: float = field(
            default=0.01, metadata={"help": "triangles with a vertex closer to the camera plane "
                                    "than this (or behind it) are dropped, not clipped; a body "
                                    "that close to a camera cannot be tracked anyway"})

    def render(self, vertices_in_world: Any, faces: Any, camera: Camera) -> np.ndarray:
        return self.render_views(vertices_in_world, faces, [camera])[0]

    def render_views(self, vertices_in_world: Any, faces: Any,
                     cameras: Sequence[Camera]) -> list[np.ndarray]:  # fmt: skip
        """`render` in every camera, the mesh checked once (what `render_views` calls)."""
        from tracking.track.raster import render_mask

        vertices, tris = _check_mesh(vertices_in_world, faces)
        # A counter-clockwise face (outward normal) in front of the camera is clockwise on
        # screen, where y points down: its signed area there is negative. The projection keeps
        # orientation (distortion too, inside its monotonic radius), so this is the 3-D test.
        winding = -1.0 if self.options.cull_back_faces else 0.0
        vertices = np.ascontiguousarray(vertices)
        masks = []
        for camera in cameras:
            mask = np.zeros((camera.height, camera.width), dtype=bool)
            if len(tris):
                # Vertices nearer than near_m, or past the monotonic radius (where the
                # distortion polynomial folds back into the image), project to NaN, and the
                # fill skips the triangles that have one.
                render_mask(vertices, tris, camera.cam_from_world, camera.K, camera.dist,
                            self.options.near_m, camera.max_radius2, winding, mask)
            masks.append(mask)
        return masks


def render_views(renderer: Any, vertices_in_world: Any, faces: Any,
                 cameras: Sequence[Camera]) -> list[np.ndarray]:  # fmt: skip
    """(H, W) bool silhouettes of one mesh in every camera: the renderer's own `render_views`
    when it has one (``cpu-raster``: the mesh checked once), else one `render` per camera."""
    if isinstance(renderer, CpuRasterRenderer):
        return renderer.render_views(vertices_in_world, faces, cameras)
    return [np.asarray(renderer.render(vertices_in_world, faces, c), dtype=bool)
            for c in cameras]  # fmt: skip


@functools.lru_cache(maxsize=32)
def _edges_of(faces: bytes, count: int) -> Any:
    """`tracking.track.raster.mesh_edges` of `count` faces of int64 `faces` (their bytes):
    the tracker's stages make new arrays of the same few face sets frame after frame."""
    from tracking.track.raster import mesh_edges

    return mesh_edges(np.frombuffer(faces, np.int64).reshape(count, 3))


class ViewGains:
    """Per view, a per-pixel gain to sum over the pixels a mesh covers (`covered_gains`), with
    what the compiled count needs made once: the gains in one (views, H, W) int8 array, zero
    past a smaller view's size; the cameras' parameters stacked; the edges of the last faces
    counted."""

    def __init__(self, cameras: Sequence[Camera]) -> None:
        """The gains zero: the caller sets them in `gains` (views into `stacked`)."""
        self.cameras = list(cameras)
        shape = (len(self.cameras), max((c.height for c in self.cameras), default=0),
                 max((c.width for c in self.cameras), default=0))
        self.stacked = np.zeros(shape, np.int8)
        self.cams_from_world = np.array([c.cam_from_world for c in self.cameras]).reshape(-1, 3, 4)
        self.Ks = np.array([c.K for c in self.cameras]).reshape(-1, 3, 3)
        self.dists = np.array([c.dist for c in self.cameras]).reshape(-1, 5)
        self.max_radius2s = np.array([c.max_radius2 for c in self.cameras], dtype=float)
        self._faces: tuple[Any, tuple[np.ndarray, int, Any]] | None = None

    @property
    def gains(self) -> list[np.ndarray]:
        """Per view, its (H, W) gains (views into `stacked`, without the padding)."""
        return [view[:c.height, :c.width] for view, c in zip(self.stacked, self.cameras,
                                                             strict=True)]  # fmt: skip

    def edges(self, faces: Any) -> tuple[np.ndarray, int, Any]:
        """(F, 3) int64 `faces` (checked: `_checked_faces`), their largest vertex index and
        their `tracking.track.raster.MeshEdges`. A read-only array (a model's faces, a
        stage's) is checked once and kept with its answer (held, so that no other array
        takes its address): a stage counts it thousands of times. Any other is checked, and
        its edges looked up by its contents, every time (it may have changed)."""
        if self._faces is not None and self._faces[0] is faces:
            return self._faces[1]
        tris, top = _checked_faces(faces)
        if not (isinstance(faces, np.ndarray) and not faces.flags.writeable):
            tris = np.ascontiguousarray(tris)
            return tris, top, _edges_of(tris.tobytes(), len(tris))
        tris = np.array(tris, order="C")  # kept: a copy of its own, whatever else shares it
        self._faces = faces, (tris, top, _edges_of(tris.tobytes(), len(tris)))
        return self._faces[1]


def covered_gains(renderer: Any, vertices_in_world: Any, faces: Any, views: ViewGains
                  ) -> np.ndarray:  # fmt: skip
    """(views,) int: per camera of `views`, the sum of its gain over the pixels the mesh
    covers in that view: what the XOR of a silhouette changes by when the mesh is drawn into
    it (`tracking.track.energy.XorCount`). ``cpu-raster`` sums while it walks the mesh's
    outline in each row, drawing no mask, every view in one compiled call
    (`tracking.track.raster.covered_gains`); any other renderer draws its masks
    (`render_views`) and they are summed."""
    if not isinstance(renderer, CpuRasterRenderer):
        return np.array([int(gain[mask].sum()) for gain, mask in zip(
            views.gains, render_views(renderer, vertices_in_world, faces, views.cameras),
            strict=True)])
    tris, top, edges = views.edges(faces)
    vertices = _checked_vertices(vertices_in_world, tris, top)
    if not len(tris) or not len(views.cameras):
        return np.zeros(len(views.cameras), np.int64)
    from tracking.track.raster import covered_gains as count

    winding = -1.0 if renderer.options.cull_back_faces else 0.0
    return count(np.ascontiguousarray(vertices), tris, edges.vertices, edges.faces, edges.signs,
                 views.cams_from_world, views.Ks, views.dists, renderer.options.near_m,
                 views.max_radius2s, winding, views.stacked)  # fmt: skip


# ---------------------------------------------------------------------------------------------
# open3d-raycast


class _PerCamera:
    """Values computed per camera (rays, canvases), kept for the last few cameras: an
    optimiser renders through the same cameras over and over."""

    def __init__(self, size: int = 16) -> None:
        self._items: OrderedDict[Camera, Any] = OrderedDict()
        self._size = size

    def get(self, camera: Camera, make: Any) -> Any:
        if camera in self._items:
            self._items.move_to_end(camera)
            return self._items[camera]
        value = self._items[camera] = make(camera)
        while len(self._items) > self._size:
            self._items.popitem(last=False)
        return value


def world_rays(camera: Camera) -> np.ndarray:
    """(H, W, 6) float32 ``origin, unit direction`` in the world through each pixel centre.

    A pixel whose distortion cannot be inverted (NaN ray) gets a zero direction, which hits
    nothing.
    """
    directions = camera.pixel_rays_in_camera @ camera.R  # d_world = R.T d_cam, as rows
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    directions[~np.isfinite(directions).all(axis=-1)] = 0.0
    origins = np.broadcast_to(camera.center_in_world, directions.shape)
    return np.concatenate([origins, directions], axis=-1).astype(np.float32)


class Open3DRaycastRenderer(Plugin):
    description = ("Open3D RaycastingScene (Embree, CPU): one ray per pixel centre, exact "
                   "distortion; the reference renderer")

    @dataclass(frozen=True, kw_only=True)
    class Options:
        threads: int = field(default=0, metadata={"help": "ray-casting threads (0: all cores)"})

    def __init__(self, options: Any) -> None:
        super().__init__(options)
        try:
            import open3d as o3d
        except Exception as exc:  # noqa: BLE001 - missing shared libraries raise OSError
            raise PluginError(f"open3d-raycast: cannot import open3d ({exc})") from None
        self._o3d = o3d
        self._rays = _PerCamera()

    def render(self, vertices_in_world: Any, faces: Any, camera: Camera) -> np.ndarray:
        o3d = self._o3d
        vertices, tris = _check_mesh(vertices_in_world, faces)
        rays = self._rays.get(camera, lambda cam: o3d.core.Tensor(world_rays(cam)))
        # A fresh scene per call: for the body's 5,568 triangles it is a small part of the
        # ~10 ms spent on 307,200 rays (measured), and simpler than moving a scene's vertices.
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),
                            o3d.core.Tensor(tris.astype(np.uint32)))
        hit = scene.test_occlusions(rays, nthreads=self.options.threads).numpy()
        return hit.astype(bool, copy=False)


# ---------------------------------------------------------------------------------------------
# open3d-filament

_FILAMENT_PROBE = """
import numpy as np, open3d as o3d
o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
r = o3d.visualization.rendering.OffscreenRenderer(16, 16)
image = np.asarray(r.render_to_image())
assert image.shape == (16, 16, 3), image.shape
print("ok")
"""
_filament_status: str | None = None  # None: not probed; "" works; else why it does not
# Filament hosts one OffscreenRenderer per process: with two, the process aborts at exit
# ("destroying MaterialInstance ... still in use"), and the render target cannot be resized.
_filament_renderer: Any = None
_filament_canvas_px = 0


def filament_unavailable_reason(timeout_s: float = 180.0) -> str:
    """Empty when Filament renders here, else one line saying why not (probed once, in a
    subprocess, because a broken GPU/Vulkan stack can abort the whole process)."""
    global _filament_status
    if _filament_status is None:
        try:
            done = subprocess.run([sys.executable, "-c", _FILAMENT_PROBE], capture_output=True,
                                  text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            _filament_status = f"Filament did not render a 16x16 test image in {timeout_s:.0f} s"
        else:
            if done.returncode == 0 and done.stdout.strip().endswith("ok"):
                _filament_status = ""
            else:
                lines = [ln.strip() for ln in done.stderr.splitlines() if ln.strip()]
                last = lines[-1] if lines else f"exit status {done.returncode}"
                _filament_status = f"Filament cannot start here ({last[:200]})"
    return _filament_status


@contextlib.contextmanager
def _quiet_stdio() -> Iterator[None]:
    """Silence C++ chatter (Filament's engine banner) on file descriptors 1 and 2."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


class Open3DFilamentRenderer(Plugin):
    description = ("Open3D Filament OffscreenRenderer, unlit (GPU, or Vulkan/EGL on the CPU: "
                   "slow); distortion by resampling a pinhole render")

    @dataclass(frozen=True, kw_only=True)
    class Options:
        canvas_px: int = field(
            default=2048, metadata={"help": "side of the square render target; every image "
                                    "(grown a little to cover lens distortion) must fit. One "
                                    "target serves the whole process, so the first renderer "
                                    "created fixes it; smaller is faster on the CPU"})

    def __init__(self, options: Any) -> None:
        super().__init__(options)
        reason = filament_unavailable_reason()
        if reason:
            raise PluginError(f"open3d-filament: {reason}")
        import open3d as o3d

        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        self._o3d = o3d
        self._material = o3d.visualization.rendering.MaterialRecord()
        self._material.shader = "defaultUnlit"
        self._material.base_color = [1.0, 1.0, 1.0, 1.0]
        self._canvas = _PerCamera()
        self._renderer = self._shared_renderer(options.canvas_px)
        self._side = _filament_canvas_px

    def _shared_renderer(self, side: int) -> Any:
        global _filament_renderer, _filament_canvas_px
        if _filament_renderer is None:
            with _quiet_stdio():
                renderer = self._o3d.visualization.rendering.OffscreenRenderer(side, side)
            renderer.scene.set_background([0.0, 0.0, 0.0, 1.0])
            view = renderer.scene.view
            view.set_post_processing(False)  # no tone mapping, dithering or FXAA
            view.set_antialiasing(False)
            view.set_sample_count(1)
            view.set_shadowing(False)
            _filament_renderer, _filament_canvas_px = renderer, side
        return _filament_renderer

    @staticmethod
    def _pinhole_canvas(camera: Camera) -> tuple[np.ndarray, int, int, Any]:
        """K and size of the pinhole image to render and, with distortion, the cv2.remap maps
        giving every output pixel's position in it (the canvas is grown to hold them all)."""
        if not camera.has_distortion:
            return camera.K, camera.width, camera.height, None
        rays = camera.pixel_rays_in_camera
        K = camera.K
        u = K[0, 0] * rays[..., 0] + K[0, 1] * rays[..., 1] + K[0, 2]
        v = K[1, 1] * rays[..., 1] + K[1, 2]
        ox, oy = int(np.floor(np.nanmin(u))), int(np.floor(np.nanmin(v)))
        width = int(np.floor(np.nanmax(u))) - ox + 1
        height = int(np.floor(np.nanmax(v))) - oy + 1
        K_canvas = K.copy()
        K_canvas[0, 2] -= ox
        K_canvas[1, 2] -= oy
        # cv2.remap puts pixel centres at integers: ours are at +0.5. NaN rays (distortion
        # not invertible) sample outside the canvas, i.e. background.
        maps = tuple(np.nan_to_num(m, nan=-2.0).astype(np.float32)
                     for m in (u - ox - 0.5, v - oy - 0.5))
        return K_canvas, width, height, maps

    def render(self, vertices_in_world: Any, faces: Any, camera: Camera) -> np.ndarray:
        o3d = self._o3d
        vertices, tris = _check_mesh(vertices_in_world, faces)
        K, width, height, maps = self._canvas.get(camera, self._pinhole_canvas)
        side = self._side
        if width > side or height > side:
            raise PluginError(f"open3d-filament: camera {camera.name} needs a {width}x{height} "
                              f"render target but this process's is {side}x{side} "
                              f"(--renderer-option canvas_px=N before the first render)")
        renderer = self._renderer
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                         o3d.utility.Vector3iVector(tris.astype(np.int32)))
        renderer.scene.add_geometry("mesh", mesh, self._material)
        extrinsic = np.vstack([camera.cam_from_world, [0.0, 0.0, 0.0, 1.0]])
        # The image is the top-left width x height of the square target: the same K over a
        # larger target only widens the field of view. Near/far planes come from the
        # geometry's bounding box, so the camera is set after adding it.
        renderer.setup_camera(K, extrinsic, side, side)
        try:
            with _quiet_stdio():
                image = np.asarray(renderer.render_to_image())
        finally:
            # No geometry may outlive the call: Filament aborts at exit when a material is
            # destroyed while a renderable still uses it.
            renderer.scene.clear_geometry()
        # Without post-processing the background is exactly 0 and unlit white comes out at
        # about half intensity (127-128, no tone mapping), so any non-zero pixel is the mesh.
        mask = image[:height, :width, 0] > 0
        if maps is None:
            return mask
        import cv2

        # Bilinear resampling of the pinhole mask, cut at 0.5, keeps edges to sub-pixel.
        coverage = cv2.remap(mask.astype(np.float32), maps[0], maps[1], cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return coverage > 0.5
