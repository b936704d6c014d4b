"""Kruppa over many pairs at once: a free principal point, and one focal per camera.

The closed form (:mod:`recon.calibration.kruppa`) gives one constant focal per pair with the
principal point fixed at the image centre. Two generalisations need several pairs at once:

Free principal point (``estimate_focal_and_principal_point``)
-------------------------------------------------------------
Unknowns ``(f, cx, cy)`` shared by every view. A pair gives two independent Kruppa equations,
so the three unknowns need two pairs with different motions at least; the thesis' two-view
experiment cannot estimate them. We minimise, over all pairs that the closed form found
non-singular (status ``ok``), the essential-matrix singular-value condition, equivalent to
Kruppa's equations (Mendonça and Cipolla 1999)::

    r_i(f, cx, cy) = (σ1 - σ2) / (σ1 + σ2)  of  E_i = Kᵀ F_i K,
    K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]

with ``scipy.optimize.least_squares`` (Cauchy loss, pair weight ``min(n, cap)``), started
from the closed form's fused focal and the image centre. The principal point is only weakly
observable from F (a shift of the principal point is mostly absorbed by a small rotation of
the cameras), so the estimate is gated:

- at least ``min_pairs`` ok pairs, spanning at least three images;
- its standard error (Gauss-Newton covariance at the optimum, scaled by the residuals' spread
  and inflated for pairs sharing images as in :mod:`recon.calibration.fusion`) below
  ``max_principal_point_sigma_factor × max(w, h)`` (an axis above it is held at the centre
  and the rest refitted), and the focal's below ``max_relative_focal_sigma``;
- inside the image.

A principal point failing a gate is rejected: the caller keeps the centre and the closed
form's focal, with the message saying why.

One focal per camera (``estimate_focals_per_camera``)
-----------------------------------------------------
For two views with different focals and known principal points, Bougnoux's formula gives
both focals from F (:func:`bougnoux_focals_px`). Each pair ``(i, j)`` of different cameras
gives one value per camera, a pair within one camera the closed form's shared focal. Per
camera, its pairs' values are fused by a weighted median in ``log f`` (weights
``conditioning² · min(n, cap)`` as in the fusion), then every camera's focal is refined
together by robust least squares on ``r(K_jᵀ F K_i)`` (Cauchy loss). The singularity checks
carry over: a pair's values count only if its conditioning - the smallest slope of ``r`` over
the directions of ``(log f_i, log f_j)``, 0 when a family of focal pairs explains F - reaches
the near-singular threshold. Bougnoux's
formula is singular whenever the optical axes are coplanar (not only for equidistant
centres): varying focals have fewer well-conditioned pairs than a constant one.

No I/O here: pure numpy (and scipy).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from recon.calibration.kruppa import balance_scale_px

__all__ = [
    "CameraFocal",
    "EpipolarConfig",
    "EpipolarPair",
    "JointPair",
    "PerCameraConfig",
    "PrincipalPointConfig",
    "PrincipalPointEstimate",
    "PrincipalPointStatus",
    "bougnoux_focals_px",
    "essential_residual_general",
    "estimate_focal_and_principal_point",
    "estimate_intrinsics_epipolar",
    "estimate_focals_per_camera",
]


def _intrinsics(focal_px: float, principal_point: tuple[float, float]) -> np.ndarray:
    cx, cy = principal_point
    return np.array([[focal_px, 0.0, cx], [0.0, focal_px, cy], [0.0, 0.0, 1.0]])


def essential_residual_general(F: np.ndarray, K_i: np.ndarray, K_j: np.ndarray) -> float:
    """``(σ1 - σ2)/(σ1 + σ2)`` of ``E = K_jᵀ F K_i`` for ``x_jᵀ F x_i = 0``: 0 iff the two
    calibrations explain F exactly."""
    sv = np.linalg.svd(K_j.T @ F @ K_i, compute_uv=False)
    total = float(sv[0] + sv[1])
    return float(sv[0] - sv[1]) / total if total > 0.0 else 1.0


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def bougnoux_focals_px(
    F: np.ndarray,
    principal_point_i: tuple[float, float],
    principal_point_j: tuple[float, float],
) -> tuple[float | None, float | None]:
    """Focals ``(f_i, f_j)`` in px of two views with ``x_jᵀ F x_i = 0`` (Bougnoux 1998).

    Square pixels, zero skew, known principal points. ``f_i² = -(p_jᵀ [e_j]ₓ Ĩ F p_i p_iᵀ Fᵀ
    p_j) / (p_jᵀ [e_j]ₓ Ĩ F Ĩ Fᵀ p_j)`` with ``Ĩ = diag(1, 1, 0)``, ``e_j`` the epipole in
    image j, and ``f_j`` the same with the views swapped. A value is None when its square is
    not positive (noise near the singular configurations: coplanar optical axes).
    """
    F = np.asarray(F, dtype=float)
    # Work in coordinates centred on each principal point and scaled to O(1) (the formula is
    # covariant; this only keeps the arithmetic well conditioned).
    scale = max(1.0, float(np.max(np.abs([*principal_point_i, *principal_point_j]))))
    T_i = np.array([[scale, 0, principal_point_i[0]], [0, scale, principal_point_i[1]], [0, 0, 1]])
    T_j = np.array([[scale, 0, principal_point_j[0]], [0, scale, principal_point_j[1]], [0, 0, 1]])
    Fc = T_j.T @ F @ T_i
    Fc /= np.linalg.norm(Fc)
    p = np.array([0.0, 0.0, 1.0])
    I_tilde = np.diag([1.0, 1.0, 0.0])

    def first(Fm: np.ndarray) -> float | None:
        # Epipole in the second image: left null vector of Fm.
        U, _, _ = np.linalg.svd(Fm)
        e2 = U[:, 2]
        num = p @ _skew(e2) @ I_tilde @ Fm @ p * (p @ Fm.T @ p)
        den = p @ _skew(e2) @ I_tilde @ Fm @ I_tilde @ Fm.T @ p
        if den == 0.0 or not math.isfinite(num / den):
            return None
        f2 = -num / den
        return math.sqrt(f2) * scale if f2 > 0.0 else None

    return first(Fc), first(Fc.T)


class PrincipalPointStatus(enum.StrEnum):
    OK = "ok"
    # Fewer than min_pairs ok pairs, or they span fewer than three images.
    TOO_FEW_PAIRS = "too-few-pairs"
    # The fit's standard error of the principal point is too large to trust.
    POORLY_CONSTRAINED = "poorly-constrained"
    # The estimate lies outside the image.
    OUTSIDE_IMAGE = "outside-image"
    # The optimiser failed or left the plausible focal range.
    FAILED = "failed"


@dataclass(frozen=True, kw_only=True)
class PrincipalPointConfig:
    """Settings of :func:`estimate_focal_and_principal_point`."""

    min_pairs: int = field(
        default=3, metadata={"help": "fewer ok pairs than this: the principal point is not fit"}
    )
    inlier_cap: int = field(
        default=1000, metadata={"help": "pair weight = min(inliers, this), as in the fusion"}
    )
    cauchy_scale: float = field(
        default=0.02,
        metadata={
            "help": "residual scale of the Cauchy loss on (σ1-σ2)/(σ1+σ2); measured on random "
            "8-view scenes at 1 px, 20 px off-centre: 0.001 → 0.48% focal error, 0.005 → "
            "0.29%, 0.02 → 0.22%, 0.1 → 0.23%"
        },
    )
    max_relative_focal_sigma: float = field(
        default=0.05,
        metadata={
            "help": "reject the fit when its focal's relative standard error exceeds this "
            "(FusionConfig.max_relative_sigma's value; accepted fits on random 8-view scenes "
            "and the 5-view thesis scene at 0.1 px: at most 0.026)"
        },
    )
    max_principal_point_sigma_factor: float = field(
        default=0.02,
        metadata={
            "help": "reject the principal point when its standard error (either axis) exceeds "
            "this × max(width, height)"
        },
    )


@dataclass(frozen=True, kw_only=True)
class PrincipalPointEstimate:
    """Focal and principal point (px) of the free-principal-point fit; see ``status``."""

    status: PrincipalPointStatus
    # The fit's values, also when rejected (for the report); None when not fit.
    focal_px: float | None
    principal_point_px: tuple[float, float] | None
    sigma_focal_px: float | None = None
    sigma_principal_point_px: tuple[float, float] | None = None
    num_pairs: int = 0
    num_images: int = 0
    # Robust residual spread (median |r|) at the start (centre) and at the optimum.
    median_residual_start: float | None = None
    median_residual: float | None = None
    # Image axes ("x", "y") the data did not constrain, held at the image centre.
    held_at_centre: tuple[str, ...] = ()
    message: str = ""

    @property
    def accepted(self) -> bool:
        return self.status is PrincipalPointStatus.OK


def _balanced(F: np.ndarray, centre: tuple[float, float], scale_px: float) -> np.ndarray:
    T_inv = np.array([[scale_px, 0.0, centre[0]], [0.0, scale_px, centre[1]], [0.0, 0.0, 1.0]])
    Fb = T_inv.T @ np.asarray(F, dtype=float) @ T_inv
    return Fb / np.linalg.norm(Fb)


def _residuals_shared(params: np.ndarray, F_balanced: np.ndarray) -> np.ndarray:
    """r_i for K = [[k, 0, u], [0, k, v], [0, 0, 1]] in balanced units; (num_pairs,)."""
    k, u, v = math.exp(params[0]), params[1], params[2]
    K = np.array([[k, 0.0, u], [0.0, k, v], [0.0, 0.0, 1.0]])
    sv = np.linalg.svd(K.T @ F_balanced @ K, compute_uv=False)
    total = sv[:, 0] + sv[:, 1]
    return np.where(total > 0, (sv[:, 0] - sv[:, 1]) / np.where(total > 0, total, 1.0), 1.0)


def _pair_correlation_inflation(image_pairs: Sequence[tuple[int, int]]) -> float:
    images = {i for pair in image_pairs for i in pair}
    return math.sqrt(max(1.0, len(image_pairs) / max(len(images) - 1, 1)))


def estimate_focal_and_principal_point(
    fundamentals: Sequence[np.ndarray],
    *,
    image_pairs: Sequence[tuple[int, int]],
    image_size: tuple[int, int],
    start_focal_px: float,
    num_inliers: Sequence[int] | None = None,
    focal_range_px: tuple[float, float] | None = None,
    config: PrincipalPointConfig | None = None,
) -> PrincipalPointEstimate:
    """Shared focal and principal point (px) from the F's of non-singular pairs.

    ``fundamentals[i]`` is (3, 3) with ``x_jᵀ F x_i = 0`` in pixels for the images
    ``image_pairs[i]``; pass only pairs the closed form found ``ok`` (the singularity gate).
    ``start_focal_px`` is the closed form's fused focal (principal point at the centre).
    """
    from scipy.optimize import least_squares  # ~0.3 s import: only when fitting

    config = config or PrincipalPointConfig()
    width, height = image_size
    longest = float(max(width, height))
    images = {i for pair in image_pairs for i in pair}
    n = len(fundamentals)
    if n < config.min_pairs or len(images) < 3:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.TOO_FEW_PAIRS,
            focal_px=None,
            principal_point_px=None,
            num_pairs=n,
            num_images=len(images),
            message=f"{n} ok pair(s) over {len(images)} image(s): the principal point needs "
            f"{config.min_pairs} pairs over 3 images at least",
        )
    centre = (0.5 * width, 0.5 * height)
    scale = balance_scale_px(image_size)
    Fb = np.stack([_balanced(F, centre, scale) for F in fundamentals])
    weights = (
        np.minimum(np.maximum(np.asarray(num_inliers, float), 1.0), config.inlier_cap)
        if num_inliers is not None
        else np.ones(n)
    )
    sqrt_w = np.sqrt(weights / weights.max())

    start = np.array([math.log(start_focal_px / scale), 0.0, 0.0])
    r_start = _residuals_shared(start, Fb)
    inflation = _pair_correlation_inflation(image_pairs)

    def fit(free: list[int]) -> tuple[np.ndarray, np.ndarray, bool]:
        """Parameters (log k, u, v) with those not in ``free`` held at the start, their
        standard errors (∞ for held ones), and whether the solver converged."""

        def residuals(x: np.ndarray) -> np.ndarray:
            params = start.copy()
            params[free] = x
            return sqrt_w * _residuals_shared(params, Fb)

        solution = least_squares(
            residuals, start[free], loss="cauchy", f_scale=config.cauchy_scale,
            x_scale="jac", method="trf",
        )
        params = start.copy()
        params[free] = solution.x
        # Gauss-Newton covariance of the (loss-weighted) problem, residual variance from the
        # fit, inflated for pairs sharing images.
        J = solution.jac
        s2 = 2.0 * float(solution.cost) / max(n - len(free), 1)
        sig = np.full(3, math.inf)
        try:
            cov = np.linalg.inv(J.T @ J) * s2 * inflation**2
            sig[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            pass
        return params, sig, bool(solution.success)

    limit = config.max_principal_point_sigma_factor * longest
    try:
        params, sig, converged = fit([0, 1, 2])
        # The principal point is often observable along one image axis only (e.g. cameras
        # moving sideways constrain cx, not cy): hold the other at the centre and refit.
        held = [axis for axis in (1, 2) if not sig[axis] * scale <= limit]
        if len(held) == 1:
            params, sig, converged = fit([k for k in (0, 1, 2) if k not in held])
    except (ValueError, np.linalg.LinAlgError) as exc:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.FAILED, focal_px=None, principal_point_px=None,
            num_pairs=n, num_images=len(images), message=f"least squares failed: {exc}",
        )
    focal = math.exp(params[0]) * scale
    pp = (centre[0] + params[1] * scale, centre[1] + params[2] * scale)
    r_final = _residuals_shared(params, Fb)
    sigma_focal = focal * float(sig[0])
    sigma_pp = (float(sig[1]) * scale, float(sig[2]) * scale)
    common = dict(
        focal_px=focal,
        principal_point_px=pp,
        sigma_focal_px=sigma_focal,
        sigma_principal_point_px=sigma_pp,
        num_pairs=n,
        num_images=len(images),
        median_residual_start=float(np.median(r_start)),
        median_residual=float(np.median(r_final)),
        held_at_centre=tuple("xy"[axis - 1] for axis in held) if len(held) == 1 else (),
    )
    where = f"({pp[0]:.1f}, {pp[1]:.1f}) px ±({sigma_pp[0]:.1f}, {sigma_pp[1]:.1f})"
    refused = _refused(common, converged and bool(np.all(np.isfinite(params))), focal,
                       sigma_focal, pp, where, (width, height), focal_range_px, config,
                       fit="fit", focal_of=f"the fit with principal point {where}")
    if refused is not None:
        return refused
    constrained = [v for v in sigma_pp if math.isfinite(v)]
    if len(held) == 2 or not constrained or max(constrained) > limit:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.POORLY_CONSTRAINED, **common,
            message=f"principal point {where} is poorly constrained by these pairs "
            f"(standard error above {limit:.1f} px)",
        )
    message = (
        f"c{common['held_at_centre'][0]} held at the image centre: these pairs do not "
        "constrain it" if len(held) == 1 else ""
    )
    return PrincipalPointEstimate(status=PrincipalPointStatus.OK, **common, message=message)


def _refused(common: dict, converged: bool, focal: float, sigma_focal: float,
             pp: Sequence[float], where: str, size: tuple[int, int],
             focal_range_px: tuple[float, float] | None, config: Any, *, fit: str,
             focal_of: str) -> PrincipalPointEstimate | None:  # fmt: skip
    """The gates every free-principal-point fit passes (`estimate_focal_and_principal_point`,
    `estimate_intrinsics_epipolar`): a fit that did not converge to a focal in
    `focal_range_px`, a principal point outside the image, or a focal whose standard error is
    over `config.max_relative_focal_sigma`; the refused estimate, or None when it passes."""
    width, height = size
    lo, hi = focal_range_px or (0.0, math.inf)
    if not converged or not (lo <= focal <= hi):
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.FAILED, **common,
            message=f"the {fit} did not converge to a plausible focal ({focal:.1f} px)",
        )
    if not (0.0 <= pp[0] <= width and 0.0 <= pp[1] <= height):
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.OUTSIDE_IMAGE, **common,
            message=f"principal point {where} lies outside the {width}x{height} image",
        )
    if not sigma_focal <= config.max_relative_focal_sigma * focal:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.POORLY_CONSTRAINED, **common,
            message=f"the focal {focal:.1f} ±{sigma_focal:.1f} px of {focal_of} is too "
            f"uncertain (more than {config.max_relative_focal_sigma:.0%})",
        )
    return None


# One focal per camera -----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class JointPair:
    """One pair's F between the images of cameras ``camera_i`` and ``camera_j``."""

    F: np.ndarray
    """(3, 3), ``x_jᵀ F x_i = 0`` in pixels."""
    camera_i: int
    camera_j: int
    num_inliers: int = 1


@dataclass(frozen=True, kw_only=True)
class PerCameraConfig:
    """Settings of :func:`estimate_focals_per_camera`."""

    near_singular_threshold: float = field(
        default=0.02,
        metadata={"help": "a pair's value for a camera counts if its conditioning reaches this"},
    )
    sharpness_step: float = field(default=0.1, metadata={"help": "step in log f for the slope"})
    inlier_cap: int = field(default=1000, metadata={"help": "pair weight cap, as in the fusion"})
    cauchy_scale: float = field(
        default=0.005,
        metadata={
            "help": "residual scale of the Cauchy loss of the joint refit (0: 2.385 robust "
            "standard deviations of the residuals at the medians). Larger scales approach "
            "least squares, which the asymmetric r(f) biases towards short focals where the "
            "common scale of all focals is weakly constrained (an arc of cameras). Measured, "
            "0.005 / data-driven / 0.02: demo arc of 10 views -0.3% / -2.8% / -2.2% (one run's "
            "matches); fountain-P11 one camera +0.26, +0.18, +0.47% / +0.27, +0.25, +0.59% / "
            "-0.12, -1.20% (three databases); random 8-view scenes at 0.5 px, worst camera "
            "0.49% / 0.55% / 0.52%; 5-view thesis scene 2.2% / 1.8% / 1.9%"
        },
    )
    min_focal_factor: float = field(default=0.2, metadata={"help": "as KruppaConfig"})
    max_focal_factor: float = field(default=10.0, metadata={"help": "as KruppaConfig"})
    refine: bool = field(
        default=True,
        metadata={"help": "refine the per-camera medians jointly by robust least squares"},
    )
    max_relative_sigma: float = field(
        default=0.25,
        metadata={"help": "a camera whose refitted focal has a larger relative standard error "
                          "gets none (the Gauss-Newton error is pessimistic: measured median 1%, "
                          "99th percentile 9.5% on random 8-view scenes at 0.5 px, where every "
                          "focal was within 1.5%)"},
    )
    min_pairs: int = field(
        default=3,
        metadata={
            "help": "a camera needs this many non-singular pairs (or all of its pairs when it "
            "has fewer), as the shared fusion's min_pairs: one stray ok pair among singular "
            "ones is noise"
        },
    )


@dataclass(frozen=True, kw_only=True)
class CameraFocal:
    """One camera's focal (px) from its pairs; None when no pair constrains it."""

    camera: int
    focal_px: float | None
    focal_median_px: float | None  # the weighted median before the joint refit
    sigma_px: float | None
    num_pairs_used: int
    num_pairs: int
    message: str = ""


def _pair_conditioning(F: np.ndarray, K_i: np.ndarray, K_j: np.ndarray, step: float) -> float:
    """Smallest mean |slope| of r over directions in (log f_i, log f_j): 0 when a family of
    focal pairs explains F (coplanar optical axes), however sharp each focal is alone."""

    def r(a: float, b: float) -> float:
        # Scaling a focal with its principal point fixed: K diag(e^a, e^a, 1).
        return essential_residual_general(
            F, K_i @ np.diag([math.exp(a), math.exp(a), 1.0]),
            K_j @ np.diag([math.exp(b), math.exp(b), 1.0]),
        )

    r0 = r(0.0, 0.0)
    slopes = []
    for angle in np.linspace(0.0, math.pi, 12, endpoint=False):
        da, db = step * math.cos(angle), step * math.sin(angle)
        slopes.append((abs(r(da, db) - r0) + abs(r(-da, -db) - r0)) / (2.0 * step))
    return min(slopes)


def _weight(conditioning: float, num_inliers: float) -> float:
    # As the fusion's: per-pair error ≈ noise / conditioning, F's noise ∝ 1/√n. (Measured: after
    # the joint refit, weights cond²·n, n or 1 give the same focals.)
    return conditioning**2 * num_inliers


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def estimate_focals_per_camera(
    pairs: Sequence[JointPair],
    *,
    principal_points: dict[int, tuple[float, float]],
    image_sizes: dict[int, tuple[int, int]],
    config: PerCameraConfig | None = None,
) -> tuple[dict[int, CameraFocal], list[dict[str, object]]]:
    """One focal per camera from the pairs' F (Bougnoux across cameras, closed form within).

    Returns the per-camera focals and a per-pair table (values, conditioning, status).
    """
    from recon.calibration.kruppa import PairStatus, focal_from_fundamental

    config = config or PerCameraConfig()
    cameras = sorted(principal_points)
    values: dict[int, list[tuple[float, float]]] = {c: [] for c in cameras}  # (log f, weight)
    counts: dict[int, int] = dict.fromkeys(cameras, 0)
    table: list[dict[str, object]] = []

    def plausible(c: int, f: float | None) -> bool:
        longest = max(image_sizes[c])
        return f is not None and (
            config.min_focal_factor * longest <= f <= config.max_focal_factor * longest
        )

    for pair in pairs:
        ci, cj = pair.camera_i, pair.camera_j
        n = min(max(pair.num_inliers, 1), config.inlier_cap)
        counts[ci] += 1
        if cj != ci:
            counts[cj] += 1
        row: dict[str, object] = {"camera_i": ci, "camera_j": cj, "focal_i_px": None,
                                  "focal_j_px": None, "conditioning_i": 0.0,
                                  "conditioning_j": 0.0, "status": ""}
        if ci == cj:
            one = focal_from_fundamental(
                pair.F, principal_point=principal_points[ci], image_size=image_sizes[ci]
            )
            row.update(focal_i_px=one.focal_px, focal_j_px=one.focal_px,
                       conditioning_i=one.conditioning, conditioning_j=one.conditioning,
                       status=f"shared camera: {one.status}")
            if one.status == PairStatus.OK and one.focal_px is not None:
                values[ci].append((math.log(one.focal_px), _weight(one.conditioning, n)))
            table.append(row)
            continue
        fi, fj = bougnoux_focals_px(pair.F, principal_points[ci], principal_points[cj])
        if not (plausible(ci, fi) and plausible(cj, fj)):
            row.update(focal_i_px=fi, focal_j_px=fj, status="no plausible root")
            table.append(row)
            continue
        assert fi is not None and fj is not None
        K_i = _intrinsics(fi, principal_points[ci])
        K_j = _intrinsics(fj, principal_points[cj])
        cond_i = cond_j = _pair_conditioning(pair.F, K_i, K_j, config.sharpness_step)
        statuses = []
        for c, f, cond in ((ci, fi, cond_i), (cj, fj, cond_j)):
            if cond >= config.near_singular_threshold:
                values[c].append((math.log(f), _weight(cond, n)))
                statuses.append("ok")
            else:
                statuses.append("near-singular")
        row.update(focal_i_px=fi, focal_j_px=fj, conditioning_i=cond_i, conditioning_j=cond_j,
                   status=" / ".join(statuses))
        table.append(row)

    medians: dict[int, float] = {}
    too_few: dict[int, str] = {}
    for c in cameras:
        needed = min(config.min_pairs, counts[c])
        if values[c] and len(values[c]) < needed:
            too_few[c] = (f"only {len(values[c])} of its {counts[c]} pairs are non-singular "
                          f"(needs {needed})")
        elif values[c]:
            logs = np.array([v for v, _ in values[c]])
            w = np.array([w for _, w in values[c]])
            medians[c] = _weighted_median(logs, w / w.max())
    refined = dict(medians)
    sigmas: dict[int, float] = {}
    if config.refine and medians:
        refined, sigmas = _refine_per_camera(pairs, medians, principal_points, config)
    result = {}
    for c in cameras:
        f = refined.get(c)
        if f is not None and c in sigmas and not sigmas[c] <= config.max_relative_sigma:
            too_few[c] = (f"its focal {math.exp(f):.1f} px is uncertain (relative standard "
                          f"error {sigmas[c]:.3g} > {config.max_relative_sigma})")
            f = None
        result[c] = CameraFocal(
            camera=c,
            focal_px=math.exp(f) if f is not None else None,
            focal_median_px=math.exp(medians[c]) if c in medians else None,
            sigma_px=math.exp(f) * sigmas[c] if f is not None and c in sigmas else None,
            num_pairs_used=len(values[c]),
            num_pairs=counts[c],
            message=too_few.get(c, "" if c in medians
                                else "no non-singular pair constrains this camera"),
        )
    return result, table


def _refine_per_camera(
    pairs: Sequence[JointPair],
    start_log_f: dict[int, float],
    principal_points: dict[int, tuple[float, float]],
    config: PerCameraConfig,
) -> tuple[dict[int, float], dict[int, float]]:
    from scipy.optimize import least_squares

    free = sorted(start_log_f)
    index = {c: k for k, c in enumerate(free)}
    used = [p for p in pairs if p.camera_i in index and p.camera_j in index]
    if not used:
        return dict(start_log_f), {}
    # Pixel F's moved to each camera's principal point and a common O(1) scale.
    scale = float(np.exp(np.mean(list(start_log_f.values()))))
    Fs = []
    for p in used:
        pi, pj = principal_points[p.camera_i], principal_points[p.camera_j]
        T_i = np.array([[scale, 0, pi[0]], [0, scale, pi[1]], [0, 0, 1.0]])
        T_j = np.array([[scale, 0, pj[0]], [0, scale, pj[1]], [0, 0, 1.0]])
        Fc = T_j.T @ p.F @ T_i
        Fs.append(Fc / np.linalg.norm(Fc))
    Fs_arr = np.stack(Fs)
    ii = np.array([index[p.camera_i] for p in used])
    jj = np.array([index[p.camera_j] for p in used])
    w = np.sqrt(np.minimum([max(p.num_inliers, 1) for p in used], config.inlier_cap))
    w = w / w.max()

    def residuals(x: np.ndarray) -> np.ndarray:
        k = np.exp(x)
        di = np.stack([k[ii], k[ii], np.ones(len(ii))], axis=1)
        dj = np.stack([k[jj], k[jj], np.ones(len(jj))], axis=1)
        E = dj[:, :, None] * Fs_arr * di[:, None, :]
        sv = np.linalg.svd(E, compute_uv=False)
        return w * (sv[:, 0] - sv[:, 1]) / (sv[:, 0] + sv[:, 1])

    x0 = np.array([start_log_f[c] - math.log(scale) for c in free])
    f_scale = config.cauchy_scale
    if f_scale <= 0:
        # From the data: the residuals' robust spread at the medians, times the fusion's
        # 2.385 (Cauchy at 95% efficiency). Real F's (distortion, COLMAP's per-pair focal
        # solver) disagree more than synthetic ones, and a fixed scale far above their spread
        # makes the refit least squares, which the asymmetric r(f) biases towards short focals.
        r0 = residuals(x0) / np.maximum(w, 1e-12)
        f_scale = max(2.385 * 1.4826 * float(np.median(r0)), 1e-4)
    solution = least_squares(residuals, x0, loss="cauchy", f_scale=f_scale, method="trf")
    x = solution.x
    sigmas: dict[int, float] = {}
    try:
        dof = max(len(used) - len(free), 1)
        cov = np.linalg.inv(solution.jac.T @ solution.jac) * 2.0 * solution.cost / dof
        sigmas = {c: float(math.sqrt(max(cov[k, k], 0.0))) for c, k in index.items()}
    except np.linalg.LinAlgError:
        pass
    out = {c: float(x[k]) + math.log(scale) for c, k in index.items()}
    return out, sigmas


# Focal and principal point from the inliers' epipolar distances ------------------------------
@dataclass(frozen=True, kw_only=True)
class EpipolarPair:
    """One pair's F and its inlier matches (px), ``x_jᵀ F x_i = 0``."""

    F: np.ndarray
    points_i: np.ndarray
    """(n, 2) keypoints in image i."""
    points_j: np.ndarray
    """(n, 2) the matching keypoints in image j."""
    image_i: int
    image_j: int


@dataclass(frozen=True, kw_only=True)
class EpipolarConfig:
    """Settings of :func:`estimate_intrinsics_epipolar`."""

    max_points_per_pair: int = field(
        default=0,
        metadata={"help": "inliers used per pair, a seeded random subset (0: all). Measured "
                          "on fountain-P11 database 2 (seeds 0, 1, 2): 400 → -0.05, -0.18, "
                          "-0.15%, 7.3, 1.1, 7.8 px off; 1000 → -0.28%, 2.4 px; all (up to "
                          "4947) → -0.16%, 1.4 px, 8 s"},
    )
    cauchy_scale_px: float = field(
        default=1.0, metadata={"help": "scale of the Cauchy loss on the Sampson distances (px)"}
    )
    seed: int = field(default=0, metadata={"help": "seed of the inlier subset"})
    min_pairs: int = field(default=3, metadata={"help": "as PrincipalPointConfig.min_pairs"})
    max_relative_focal_sigma: float = field(
        default=0.05, metadata={"help": "as PrincipalPointConfig"}
    )
    max_principal_point_sigma_factor: float = field(
        default=0.02, metadata={"help": "as PrincipalPointConfig"}
    )


_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _relative_pose(
    E: np.ndarray, rays_i: np.ndarray, rays_j: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` with ``x_j ~ R x_i + t`` from E's four decompositions: the one with the most
    rays triangulated in front of both cameras. ``rays``: (n, 3) normalised coordinates."""
    U, _, Vt = np.linalg.svd(E)
    U = U * np.sign(np.linalg.det(U))
    Vt = Vt * np.sign(np.linalg.det(Vt))
    best: tuple[int, np.ndarray, np.ndarray] | None = None
    for R in (U @ _W @ Vt, U @ _W.T @ Vt):
        a = rays_i @ R.T
        for t in (U[:, 2], -U[:, 2]):
            # Depths z_i, z_j of z_j x_j = z_i R x_i + t, per ray, by least squares.
            a11, a12, a22 = (a * a).sum(1), -(a * rays_j).sum(1), (rays_j * rays_j).sum(1)
            b1, b2 = -(a @ t), rays_j @ t
            det = a11 * a22 - a12 * a12
            with np.errstate(divide="ignore", invalid="ignore"):
                z_i, z_j = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
            score = int(np.sum((z_i > 0) & (z_j > 0)))
            if best is None or score > best[0]:
                best = (score, R, t)
    assert best is not None
    return best[1], best[2]


def _sampson_px(F: np.ndarray, x_i: np.ndarray, x_j: np.ndarray) -> np.ndarray:
    """Signed Sampson distances (px) of homogeneous (n, 3) matches under one F."""
    Fx = x_i @ F.T
    Ftx = x_j @ F
    return (x_j * Fx).sum(1) / np.sqrt(Fx[:, 0] ** 2 + Fx[:, 1] ** 2 + Ftx[:, 0] ** 2
                                       + Ftx[:, 1] ** 2)


class _PairPose:
    """A pair's calibrated relative pose ``x_j ~ R x_i + t`` (|t| = 1) refit for a given K."""

    def __init__(self, pair: EpipolarPair, K: np.ndarray, rng: np.random.Generator,
                 max_points: int) -> None:
        n = len(pair.points_i)
        keep = (rng.choice(n, max_points, replace=False) if 0 < max_points < n
                else np.arange(n))
        self.x_i = np.c_[pair.points_i[keep], np.ones(len(keep))]
        self.x_j = np.c_[pair.points_j[keep], np.ones(len(keep))]
        K_inv = np.linalg.inv(K)
        self.R, self.t = _relative_pose(
            K.T @ pair.F @ K, self.x_i @ K_inv.T, self.x_j @ K_inv.T
        )

    def _pose(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from scipy.spatial.transform import Rotation

        axis = np.eye(3)[int(np.argmin(np.abs(self.t)))]
        b1 = np.cross(self.t, axis)
        b1 /= np.linalg.norm(b1)
        t = self.t + p[3] * b1 + p[4] * np.cross(self.t, b1)
        return self.R @ Rotation.from_rotvec(p[:3]).as_matrix(), t / np.linalg.norm(t)

    def residuals(self, K: np.ndarray, scale_px: float) -> np.ndarray:
        """Sampson distances (px) after refitting (R, t) for K (Cauchy loss); keeps the pose
        as the next start."""
        from scipy.optimize import least_squares

        K_inv = np.linalg.inv(K)

        def fun(p: np.ndarray) -> np.ndarray:
            R, t = self._pose(p)
            return _sampson_px(K_inv.T @ _skew(t) @ R @ K_inv, self.x_i, self.x_j)

        solution = least_squares(fun, np.zeros(5), loss="cauchy", f_scale=scale_px,
                                 x_scale=np.full(5, 1e-3), xtol=1e-12, ftol=1e-12, gtol=1e-12)
        self.R, self.t = self._pose(solution.x)
        return solution.fun


def estimate_intrinsics_epipolar(
    pairs: Sequence[EpipolarPair],
    *,
    image_size: tuple[int, int],
    start_focal_px: float,
    start_principal_point_px: tuple[float, float] | None = None,
    focal_range_px: tuple[float, float] | None = None,
    config: EpipolarConfig | None = None,
) -> PrincipalPointEstimate:
    """Shared focal and principal point (px) that best explain every pair's inliers.

    The maximum-likelihood form of the pairwise condition: each pair ``i`` gets a calibrated
    relative pose ``(R_i, t_i)``, and ``(f, cx, cy)`` minimise the Sampson distances of all the
    pairs' inliers to ``F_i = K⁻ᵀ [t_i]ₓ R_i K⁻¹`` (Cauchy loss). By variable projection: for
    each K every pose is refit alone (5 parameters), and the outer fit has only K. Unlike
    ``(σ1-σ2)/(σ1+σ2)`` of ``Kᵀ F K``, each pair weighs as much as its matches say, and a pair
    whose F is sharp in a direction the essential condition hardly sees still counts. No 3D
    points and no poses shared between pairs: a shared pose cannot add a principal point
    (a shift of it is, to first order, one rotation of every camera in its own frame, which
    every rotation cycle and baseline triangle absorbs; measured on fountain-P11, see the
    README). Gated as :func:`estimate_focal_and_principal_point`, without the held axis.
    """
    from scipy.optimize import least_squares

    config = config or EpipolarConfig()
    width, height = image_size
    longest = float(max(width, height))
    images = {i for p in pairs for i in (p.image_i, p.image_j)}
    n = len(pairs)
    if n < config.min_pairs or len(images) < 3:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.TOO_FEW_PAIRS, focal_px=None, principal_point_px=None,
            num_pairs=n, num_images=len(images),
            message=f"{n} pairs over {len(images)} images (needs {config.min_pairs} over 3)",
        )
    centre = start_principal_point_px or (0.5 * width, 0.5 * height)
    f0 = start_focal_px
    K0 = _intrinsics(f0, centre)
    rng = np.random.default_rng(config.seed)
    poses = [_PairPose(p, K0, rng, config.max_points_per_pair) for p in pairs]
    s = config.cauchy_scale_px

    def K_of(x: np.ndarray) -> np.ndarray:
        return _intrinsics(f0 * math.exp(x[0]), (centre[0] + x[1] * f0, centre[1] + x[2] * f0))

    def residuals(x: np.ndarray) -> np.ndarray:
        r = np.concatenate([pose.residuals(K_of(x), s) for pose in poses])
        # Cauchy-whitened, so that the outer least squares minimises the same robust cost.
        return np.sign(r) * s * np.sqrt(2.0 * np.log1p((r / s) ** 2))

    r_start = residuals(np.zeros(3))
    try:
        solution = least_squares(residuals, np.zeros(3), diff_step=1e-4, method="lm",
                                 xtol=1e-10)
        params = solution.x
        dof = max(len(solution.fun) - 3 - 5 * n, 1)
        cov = np.linalg.inv(solution.jac.T @ solution.jac) * float(
            np.sum(solution.fun**2)) / dof
        # Pairs sharing an image share its keypoints' noise, as in the pairwise fit.
        sig = np.sqrt(np.maximum(np.diag(cov), 0.0)) * _pair_correlation_inflation(
            [(p.image_i, p.image_j) for p in pairs])
    except (ValueError, np.linalg.LinAlgError) as exc:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.FAILED, focal_px=None, principal_point_px=None,
            num_pairs=n, num_images=len(images), message=f"least squares failed: {exc}",
        )
    K = K_of(params)
    focal, pp = float(K[0, 0]), (float(K[0, 2]), float(K[1, 2]))
    sigma_focal = focal * float(sig[0])
    sigma_pp = (float(sig[1]) * f0, float(sig[2]) * f0)
    common = dict(
        focal_px=focal, principal_point_px=pp, sigma_focal_px=sigma_focal,
        sigma_principal_point_px=sigma_pp, num_pairs=n, num_images=len(images),
        median_residual_start=float(np.median(np.abs(r_start))),
        median_residual=float(np.median(np.abs(solution.fun))),
    )
    where = f"({pp[0]:.1f}, {pp[1]:.1f}) px ±({sigma_pp[0]:.1f}, {sigma_pp[1]:.1f})"
    refused = _refused(common, bool(solution.success) and bool(np.all(np.isfinite(params))),
                       focal, sigma_focal, pp, where, (width, height), focal_range_px, config,
                       fit="epipolar fit", focal_of="the epipolar fit")
    if refused is not None:
        return refused
    limit = config.max_principal_point_sigma_factor * longest
    if not max(sigma_pp) <= limit:
        return PrincipalPointEstimate(
            status=PrincipalPointStatus.POORLY_CONSTRAINED, **common,
            message=f"principal point {where} is poorly constrained by these pairs' inliers "
            f"(standard error above {limit:.1f} px)",
        )
    return PrincipalPointEstimate(status=PrincipalPointStatus.OK, **common)
