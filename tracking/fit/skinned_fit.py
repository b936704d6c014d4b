"""Refine a body fit with a skinned body model (a ``mocap.body`` plugin's `TrackedModel`, e.g.
MakeHuman's ``mpfb``): its pose and its own shape parameters against the point cloud.

The superquadric fit (`tracking.fit.body_fit.fit_body`) is the start: its search is what finds
the orientation and the limbs, and its pose drives any model of the same layout
(`tracking.body.model.POSE_LAYOUT`). From the plugin's `tracking_model` of the fitted height,
at its full resolution when it has one (the cloud is dense; mpfb's ``mesh="full"``), ICP moves
the 26 pose parameters (within the joint limits) and the shape parameters
(`TrackedModel.shape_parameters`: mpfb's gender, muscle, weight, height, proportions and
clothing) together:

* match: every point to the nearest point of the posed triangle mesh (Open3D), kept as a
  triangle and barycentric coordinates, so that the matched point moves with the mesh;
* solve: damped Gauss-Newton steps on the point-to-plane distances to the matched triangles
  (soft-L1, `tracking.fit.body_fit.damped_steps`). A vertex's pose derivative is each node's
  rigid motion weighted by its skinning weight on the nodes the parameter moves
  (`tracking.track.contour`'s `_Posed`, what the outline refinement uses); the shape
  derivatives are forward differences of the vertices, one reshaped model per parameter.

Pure numpy/Open3D, no files.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tracking.body.model import LOWER_LIMITS, N_POSE_PARAMS, UPPER_LIMITS, Pose, TrackedModel
from tracking.fit.body_fit import (
    FitConfig,
    best_leg_pair,
    damped_steps,
    search_limbs,
    triangle_scene,
    two_way_cost,
)
from tracking.track.contour import _Posed

_STEPS_PER_ROUND = 2


def fitting_model(body: str, height_m: float) -> TrackedModel:
    """The ``body`` plugin's start for a subject of stature `height_m` (`tracking_model`), at
    its full resolution when the model has a ``mesh`` option (module docstring)."""
    from plugins.registry import create

    model = create("body", body).tracking_model(height_m)
    if dataclasses.is_dataclass(model) and "mesh" in {f.name for f in dataclasses.fields(model)}:
        model = dataclasses.replace(model, mesh="full")
    return model


def closest_on_mesh(vertices: np.ndarray, faces: np.ndarray,
                    points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The nearest point of the triangle mesh (V, 3), (F, 3) to each of points (N, 3): its
    triangle (N,) and barycentric coordinates (N, 3) (Open3D's uv: weights 1-u-v, u, v of the
    triangle's vertices 0, 1, 2)."""
    import open3d as o3d

    query = o3d.core.Tensor(np.asarray(points, np.float32))
    hit = triangle_scene(vertices, faces).compute_closest_points(query)
    uv = hit["primitive_uvs"].numpy().astype(float)
    bary = np.column_stack([1.0 - uv.sum(axis=1), uv])
    return hit["primitive_ids"].numpy().astype(np.int64), bary


def _on_triangles(vertices: np.ndarray, corners: np.ndarray,
                  bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Points (N, 3) at barycentric `bary` of the triangles `corners` (N, 3 vertex indices)
    and the triangles' unit normals (N, 3)."""
    a, b, c = (vertices[corners[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c, normal


class SkinnedProblem:
    """ICP of a skinned model over x = (26 pose parameters, its shape parameters), the
    interface of `tracking.fit.body_fit`'s searches (``bounds``, ``cost``, ``icp``,
    ``n_samples``); `scale`: the robust scale (cloud units)."""

    def __init__(self, base: TrackedModel, scale: float) -> None:
        self.base, self.scale = base, scale
        self.params = base.shape_parameters()
        self.faces = np.asarray(base.faces)
        self.bounds = (np.concatenate([LOWER_LIMITS, self.params.lower]),
                       np.concatenate([UPPER_LIMITS, self.params.upper]))  # fmt: skip
        self.n_samples = len(base.node_weights)
        self._models: dict[bytes, TrackedModel] = {}

    def start(self, pose: Pose) -> np.ndarray:
        """The unknowns of `pose` (clipped to the joint limits) on the base shape."""
        return np.concatenate([np.clip(pose.params, LOWER_LIMITS, UPPER_LIMITS),
                               self.params.values])  # fmt: skip

    def model(self, x: np.ndarray) -> TrackedModel:
        """The model of x's shape, kept while its values recur (every trial step reshapes)."""
        values = np.asarray(x[N_POSE_PARAMS:], float)
        key = values.tobytes()
        if key not in self._models:
            if len(self._models) > 2 * len(values) + 4:
                self._models.clear()
            self._models[key] = self.base.reshaped(values)
        return self._models[key]

    def vertices(self, x: np.ndarray) -> np.ndarray:
        return self.model(x).posed_vertices(Pose(x[:N_POSE_PARAMS]))

    def cost(self, x: np.ndarray, points: np.ndarray, samples: np.ndarray | None = None,
             keep_model: float = 0.6) -> float:  # fmt: skip
        """`tracking.fit.body_fit.two_way_cost` of the vertices (`samples`, default all)."""
        vertices = self.vertices(x)
        return two_way_cost(vertices if samples is None else vertices[samples], points,
                            self.scale, keep_model)  # fmt: skip

    def _linearise(self, x: np.ndarray, points: np.ndarray, corners: np.ndarray,
                   bary: np.ndarray, free: np.ndarray):  # fmt: skip
        """Residuals, normals and Jacobian (N, 3, len(free)) of the matches (module
        docstring)."""
        step, upper = self.params.step, self.params.upper
        model = self.model(x)
        free_pose = free[free < N_POSE_PARAMS]
        free_shape = free[free >= N_POSE_PARAMS] - N_POSE_PARAMS
        used, inverse = np.unique(corners, return_inverse=True)
        verts = model.posed_vertices(Pose(x[:N_POSE_PARAMS]))
        extra = None
        if len(free_shape):
            # Forward differences (backwards at an upper bound), on the matched vertices.
            extra = np.zeros((len(verts), 3, len(free_shape)))
            for col, i in enumerate(free_shape):
                sign = 1.0 if x[N_POSE_PARAMS + i] + step <= upper[i] else -1.0
                y = x.copy()
                y[N_POSE_PARAMS + i] += sign * step
                extra[used, :, col] = (self.vertices(y)[used] - verts[used]) / (sign * step)
        posed = _Posed(model, x[:N_POSE_PARAMS], free_pose, extra)
        # Columns: shape first, then pose (`_Posed`); each point blends its triangle's corners.
        d = posed.derivatives(used)[inverse.reshape(corners.shape)]
        jac = np.einsum("nk,nkip->nip", bary, d)
        order = {int(k): c for c, k in enumerate(np.concatenate([N_POSE_PARAMS + free_shape,
                                                                 free_pose]))}  # fmt: skip
        jac = jac[:, :, [order[int(k)] for k in free]]
        on, normal = _on_triangles(verts, corners, bary)
        return points - on, normal, jac

    def icp(
        self, x: np.ndarray, points: np.ndarray, free: np.ndarray, rounds: int, steps: int,
        loss: str = "soft_l1", samples: np.ndarray | None = None,
    ) -> np.ndarray:  # fmt: skip
        """ICP on the unknowns `free` of x: each round matches every point to the nearest
        point of the posed mesh, then takes `steps` damped Gauss-Newton steps (`samples`, the
        superquadric's surface subset, has no meaning here and is ignored)."""
        free = np.asarray(free)
        lo, hi = self.bounds[0][free], self.bounds[1][free]
        x = x.copy()
        x[free] = np.clip(x[free], lo, hi)
        for _ in range(rounds):
            triangle, bary = closest_on_mesh(self.vertices(x), self.faces, points)
            corners = self.faces[triangle]

            def residuals(y: np.ndarray, corners: np.ndarray = corners,
                          bary: np.ndarray = bary) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
                on, normal = _on_triangles(self.vertices(y), corners, bary)
                return points - on, normal

            def linearise(y: np.ndarray, corners: np.ndarray = corners, bary: np.ndarray = bary):
                return self._linearise(y, points, corners, bary, free)

            start = x[free].copy()
            x = damped_steps(x, free, (lo, hi), linearise, residuals, steps=steps,
                             scale=self.scale, loss=loss)  # fmt: skip
            if np.abs(x[free] - start).max() < 1e-4:
                break
        return x


def refine_skinned(body: str, height_m: float, pose: Pose, points: np.ndarray,
                   config: FitConfig) -> tuple[TrackedModel, Pose]:  # fmt: skip
    """The ``body`` model (`fitting_model` of `height_m`, reshaped) and pose that fit `points`
    (N, 3) best from `pose`: ICP over pose and shape, the limb search of
    `tracking.fit.body_fit.search_limbs` on this model (a forearm the superquadrics left
    folded the wrong way), and ICP again; `config.robust_scale` of the height is the soft-L1
    scale, `config.body_rounds` the ICP rounds of each pass."""
    base = fitting_model(body, height_m)
    problem = SkinnedProblem(base, config.robust_scale * base.shape.height)
    x = problem.start(pose)
    everything = config.free(len(x))
    x = problem.icp(x, points, everything, rounds=config.body_rounds, steps=_STEPS_PER_ROUND)
    coarse = points[np.random.default_rng(config.seed).choice(
        len(points), min(400, len(points)), replace=False)]
    x = search_limbs(problem, x, coarse, grid=config.arm_grid)
    challenger = best_leg_pair(problem, x, coarse)
    fits = [problem.icp(y, points, everything, rounds=config.body_rounds, steps=_STEPS_PER_ROUND)
            for y in (x, challenger)]  # fmt: skip
    x = min(fits, key=lambda y: problem.cost(y, points))
    return problem.model(x), Pose(x[:N_POSE_PARAMS])


def repair_limbs(model: TrackedModel, pose: Pose, points: np.ndarray, config: FitConfig,
                 limbs: tuple[str, ...], thorough: bool = False,
                 ) -> tuple[TrackedModel, Pose]:  # fmt: skip
    """`model` in `pose` with the `limbs` searched again, every candidate refined rather than
    the best few of the pre-scoring (`search_limbs` with ``refined`` = all), then ICP over
    pose and shape: the second chance of a fit that `tracking.fit.body_fit.acceptance`
    refuses for a limb. Measured on a CMU dance frame (a hanging arm fitted raised): the
    pre-scoring ranked the hanging candidate out of the best three; refined, it has the
    lowest cost of the 24 (joint error 68 -> 13 mm before the final ICP). thorough: the
    search of `search_limbs` with ``dense`` = all `points` (the second look at an accepted
    fit)."""
    problem = SkinnedProblem(model, config.robust_scale * model.shape.height)
    x = problem.start(pose)
    coarse = points[np.random.default_rng(config.seed).choice(
        len(points), min(400, len(points)), replace=False)]
    x = search_limbs(problem, x, coarse, limbs, exhaustive=True,
                     dense=points if thorough else None, grid=config.arm_grid)
    x = problem.icp(x, points, config.free(len(x)), rounds=config.body_rounds,
                    steps=_STEPS_PER_ROUND)  # fmt: skip
    return problem.model(x), Pose(x[:N_POSE_PARAMS])
