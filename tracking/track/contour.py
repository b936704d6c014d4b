"""Joint refinement of the pose against the silhouette outlines (damped Gauss-Newton).

The hierarchy of thesis 6.2.5 (`tracking.track.tracker`) solves one part of the body at a time with
the rest held still, so a parameter the silhouettes hardly constrain alone (pelvis pitch
against hip flexion and spine bend; pelvis yaw against limb twists) drifts and the stages that
follow compensate. This module moves all parameters together, in the spirit of contour-based
trackers (Rosenhahn et al.; Gall et al.): per view,

* model to image: the occluding-contour vertices of the model (surface normal nearly
  perpendicular to the viewing ray, and projected on the outline of the rendered model
  silhouette) should lie on the image silhouette's outline: residual = signed distance of
  their projection to the image outline (positive outside the image silhouette);
* image to model: every point of the image silhouette's outer outline should have a model
  contour vertex on it: residual = 2-D offset to the nearest projected contour vertex.

Residuals are in pixels of the pyramid level used, weighted by a Cauchy loss, and derivatives
are analytic (`tracking.body.model.pose_derivative_axes`; the projection's derivative ignores lens
distortion, the projection itself does not). Steps are Levenberg-Marquardt steps accepted
only when the XOR energy (`tracking.track.energy`, the tracker's objective) goes down, so the
refinement can never make a frame worse in the thesis' own measure.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from recon.cameras import Camera
from tracking.body.model import (
    PARAM_MOVES_NODE,
    POSE_LAYOUT,
    SEARCH_LOWER_LIMITS,
    SEARCH_UPPER_LIMITS,
    Pose,
    TrackedModel,
    pose_derivative_axes,
)


@dataclass(frozen=True, kw_only=True)
class ContourConfig:
    iterations: int = field(default=8, metadata={"help": "Gauss-Newton iterations"})
    robust_px: float = field(
        default=3.0, metadata={"help": "Cauchy scale of the outline residuals, pixels"}
    )
    grazing: float = field(
        default=0.35,
        metadata={"help": "a vertex is an occluding-contour candidate when |normal . ray| is "
                  "below this"},
    )  # fmt: skip
    hole_fraction: float = field(
        default=0.02,
        metadata={"help": "holes in an image silhouette smaller than this fraction of its "
                  "area are filled before its outline is taken"},
    )  # fmt: skip
    outline_step_px: int = field(
        default=2, metadata={"help": "take every n-th pixel of the image outlines"}
    )


class _ViewTarget:
    """What one view's image silhouette offers: its signed distance field (pixels, positive
    outside), the field's gradient, and the points of its outer outline."""

    def __init__(self, camera: Camera, mask: np.ndarray, config: ContourConfig,
                 known: np.ndarray | None = None) -> None:  # fmt: skip
        self.camera = camera
        self.known = known  # pixels whose label counts (None: all)
        mask = np.asarray(mask, dtype=np.uint8)
        contours, hierarchy = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
        filled = mask.copy()
        area = max(int(mask.sum()), 1)
        outer = []
        if hierarchy is not None:
            for contour, (_, _, _, parent) in zip(contours, hierarchy[0], strict=True):
                if parent >= 0:  # a hole: fill it when small (silhouette noise)
                    if cv2.contourArea(contour) < config.hole_fraction * area:
                        cv2.drawContours(filled, [contour], -1, 1, -1)
                else:
                    outer.append(contour[:, 0, :])
        self.mask = filled.astype(bool)
        inside = cv2.distanceTransform(filled, cv2.DIST_L2, 5)
        outside = cv2.distanceTransform(1 - filled, cv2.DIST_L2, 5)
        # Half a pixel each side: the outline lies between a foreground and a background pixel.
        sdf = np.where(filled > 0, 0.5 - inside, outside - 0.5).astype(np.float32)
        self.sdf = sdf
        self.grad_u = cv2.Sobel(sdf, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        self.grad_v = cv2.Sobel(sdf, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        points = (np.concatenate(outer)[:: max(config.outline_step_px, 1)].astype(float) + 0.5
                  if outer else np.zeros((0, 2)))  # fmt: skip
        if known is not None and len(points):
            # An outline along unknown pixels is where the view could not tell, not an edge.
            pixel = np.floor(points).astype(int)
            points = points[known[pixel[:, 1], pixel[:, 0]]]
        self.outline = points  # (N, 2) pixel coordinates (centres at +0.5)


class _Posed:
    """A model in a pose: world vertices and normals, and the derivatives of the vertices with
    respect to the pose parameters `free` (and to any `extra` columns, e.g. shape scales).

    A vertex moved by parameter k with weight w (its skinning weight on the nodes k moves:
    1 or 0 for the rigid model) changes at w * axis_k x (v - pivot_k): exact for rigid
    segments, and for a skinned vertex the blend of its bones' motions to first order in the
    spread of their positions. The pivots are our forward kinematics of `model.shape`.
    """

    def __init__(self, model: TrackedModel, x: np.ndarray, free: np.ndarray,
                 extra: np.ndarray | None = None) -> None:  # fmt: skip
        _, axes, pivots = pose_derivative_axes(Pose(x), model.shape)
        self.verts, self.normals = model.posed_surface(Pose(x))
        self.node_weights = model.node_weights  # (V, 16)
        self.free = np.asarray(free)
        self.moved_nodes = PARAM_MOVES_NODE[self.free].astype(float)  # (P, 16)
        # d v / d p_k = axis_k x v - axis_k x pivot_k for a rotation, axis_k for a
        # translation: (P, 3, 3) cross-product matrices (0 for a translation) and (3, P)
        # constant terms, so that the derivatives of many vertices are one product.
        rotation = _ROTATION[self.free]
        a = np.where(rotation[:, None], axes[self.free], 0.0)
        skew = np.zeros((len(self.free), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -a[:, 2], a[:, 1], -a[:, 0]
        self.skew = skew - skew.transpose(0, 2, 1)
        self.constant = np.where(rotation[:, None], -np.einsum("kij,kj->ki", self.skew,
                                                               pivots[self.free]),
                                 axes[self.free]).T  # fmt: skip
        self.extra = extra  # (V, 3, E) or None

    @property
    def columns(self) -> int:
        return len(self.free) + (0 if self.extra is None else self.extra.shape[2])

    def derivatives(self, idx: np.ndarray) -> np.ndarray:
        """(n, 3, columns) derivatives of the vertices idx: extra columns first, then pose."""
        e = 0 if self.extra is None else self.extra.shape[2]
        out = np.empty((len(idx), 3, self.columns))
        if e:
            out[:, :, :e] = self.extra[idx]
        weight = self.node_weights[idx] @ self.moved_nodes.T  # (n, P)
        out[:, :, e:] = (np.einsum("kij,nj->nik", self.skew, self.verts[idx])
                         + self.constant) * weight[:, None, :]  # fmt: skip
        return out


_ROTATION = np.array([p.kind == "rotation" for p in POSE_LAYOUT])


def _outline_system(posed: _Posed, cameras: Sequence[Camera], targets: Sequence[_ViewTarget],
                    model_masks: Sequence[np.ndarray], config: ContourConfig,
                    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Gauss-Newton normal equations (A, b) of one frame's outline residuals (module
    docstring) over the columns of `posed`; each view's rows compiled
    (`tracking.track.outline_kernel`)."""
    from tracking.track.outline_kernel import contour_vertices, outline_rows

    n = posed.columns
    a, b = np.zeros((n, n)), np.zeros(n)
    scale = config.robust_px
    extra = posed.extra if posed.extra is not None else np.zeros((len(posed.verts), 3, 0))
    no_mask = np.zeros((0, 0), bool)
    for cam, target, model_mask in zip(cameras, targets, model_masks, strict=True):
        uv, depth = cam.project(posed.verts)
        # Contour vertices: on the outline of the model's own silhouette, i.e. with some
        # background pixel next to them (the rest are hidden behind other parts).
        idx = contour_vertices(posed.verts, posed.normals, cam.center_in_world, uv, depth,
                               model_mask, no_mask if target.known is None else target.known,
                               config.grazing)  # fmt: skip
        if len(idx) == 0:
            continue
        jac, sdf, jac2, res, dist = outline_rows(
            idx, posed.verts, uv, cam.R, cam.t, cam.K[0, 0], cam.K[1, 1], extra,
            posed.node_weights, posed.moved_nodes, posed.skew, posed.constant, target.sdf,
            target.grad_u, target.grad_v, target.outline)
        # Model -> image: signed distance of each contour point to the image outline.
        weight = 1.0 / (1.0 + (sdf / scale) ** 2)
        a += (jac * weight[:, None]).T @ jac
        b += (jac * weight[:, None]).T @ sdf
        # Image -> model: each outline point to its nearest projected contour point; both
        # pixel coordinates of each outline point are rows of one system.
        if len(target.outline):
            weighted = jac2 * np.repeat(1.0 / (1.0 + (dist / scale) ** 2), 2)[:, None]
            a += weighted.T @ jac2
            b += weighted.T @ res
    return a, b


def _damped_steps(a: np.ndarray, b: np.ndarray, lam: float) -> np.ndarray | None:
    """Levenberg-Marquardt step -(A + lam diag(A))^-1 b, or None when singular."""
    diag = np.diag(a) + 1e-9 * max(np.trace(a), 1e-12) / len(a)
    try:
        return -np.linalg.solve(a + lam * np.diag(diag) + 1e-12 * np.eye(len(a)), b)
    except np.linalg.LinAlgError:
        return None


def _accepted_step(a: np.ndarray, b: np.ndarray, z: np.ndarray, bounds: tuple[np.ndarray,
                   np.ndarray], lam: float, best: float, cost: Callable[[np.ndarray], float],
                   ) -> tuple[np.ndarray | None, float, float, int]:  # fmt: skip
    """Up to three damped steps from z within bounds, the damping raised tenfold after each
    rejected one: (the first whose cost is below `best`, or None; its cost; the damping for
    the next iteration; the number of cost evaluations)."""
    evaluations = 0
    for _attempt in range(3):
        step = _damped_steps(a, b, lam)
        if step is None:
            lam *= 10
            continue
        y = np.clip(z + step, *bounds)
        e = cost(y)
        evaluations += 1
        if e < best:
            return y, e, max(lam / 3, 1e-4), evaluations
        lam *= 10
    return None, best, lam, evaluations


class _FrameOutlines:
    """One frame's image outlines at one pyramid level."""

    def __init__(self, cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                 config: ContourConfig, known: Sequence[np.ndarray | None] | None = None,
                 ) -> None:  # fmt: skip
        self.cameras = list(cameras)
        known = list(known) if known is not None else [None] * len(self.cameras)
        self.targets = [_ViewTarget(c, m, config, k) for c, m, k in
                        zip(self.cameras, masks, known, strict=True)]  # fmt: skip

    def system(self, model: TrackedModel, x: np.ndarray, free: np.ndarray, renderer: object,
               config: ContourConfig,
               extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        from tracking.track.render import render_views

        posed = _Posed(model, x, free, extra)
        masks = render_views(renderer, posed.verts, model.faces, self.cameras)
        return _outline_system(posed, self.cameras, self.targets, masks, config)


class ContourRefiner:
    """Refines poses of `model` against one frame's silhouettes (`masks`, one per camera, the
    cameras of the pyramid level to use; `known`: per view, None or the pixels that count)."""

    def __init__(self, model: TrackedModel, cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                 renderer: object, config: ContourConfig | None = None,
                 known: Sequence[np.ndarray | None] | None = None) -> None:  # fmt: skip
        self.model, self.renderer = model, renderer
        self.config = config or ContourConfig()
        self.frame = _FrameOutlines(cameras, masks, self.config, known)

    def refine(self, x: np.ndarray, free: Sequence[int], energy: Callable[[np.ndarray], float],
               prior: tuple[np.ndarray, np.ndarray] | None = None,
               ) -> tuple[np.ndarray, float, int]:  # fmt: skip
        """Levenberg-Marquardt on the outline residuals over the `free` parameters, each step
        accepted only when `energy` (of a full parameter vector) decreases.

        prior: (centre, weight) per parameter, adding weight (x - centre)^2 (squared pixels)
        to the least-squares cost: a pull on directions the outlines do not fix.
        Returns the parameters, their energy and the number of energy evaluations.
        """
        free = np.asarray(free)
        x = np.clip(np.asarray(x, float).copy(), SEARCH_LOWER_LIMITS, SEARCH_UPPER_LIMITS)
        best = energy(x)
        evaluations = 1
        lam = 1e-2

        def cost(values: np.ndarray) -> float:
            y = x.copy()
            y[free] = values
            return energy(y)

        for _ in range(self.config.iterations):
            a, b = self.frame.system(self.model, x, free, self.renderer, self.config)
            if prior is not None:
                centre, weight = prior
                a = a + np.diag(weight[free])
                b = b + weight[free] * (x[free] - centre[free])
            values, best, lam, n = _accepted_step(
                a, b, x[free], (SEARCH_LOWER_LIMITS[free], SEARCH_UPPER_LIMITS[free]), lam,
                best, cost)  # fmt: skip
            evaluations += n
            if values is None:
                break
            x = x.copy()
            x[free] = values
        return x, best, evaluations


def refine_shape(base: TrackedModel, frames: Sequence[tuple[Sequence[Camera],
                 Sequence[np.ndarray], Sequence[np.ndarray | None]]],
                 poses: Sequence[np.ndarray], renderer: object,
                 energy: Callable[[TrackedModel, Sequence[np.ndarray]], float],
                 config: ContourConfig | None = None, free: Sequence[int] | None = None,
                 ) -> tuple[TrackedModel, list[np.ndarray], float]:  # fmt: skip
    """The shape parameters of `base` (`TrackedModel.shape_parameters`: the segment scales of
    `tracking.body.model.SHAPE_GROUPS`, or a skinned body's macro modifiers) and the poses of
    several frames together against their outlines; frames: (cameras, masks, known) per frame
    (known: per view, None or the pixels that count).

    energy(model, poses): the XOR energy summed over the frames, which every accepted step
    lowers. Shape derivatives are forward differences of the vertices (the parameters' own
    step). free: the pose parameters refined (default: all; the others keep their values).
    Returns the reshaped model, the poses and their energy.
    """
    cfg = config or ContourConfig()
    outlines = [_FrameOutlines(c, m, cfg, k) for c, m, k in frames]
    params = base.shape_parameters()
    values = np.asarray(params.values, float).copy()
    poses = [np.clip(np.asarray(x, float), SEARCH_LOWER_LIMITS, SEARCH_UPPER_LIMITS)
             for x in poses]
    n_shape, n_pose = len(values), len(SEARCH_LOWER_LIMITS)
    free = np.arange(n_pose) if free is None else np.asarray(free)
    lo = np.concatenate([params.lower, np.tile(SEARCH_LOWER_LIMITS, len(poses))])
    hi = np.concatenate([params.upper, np.tile(SEARCH_UPPER_LIMITS, len(poses))])
    h = params.step

    def split(z: np.ndarray) -> tuple[TrackedModel, list[np.ndarray]]:
        """The model of z's shape parameters and z's poses."""
        return (base.reshaped(z[:n_shape]),
                [z[n_shape + k * n_pose:n_shape + (k + 1) * n_pose] for k in range(len(poses))])

    model = base.reshaped(values)
    best = energy(model, poses)
    lam = 1e-2
    size = n_shape + n_pose * len(poses)
    for _ in range(cfg.iterations):
        # A forward step past an upper bound goes backwards instead.
        signs = np.where(values + h <= params.upper, 1.0, -1.0)
        bumped = [base.reshaped(values + signs[i] * h * np.eye(n_shape)[i])
                  for i in range(n_shape)]  # fmt: skip
        a, b = np.zeros((size, size)), np.zeros(size)
        for k, (frame, x) in enumerate(zip(outlines, poses, strict=True)):
            verts = model.posed_vertices(Pose(x))
            extra = np.stack([(m.posed_vertices(Pose(x)) - verts) / (s * h)
                              for m, s in zip(bumped, signs, strict=True)], -1)  # fmt: skip
            ak, bk = frame.system(model, x, free, renderer, cfg, extra)
            rows = np.r_[np.arange(n_shape), n_shape + k * n_pose + free]
            a[np.ix_(rows, rows)] += ak
            b[rows] += bk
        accepted, best, lam, _ = _accepted_step(a, b, np.concatenate([values, *poses]),
                                                (lo, hi), lam, best,
                                                lambda z: energy(*split(z)))  # fmt: skip
        if accepted is None:
            break
        model, poses = split(accepted)
        values = accepted[:n_shape]
    return model, poses, best
