"""`mocap synth`: synthetic multi-camera silhouette sequences of a BVH clip, with ground truth.

The body model (`tracking.body.model`) follows a BVH clip (a CMU skeleton is retargeted with
`tracking.body.retarget`; a body-model BVH such as `mocap track` writes is read exactly with
`tracking.body.motion`), calibrated pinhole cameras stand on a ring around it, and each view's
silhouette is rendered and made noisy the way background subtraction is noisy. Written into a
video workspace (`recon.workspace`)::

    WS/cameras.json                        mocap-cameras-v1 (`tracking.rig.cameras`), cam00..camNN
    WS/silhouettes/<camera>/<frame>.png    uint8, 0 background / 255 foreground, frame 000000..
    WS/gt/joints.csv                       frame,joint,x,y,z: the 16 nodes of NODE_NAMES, metres
    WS/gt/pose.json                        the poses, in the format of tracks/pose.json
    WS/logs/synth.rrd                      cameras, silhouettes and skeleton over the frames
    WS/run.json                            step "synth": config, fingerprint, timing, summary

World frame: the BVH's, metres, Y up (so the floor is horizontal). Frame k of the sequence is
clip frame ``first + k * step``; the frame rate is the clip's divided by ``step``. Unless
``first_frame`` is given, ``first`` skips a reference T-pose in frame 0 and the frames that
blend out of it (`tracking.body.bvh.leading_reference_frames`).

Cameras: ``cameras`` pinholes evenly on a horizontal circle around the subject's mean pelvis
position, ``camera_height_m`` above the floor, all looking at the subject's mean position at
mid-height, with a ``fov_deg`` horizontal field of view. Unless a radius is given, the ring is
the smallest (from 4 m up, in 0.25 m steps) that keeps every vertex of every frame at least
`_EDGE_MARGIN_PX` (plus the jitter) inside every image: a walk crosses the ring, so a fixed
radius would lose the feet in the camera it walks towards.

Noise, each view and frame drawn from its own generator (seed, frame, view), applied to the
exact render in this order:

1. shadow: a filled ellipse on the floor plane (lowest sole height over the clip), under the
   feet and stretched away from them along a fixed light azimuth, projected into the view and
   added to the mask (background subtraction takes cast shadows for foreground);
2. boundary jitter: the mask is resampled through a smooth random displacement field (RMS
   ``jitter_px``, correlation length ``jitter_scale_px``), so the outline wobbles by a pixel or
   two without tearing;
3. holes: a Poisson number of small random ellipses (``hole_radius_m`` on the body, converted
   to pixels at the pelvis' depth) cut out well inside the body (clothing that matches the
   background).

``clean`` skips all three: the silhouettes are then exactly the renderer's masks.

``videos`` also writes what the cameras would have filmed, ``WS/render/videos/<camera>.avi``
(the exact silhouettes painted as a subject over a static textured scene) and a photo of the
empty scene per camera, ``WS/render/backgrounds/<camera>.png`` (`tracking.rig.synth_video`):
the inputs of `mocap init-video` and `mocap capture`, with ``WS/cameras.json`` as calibration.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from recon.cameras import Camera, write_cameras_json
from recon.errors import UserError
from recon.workspace import (
    Timer,
    Workspace,
    atomic_output,
    file_digest,
    fingerprint,
    write_json_atomic,
)
from tracking.body.bvh import Motion, leading_reference_frames, read_bvh
from tracking.body.model import BONES, NODE_NAMES, BodyShape, Pose
from tracking.rig.cameras import ring_cameras
from tracking.rig.synth_video import RENDER_DIR, VIDEO_SUFFIX, SyntheticVideos
from tracking.track.render import DEFAULT_RENDERER

STEP = "synth"
_EDGE_MARGIN_PX = 3.0
"""Least distance (px) from any projected vertex to the image edge, besides 2x the jitter."""
_MIN_RADIUS_M, _RADIUS_STEP_M, _MAX_RADIUS_M = 4.0, 0.25, 40.0


SUBJECT_SHAPE: dict[str, float] = {"gender": 0.2, "weight": 0.7, "height": 0.4, "age_years": 40}
"""The default synthetic subject of the mpfb body: a heavier, shorter, mostly female
40-year-old, not MakeHuman's average (gender 0.5, 25 years, weight 0.5, height 0.5) from which
`mocap track` starts, so that a benchmark never scores the tracker on its own start."""
SUBJECT_CLOTHES_CM = 2.0
"""... in loose clothing (the tracker's body starts unclothed)."""


@dataclass(frozen=True, kw_only=True)
class SynthConfig:
    """Settings of `mocap synth`. Field help is the CLI's help."""

    bvh: Path = field(metadata={"help": "BVH clip that drives the body model (a CMU skeleton "
                                "is retargeted; a body-model BVH is read as it is)"})
    metres_per_unit: float | None = field(
        default=None,
        metadata={"help": "length unit of a CMU-skeleton BVH in metres (default: its naming's; "
                  "CMU: 0.0254/0.45, Daz-style: 0.01)"})
    cameras: int = field(default=4, metadata={"help": "number of cameras on the ring"})
    size: str = field(default="640x480", metadata={"help": "image size WIDTHxHEIGHT in pixels",
                                                   "metavar": "WxH"})
    frames: int | None = field(
        default=None, metadata={"help": "keep the first N frames after subsampling "
                                "(default: all)"})
    first_frame: int | None = field(
        default=None, metadata={"help": "first clip frame (default: the first frame of the "
                                "capture: past a reference pose in frame 0, such as the T-pose "
                                "many CMU conversions start with, and the frames that blend out "
                                "of it; else 0)", "metavar": "FRAME"})
    step: int | None = field(
        default=None, metadata={"help": "keep every K-th clip frame (default: the step that "
                                "comes closest to --fps)"})
    fps: float = field(default=30.0, metadata={"help": "frame rate to subsample the clip to "
                                               "when --step is not given"})
    radius_m: float | None = field(
        default=None, metadata={"help": "camera ring radius in metres (default: the smallest "
                                "from 4 m up that keeps the subject in every view)",
                                "flags": ("--radius",)})
    camera_height_m: float = field(
        default=1.5, metadata={"help": "camera height above the floor in metres",
                               "flags": ("--camera-height",)})
    fov_deg: float = field(default=50.0, metadata={"help": "horizontal field of view in degrees",
                                                   "flags": ("--fov",)})
    body: str = field(
        default="mpfb",
        metadata={"help": "body model plugin that the pose drives (see `mocap plugins`): its "
                  "surface is rendered and its joints are the truth"})
    shape: str | None = field(
        default=None,
        metadata={"help": "the mpfb subject's macro shape as KEY=VALUE,... of gender, age_years, "
                  "muscle, weight, height and proportions (default: "
                  + ",".join(f"{k}={v:g}" for k, v in SUBJECT_SHAPE.items())
                  + ": not MakeHuman's average, where the tracker starts)",
                  "metavar": "KEY=VALUE,..."})
    clothes_cm: float | None = field(
        default=None,
        metadata={"help": "the mpfb subject's loose clothing in centimetres, 0..10 (default: "
                  f"{SUBJECT_CLOTHES_CM:g}; the tracker starts unclothed)",
                  "flags": ("--clothes",), "metavar": "CM"})
    body_options: tuple[str, ...] = field(
        default=(), metadata={"help": "an option of the body model as KEY=VALUE (repeatable)",
                              "flags": ("--body-option",), "metavar": "KEY=VALUE"})
    renderer: str = field(default=DEFAULT_RENDERER,
                          metadata={"help": "silhouette renderer plugin (see `mocap plugins`)"})
    renderer_options: tuple[str, ...] = field(
        default=(), metadata={"help": "an option of the renderer as KEY=VALUE (repeatable)",
                              "flags": ("--renderer-option",), "metavar": "KEY=VALUE"})
    seed: int = field(default=0, metadata={"help": "seed of the silhouette noise"})
    clean: bool = field(default=False, metadata={"help": "no noise: write the exact renders"})
    videos: bool = field(
        default=False, metadata={"help": "also write WS/render/videos/<camera>.avi, the subject "
                                 "over a static textured scene, and WS/render/backgrounds/"
                                 "<camera>.png, the empty scene (for mocap init-video or "
                                 "mocap capture with --calibration WS/cameras.json)"})
    jitter_px: float = field(
        default=0.6, metadata={"help": "boundary jitter: RMS displacement of the outline, px"})
    jitter_scale_px: float = field(
        default=12.0, metadata={"help": "boundary jitter: correlation length along the "
                               "outline, px"})
    holes: float = field(
        default=2.0, metadata={"help": "mean number of holes per view and frame (Poisson)"})
    hole_radius_m: float = field(
        default=0.025, metadata={"help": "mean semi-axis of a hole on the body, metres"})
    shadow_length_m: float = field(
        default=0.4, metadata={"help": "length of the floor shadow ellipse, metres (0: none)"})
    shadow_width_m: float = field(
        default=0.2, metadata={"help": "width of the floor shadow ellipse, metres"})
    shadow_offset_m: float = field(
        default=0.05, metadata={"help": "distance from the feet to the shadow's centre, metres"})
    shadow_azimuth_deg: float = field(
        default=30.0, metadata={"help": "direction the shadow points to, degrees from world +Z "
                                "towards +X (a fixed light)"})


@dataclass(frozen=True)
class SynthSummary:
    """What `synthesize` made (or found up to date) in ``root``."""

    root: Path
    summary: dict[str, Any]
    reused: bool = False

    def lines(self) -> list[str]:
        s = self.summary
        root = self.root
        noise = s["noise"]
        if noise["clean"]:
            noise_text = "none (--clean): the exact renders"
        else:
            noise_text = (f"jitter {noise['jitter_px']:g} px, {noise['holes']:g} holes per view, "
                          f"shadow {noise['shadow_length_m']:g}x{noise['shadow_width_m']:g} m; "
                          f"IoU with the exact renders {noise['mean_iou']:.3f} (mean), "
                          f"{noise['min_iou']:.3f} (min)")
        lines = [
            f"synth       {s['frames']} frames x {s['cameras']} cameras {s['width']}x"
            f"{s['height']} at {s['frame_rate']:.4g} Hz from {Path(s['bvh']).name} (clip frames "
            f"{s['clip_frames'][0]}..{s['clip_frames'][-1]}, every {s['step']})",
            f"cameras     ring radius {s['radius_m']:.2f} m, height {s['camera_height_m']:.2f} m, "
            f"focal {s['focal_px']:.1f} px ({s['fov_deg']:g} deg wide); subject at least "
            f"{s['min_edge_margin_px']:.0f} px inside every image",
            f"noise       {noise_text}",
            f"truth       {root / 'gt' / 'joints.csv'}, {root / 'gt' / 'pose.json'} "
            f"({s['retarget']['method']}, {s['retarget']['mean_residual_mm']:.1f} mm RMS mean)",
            f"silhouettes {root / 'silhouettes'}/<camera>/<frame:06d>.png",
            *([f"videos      {root / s['videos']['videos']}/<camera>{VIDEO_SUFFIX}, "
               f"empty scene {root / s['videos']['backgrounds']}/<camera>.png"]
              if s.get("videos") else []),
            f"recording   {root / 'logs' / 'synth.rrd'}",
        ]
        if self.reused:
            lines.append("time        up to date (use --overwrite to redo)")
        else:
            t = s["seconds"]
            lines.append(f"time        poses {t['poses']:.1f} s, silhouettes "
                         f"{t['silhouettes']:.1f} s, total {t['total']:.1f} s")
        return lines


# ---------------------------------------------------------------------------------------------
# Settings and frames (pure)


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> (640, 480); a one-line UserError otherwise."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise UserError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480")
    width, height = int(match[1]), int(match[2])
    if not (16 <= width <= 16384 and 16 <= height <= 16384):
        raise UserError(f"--size {text}: width and height must be 16..16384 pixels")
    return width, height


def body_options(config: SynthConfig) -> tuple[str, ...]:
    """The body plugin's options: for mpfb, `SUBJECT_SHAPE` and `SUBJECT_CLOTHES_CM` unless
    --shape and --clothes say otherwise, then --body-option; other bodies take
    --body-option alone (--shape or --clothes for them is a UserError)."""
    if config.body != "mpfb":
        if config.shape is not None or config.clothes_cm is not None:
            raise UserError(f"--shape and --clothes shape the mpfb body, not {config.body!r} "
                            f"(use --body-option KEY=VALUE)")
        return tuple(config.body_options)
    shape: dict[str, object] = dict(SUBJECT_SHAPE)
    if config.shape is not None:
        shape = {}
        for item in filter(None, (t.strip() for t in config.shape.split(","))):
            key, sep, value = item.partition("=")
            if not sep or not key.strip():
                raise UserError(f"--shape {config.shape!r}: expected KEY=VALUE,... "
                                f"(e.g. gender=0.2,weight=0.7)")
            shape[key.strip()] = value.strip()
    clothes = SUBJECT_CLOTHES_CM if config.clothes_cm is None else config.clothes_cm
    return (*(f"{k}={v:g}" if isinstance(v, float | int) else f"{k}={v}"
              for k, v in shape.items()), f"clothes_cm={clothes:g}", *config.body_options)


def _check_config(config: SynthConfig) -> None:
    if config.cameras < 1:
        raise UserError(f"--cameras {config.cameras}: need at least 1 camera")
    if not 1.0 <= config.fov_deg <= 170.0:
        raise UserError(f"--fov {config.fov_deg}: expected 1..170 degrees")
    if config.radius_m is not None and not config.radius_m > 0:
        raise UserError(f"--radius {config.radius_m}: must be positive")
    if not config.fps > 0 or not (config.metres_per_unit is None or config.metres_per_unit > 0):
        raise UserError("--fps and --metres-per-unit must be positive")
    negative = [f.name for f in dataclasses.fields(config)
                if f.name in ("jitter_px", "jitter_scale_px", "holes", "hole_radius_m",
                              "shadow_length_m", "shadow_width_m", "shadow_offset_m",
                              "seed")
                and not getattr(config, f.name) >= 0]  # fmt: skip
    if negative:
        raise UserError(f"--{negative[0].replace('_', '-')} must be 0 or more")


def select_clip_frames(num_frames: int, clip_fps: float, *, step: int | None, fps: float,
                       frames: int | None, first: int = 0) -> tuple[np.ndarray, int]:  # fmt: skip
    """Clip frame indices (N,) of the sequence and the step between them.

    The sequence starts at clip frame ``first``; ``step`` defaults to ``round(clip_fps / fps)``
    (at least 1); ``frames`` takes the first N of the subsampled frames (default all; out of
    range is a UserError).
    """
    if step is not None and step < 1:
        raise UserError(f"--step {step}: must be 1 or more")
    if not 0 <= first < num_frames:
        raise UserError(f"--first-frame {first}: the clip has frames 0..{num_frames - 1}")
    step = step if step is not None else max(1, round(clip_fps / fps))
    available = len(range(first, num_frames, step))
    if frames is None:
        frames = available
    elif not 1 <= frames <= available:
        raise UserError(f"--frames {frames}: the clip has {available} frames from frame {first} "
                        f"at step {step} ({num_frames} at {clip_fps:.4g} Hz); choose "
                        f"1..{available}")
    return first + np.arange(frames) * step, step


# ---------------------------------------------------------------------------------------------
# Cameras (pure)


def focal_for_fov(width: int, fov_deg: float) -> float:
    """Focal length (px) of a ``width``-pixel image with horizontal field of view ``fov_deg``."""
    return width / 2.0 / math.tan(math.radians(fov_deg) / 2.0)


def edge_margins_px(cameras: list[Camera], points_in_world: np.ndarray) -> np.ndarray:
    """(C,) least distance in pixels from the projections of (N, 3) points to each image's edge;
    negative when a point falls outside, -inf when one is behind the camera."""
    margins = np.empty(len(cameras))
    for i, camera in enumerate(cameras):
        uv, depth = camera.project(points_in_world)
        if not (depth > 0).all():
            margins[i] = -np.inf
            continue
        margins[i] = min(uv[:, 0].min(), camera.width - uv[:, 0].max(),
                         uv[:, 1].min(), camera.height - uv[:, 1].max())
    return margins


def place_cameras(vertices_in_world: np.ndarray, pelvis_in_world: np.ndarray, floor_y: float,
                  subject_height_m: float, size: tuple[int, int], config: SynthConfig,
                  ) -> tuple[list[Camera], float, float]:  # fmt: skip
    """The camera ring for a sequence: cameras, radius (m) and least edge margin (px).

    vertices_in_world: (T, V, 3) posed mesh of every frame; pelvis_in_world: (T, 3). The
    target is the mean pelvis position at mid-height above the floor.
    """
    width, height = size
    focal_px = focal_for_fov(width, config.fov_deg)
    centre = pelvis_in_world.mean(axis=0)
    target = np.array([centre[0], floor_y + subject_height_m / 2.0, centre[2]])
    points = vertices_in_world.reshape(-1, 3)
    needed = _EDGE_MARGIN_PX + (0.0 if config.clean else 2.0 * config.jitter_px)
    if config.radius_m is not None:
        radii = [config.radius_m]
    else:
        radii = list(np.arange(_MIN_RADIUS_M, _MAX_RADIUS_M + 1e-9, _RADIUS_STEP_M))
    for radius in radii:
        cameras = ring_cameras(config.cameras, float(radius), floor_y + config.camera_height_m,
                               target, width, height, focal_px)
        margins = edge_margins_px(cameras, points)
        if margins.min() >= needed:
            return cameras, float(radius), float(margins.min())
    worst = int(np.argmin(margins))
    hint = ("give a larger --radius or --fov, or omit --radius" if config.radius_m is not None
            else "give a larger --fov or fewer --frames")
    raise UserError(f"the subject leaves the view of {cameras[worst].name} (edge margin "
                    f"{margins[worst]:.0f} px at ring radius {radii[-1]:g} m); {hint}")


# ---------------------------------------------------------------------------------------------
# Silhouette noise (pure)


def shadow_polygon_in_world(feet_in_world: np.ndarray, floor_y: float, config: SynthConfig,
                            n_points: int = 48) -> np.ndarray:  # fmt: skip
    """(n_points, 3) outline of the shadow ellipse on the floor: centred ``shadow_offset_m``
    from the midpoint of the feet (ankles, (2, 3)) along the light azimuth, its long axis
    along that azimuth."""
    azimuth = math.radians(config.shadow_azimuth_deg)
    along = np.array([math.sin(azimuth), 0.0, math.cos(azimuth)])
    across = np.array([along[2], 0.0, -along[0]])
    feet = np.asarray(feet_in_world, dtype=float).mean(axis=0)
    centre = np.array([feet[0], floor_y, feet[2]]) + config.shadow_offset_m * along
    angles = 2 * np.pi * np.arange(n_points) / n_points
    return (centre + np.outer(np.cos(angles), along) * config.shadow_length_m / 2
            + np.outer(np.sin(angles), across) * config.shadow_width_m / 2)


def fill_polygon(mask: np.ndarray, uv: np.ndarray) -> None:
    """Set the pixels of ``mask`` (H, W) bool whose centres lie in the polygon ``uv`` (N, 2)."""
    if not np.isfinite(uv).all():
        return
    # OpenCV puts pixel centres at integers, ours at +0.5; 4 fractional bits keep sub-pixels.
    points = np.round((uv - 0.5) * 16).astype(np.int32)
    canvas = mask.astype(np.uint8)
    cv2.fillPoly(canvas, [points], 1, lineType=cv2.LINE_8, shift=4)
    mask |= canvas.astype(bool)


def _box(mask: np.ndarray, pad: int) -> tuple[slice, slice] | None:
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not len(rows):
        return None
    h, w = mask.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)))


def jitter_boundary(mask: np.ndarray, amplitude_px: float, scale_px: float,
                    rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """``mask`` (H, W) bool resampled through a smooth random displacement field of RMS
    ``amplitude_px`` per axis and correlation length ``scale_px``: the outline moves by about
    the amplitude, and the field being smooth, no specks or tears appear."""
    box = _box(mask, pad=int(math.ceil(4 * amplitude_px)) + 2)
    if box is None or amplitude_px <= 0:
        return mask.copy()
    roi = mask[box].astype(np.float32)
    h, w = roi.shape
    scale = max(scale_px, 1.0)
    coarse = rng.standard_normal((2, int(math.ceil(h / scale)) + 2,
                                  int(math.ceil(w / scale)) + 2)).astype(np.float32)
    field_px = np.stack([cv2.resize(c, (w, h), interpolation=cv2.INTER_CUBIC) for c in coarse])
    field_px *= amplitude_px / max(float(field_px.std()), 1e-6)
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    warped = cv2.remap(roi, xs + field_px[0], ys + field_px[1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    out = mask.copy()
    out[box] = warped >= 0.5
    return out


def hole_mask(body: np.ndarray, mean_count: float, mean_radius_px: float, keep_out_px: float,
              rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """(H, W) bool of a Poisson(``mean_count``) number of ellipses inside ``body``: semi-axes
    0.5-1.5 times ``mean_radius_px``, random orientation, each centred where the body extends
    at least its long semi-axis + ``keep_out_px`` around it (so holes never open the outline).
    """
    holes = np.zeros_like(body, dtype=bool)
    count = int(rng.poisson(mean_count)) if mean_count > 0 else 0
    box = _box(body, pad=1)
    if count == 0 or box is None or mean_radius_px <= 0:
        return holes
    inside = cv2.distanceTransform(body[box].astype(np.uint8), cv2.DIST_L2, 5)
    canvas = np.zeros(inside.shape, np.uint8)
    for _ in range(count):
        axes = mean_radius_px * rng.uniform(0.5, 1.5, size=2)
        rows, cols = np.nonzero(inside > axes.max() + keep_out_px)
        if not len(rows):
            continue
        k = rng.integers(len(rows))
        centre = (int(round(cols[k] * 16)), int(round(rows[k] * 16)))  # pixel centres: integers
        cv2.ellipse(canvas, centre, (int(round(axes[0] * 16)), int(round(axes[1] * 16))),
                    float(rng.uniform(0, 180)), 0, 360, 1, thickness=-1, lineType=cv2.LINE_8,
                    shift=4)
    holes[box] = canvas.astype(bool)
    return holes


def noisy_silhouette(clean: np.ndarray, camera: Camera, shadow_in_world: np.ndarray | None,
                     px_per_m: float, config: SynthConfig,
                     rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """The exact mask ``clean`` (H, W) bool as background subtraction would give it: shadow
    added, outline jittered, holes cut (module docstring). ``px_per_m``: image scale at the
    body (focal / depth of the pelvis)."""
    mask = clean.copy()
    if shadow_in_world is not None:
        uv, depth = camera.project(shadow_in_world)
        if (depth > 0).all():
            fill_polygon(mask, uv)
    mask = jitter_boundary(mask, config.jitter_px, config.jitter_scale_px, rng)
    holes = hole_mask(clean, config.holes, config.hole_radius_m * px_per_m,
                      2.0 + 3.0 * config.jitter_px, rng)
    return mask & ~holes


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else 1.0


# ---------------------------------------------------------------------------------------------
# The step (disk)


def _read_motion(path: Path) -> Motion:
    try:
        return read_bvh(path)
    except OSError as exc:
        raise UserError(f"cannot read {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise UserError(" ".join(str(exc).split()) or f"{path}: not a BVH file") from None


def sequence_poses(motion: Motion, clip_frames: np.ndarray, config: SynthConfig,
                   ) -> tuple[list[Pose], BodyShape, np.ndarray, str]:  # fmt: skip
    """Poses (one per clip frame), shape, per-frame residuals (m) and the method used."""
    from tracking.body.motion import is_body_skeleton, poses_from_motion
    from tracking.body.retarget import cmu_naming, retarget

    if is_body_skeleton(motion):
        poses, shape = poses_from_motion(motion)
        return [poses[i] for i in clip_frames], shape, np.zeros(len(clip_frames)), "body BVH"
    try:
        cmu_naming(motion)
    except ValueError as exc:
        raise UserError(f"{config.bvh}: neither a body-model BVH nor {exc}") from None
    try:
        result = retarget(motion, config.metres_per_unit, frames=clip_frames)
    except (KeyError, ValueError) as exc:
        raise UserError(f"{config.bvh}: neither a CMU skeleton nor a body-model BVH "
                        f"({' '.join(str(exc).split())})") from None
    return result.poses, result.shape, result.residual_rms_m, "retargeted CMU"


def _config_record(config: SynthConfig) -> dict[str, Any]:
    record = dataclasses.asdict(config)
    record["bvh"] = str(config.bvh.resolve())
    record["renderer_options"] = list(config.renderer_options)
    record["body_options"] = list(body_options(config))
    return record


def synthesize(ws_root: Path | str, config: SynthConfig, *,
               overwrite: bool = False) -> SynthSummary:  # fmt: skip
    """Render the sequence into the video workspace ``ws_root`` (layout: module docstring).

    Skipped when the workspace holds the result of the same config and clip ("synth" in
    run.json), unless ``overwrite``. Every output is written to a temporary sibling and renamed;
    the recording, renamed last, was removed first, so an interrupted run is never taken as
    complete.
    """
    from plugins.registry import create
    from recon.recording import (
        log_camera_image,
        log_silhouette,
        log_silhouette_context,
        log_skeleton_frames,
        log_y_up_world,
        step_recording,
    )

    ws = Workspace(ws_root)
    if ws.root.exists() and not ws.root.is_dir():
        raise UserError(f"workspace path {ws.root} is a file, not a folder")
    if ws.videos_dir.exists():
        raise UserError(f"{ws.root} holds real videos ({ws.videos_dir}); synthesise into a new "
                        "workspace")
    _check_config(config)
    size = parse_size(config.size)
    if not config.bvh.is_file():
        raise UserError(f"BVH file {config.bvh} does not exist")
    config_record = _config_record(config)
    # The clip's content, not its path, identifies the input.
    fp = fingerprint(STEP, {k: v for k, v in config_record.items() if k != "bvh"},
                     file_digest(config.bvh))
    recording_path = ws.logs_dir / f"{STEP}.rrd"
    render_dir = ws.root / RENDER_DIR
    outputs = (ws.cameras_path, ws.silhouettes_dir, ws.gt_dir / "joints.csv",
               ws.gt_dir / "pose.json", recording_path, *([render_dir] if config.videos else []))
    if done := ws.reusable(STEP, fp, *outputs, overwrite=overwrite):
        return SynthSummary(ws.root, done.summary, reused=True)

    motion = _read_motion(config.bvh)
    first = (leading_reference_frames(motion) if config.first_frame is None
             else config.first_frame)
    clip_frames, step = select_clip_frames(motion.num_frames, motion.fps, step=config.step,
                                           fps=config.fps, frames=config.frames, first=first)
    frame_rate = motion.fps / step
    renderer = create("renderer", config.renderer, config.renderer_options)
    body = create("body", config.body, body_options(config))
    with Timer() as total:
        with Timer() as t_poses:
            poses, shape, residual_m, method = sequence_poses(motion, clip_frames, config)
        posed = [body.posed(p, shape) for p in poses]
        faces = posed[0].faces
        vertices = np.stack([b.vertices for b in posed])  # (T, V, 3)
        joints = np.stack([b.joints for b in posed])  # (T, 16, 3)
        floor_y = float(vertices[..., 1].min())
        pelvis = joints[:, NODE_NAMES.index("pelvis")]
        cameras, radius_m, margin_px = place_cameras(vertices, pelvis, floor_y, shape.height,
                                                     size, config)
        feet = joints[:, [NODE_NAMES.index("l_ankle"), NODE_NAMES.index("r_ankle")]]
        with_shadow = not config.clean and config.shadow_length_m > 0 and config.shadow_width_m > 0

        ws.root.mkdir(parents=True, exist_ok=True)
        recording_path.unlink(missing_ok=True)
        frames = np.arange(len(poses))
        times_s = frames / frame_rate
        ious: list[float] = []
        with Timer() as t_sil, contextlib.ExitStack() as stack:
            # Entered first, renamed last: the recording marks a complete run (see docstring).
            rec = stack.enter_context(step_recording(ws.log_path(STEP), STEP))
            sil_dir = stack.enter_context(atomic_output(ws.silhouettes_dir))
            gt_dir = stack.enter_context(atomic_output(ws.gt_dir))
            sil_dir.mkdir()
            gt_dir.mkdir()
            videos = (stack.enter_context(SyntheticVideos(
                stack.enter_context(atomic_output(render_dir)), cameras, frame_rate,
                config.seed)) if config.videos else None)
            log_y_up_world(rec)
            log_silhouette_context(rec, "world/cameras")
            for camera in cameras:
                (sil_dir / camera.name).mkdir()
                log_camera_image(rec, image_name=camera.name, image_path=None, K=camera.K,
                                 width=camera.width, height=camera.height,
                                 cam_from_world=camera.cam_from_world)
            for k in frames:
                shadow = (shadow_polygon_in_world(feet[k], floor_y, config) if with_shadow
                          else None)
                for v, camera in enumerate(cameras):
                    mask = np.asarray(renderer.render(vertices[k], faces, camera), bool)
                    if videos is not None:
                        videos.add(v, mask)
                    if not config.clean:
                        depth = float(camera.project(pelvis[k][None])[1][0])
                        rng = np.random.default_rng([config.seed, int(k), v])
                        noisy = noisy_silhouette(mask, camera, shadow, camera.K[0, 0] / depth,
                                                 config, rng)
                        ious.append(iou(noisy, mask))
                        mask = noisy
                    path = sil_dir / camera.name / f"{k:06d}.png"
                    if not cv2.imwrite(str(path), mask.astype(np.uint8) * 255):
                        raise UserError(f"could not write {path}")
                    log_silhouette(rec, f"world/cameras/{camera.name}/image", mask, int(k),
                                   float(times_s[k]))
            log_skeleton_frames(rec, "world/gt", frames, times_s, joints, BONES)
            _write_truth(gt_dir, poses, shape, joints, clip_frames, frame_rate, config,
                         body.subject_record())
            write_cameras_json(ws.cameras_path, cameras)
        if videos is None and render_dir.exists():  # videos of an earlier run's settings
            shutil.rmtree(render_dir)

    noise = {"clean": config.clean, "jitter_px": config.jitter_px, "holes": config.holes,
             "shadow_length_m": config.shadow_length_m if with_shadow else 0.0,
             "shadow_width_m": config.shadow_width_m if with_shadow else 0.0,
             "mean_iou": float(np.mean(ious)) if ious else 1.0,
             "min_iou": float(np.min(ious)) if ious else 1.0}
    summary = {
        "bvh": config_record["bvh"], "frames": len(poses), "cameras": len(cameras),
        "width": size[0], "height": size[1], "frame_rate": frame_rate, "step": step,
        "clip_frames": [int(clip_frames[0]), int(clip_frames[-1])],
        "radius_m": radius_m, "camera_height_m": config.camera_height_m,
        "focal_px": float(cameras[0].K[0, 0]), "fov_deg": config.fov_deg,
        "floor_y_m": floor_y, "min_edge_margin_px": margin_px, "noise": noise,
        "retarget": {"method": method, "mean_residual_mm": float(residual_m.mean() * 1000),
                     "max_residual_mm": float(residual_m.max() * 1000)},
        "subject_height_m": shape.height,
        "videos": videos.summary() if videos is not None else None,
        "seconds": {"poses": t_poses.seconds, "silhouettes": t_sil.seconds,
                    "total": total.seconds},
    }
    ws.record_step(STEP, fp, outputs=outputs, config=config_record, seconds=total.seconds,
                   summary=summary)
    return SynthSummary(ws.root, summary)


def _write_truth(gt_dir: Path, poses: list[Pose], shape: BodyShape, joints: np.ndarray,
                 clip_frames: np.ndarray, frame_rate: float, config: SynthConfig,
                 body_record: dict[str, Any]) -> None:  # fmt: skip
    """gt/joints.csv (micrometre precision) and gt/pose.json (exact floats)."""
    lines = ["frame,joint,x,y,z"]
    for k, frame_joints in enumerate(joints):
        lines += [f"{k},{name},{x:.6f},{y:.6f},{z:.6f}"
                  for name, (x, y, z) in zip(NODE_NAMES, frame_joints, strict=True)]
    (gt_dir / "joints.csv").write_text("\n".join(lines) + "\n")
    write_json_atomic(gt_dir / "pose.json", {
        "frame_rate": frame_rate,
        "shape": dataclasses.asdict(shape),
        "body": {**body_record, "options": list(body_options(config))},
        "source": {"bvh": str(config.bvh.resolve()), "clip_frames": [int(f) for f in clip_frames]},
        "frames": [{"frame": k, "clip_frame": int(f), "params": [float(v) for v in p.params]}
                   for k, (f, p) in enumerate(zip(clip_frames, poses, strict=True))],
    })
