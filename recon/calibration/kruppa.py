"""Focal length from one fundamental matrix: the degenerated Kruppa equations (thesis ch. 4).

Camera model: both views share ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` (square pixels,
zero skew, known principal point, one unknown constant focal ``f`` in pixels).

Conventions
-----------
- ``F`` maps image-1 points to epipolar lines in image 2: ``x2ᵀ F x1 = 0`` for homogeneous
  pixel coordinates (COLMAP's and pycolmap's convention; OpenCV's ``findFundamentalMat(pts1,
  pts2)`` returns the same). For cameras ``P1 = K[I|0]``, ``P2 = K[R|t]``,
  ``F = K⁻ᵀ [t]ₓ R K⁻¹``.
- ``image_size`` is ``(width, height)`` and ``principal_point`` is ``(cx, cy)`` in pixels, in
  whatever pixel convention ``F`` uses (COLMAP: pixel centres at +0.5, so ``cx = w/2``).

The equations
-------------
Image coordinates are moved to the principal point and divided by a scale ``s`` (pixels):
``x_n = T x`` with ``T = [[1/s, 0, -cx/s], [0, 1/s, -cy/s], [0, 0, 1]]``, so
``F' = T⁻ᵀ F T⁻¹`` (scaled to unit Frobenius norm) and the unknown is ``x = (f/s)²``.
With ``F' = U diag(a, b, 0) Vᵀ`` and ``u13, u23, v13, v23`` the third components of the first
two columns of ``U`` and ``V``, Hartley's SVD form of Kruppa's equations with
``C = diag(f², f², 1)`` reduces to (derived and checked symbolically; the thesis' OCR'd (4.11)
has a typo in its middle fraction, (4.12)–(4.14) are right)::

    (4.12)  x [a u13 u23 (1 - v13²) + b v13 v23 (1 - u23²)] + u23 v13 (a u13 v13 + b u23 v23) = 0
    (4.13)  x [a v13 v23 (1 - u13²) + b u13 u23 (1 - v23²)] + u13 v23 (a u13 v13 + b u23 v23) = 0
    (4.14)  c1 x² + c2 x + c3 = 0
            c1 = a²(1 - u13²)(1 - v13²) - b²(1 - u23²)(1 - v23²)
            c2 = a²(u13² + v13² - 2 u13² v13²) - b²(u23² + v23² - 2 u23² v23²)
            c3 = a² u13² v13² - b² u23² v23²

(4.12) and (4.13) are the two diagonal Kruppa equations with the unknown scale taken from
the off-diagonal one (which cancels a factor ``1 - x``); (4.14) equates the two diagonal
ones. Without noise (4.14) had exactly one positive root in every configuration we sampled
(the other ≤ 0). Note ``a u13 v13 + b u23 v23 = F'₃₃``: the linear equations lose their
constant term when the optical axes are coplanar (``p2ᵀ F p1 = 0`` for the principal points).

COLMAP note: for two images of one camera without a focal prior, COLMAP 4 stores the F of its
shared-focal solver, which is exactly consistent with one focal and the camera's principal
point, so every equation here returns that solver's focal. Plain F's (e.g. one camera per
image) carry the information the thesis' method uses.

Choice of the scale ``s`` (why not ``max(w, h)``)
-------------------------------------------------
At ``f/s = 1`` the normalised ``F'`` is an essential matrix, ``a = b`` and ``U``, ``V`` are
not unique, so every equation above is ill-conditioned near ``f ≈ s`` (measured: ``s = 640``
px with ``f = 600`` px multiplies the per-pair error at 1 px noise by 3-10). Two passes avoid
it. Pass 1 uses ``s = 2 × largest plausible focal`` (20·max(w, h) by default: every plausible
focal is ≤ 0.5 units). Pass 2 re-solves with ``s = f₁ / 3`` (the focal ≈ 3 units, image
coordinates O(1) as in Hartley's normalisation, where F's noise is closest to isotropic).
Without noise both give the same root; with 1 px noise pass 2 was less biased on the thesis'
scene (mean of 400 trials +0.4% against -3% for pass 1) and as accurate on random scenes.
The thesis' switch ``c1²/(c2²+c3²) < 1e-3`` is unit-dependent (it scales roughly as
``(s/f)⁸``): in pixel units it always picks the linear equations, at ``f/s ≤ 0.5`` never, at
``f/s ≈ 3`` occasionally. It is applied in the pass-2 units.

Singular configurations and conditioning
----------------------------------------
The linear equations are singular whenever the optical axes are coplanar (thesis §4.5.1.2,
Sturm et al.). The quadratic - and Kruppa's equations as a whole - stay regular for
coplanar axes unless, in addition, the two centres are equidistant from the point where the
axes meet (a turntable or a ring of cameras aimed at one point: every focal then explains
``F`` exactly). Both are measured per pair:

- ``axes_coplanarity`` = ``|Ê₃₃|·√2`` for ``Ê = K'ᵀ F K'`` scaled to ``‖Ê‖ = √2``: the triple
  product (baseline direction, axis 1, axis 2), 0 when the axes are coplanar;
- ``conditioning`` = how fast ``E(f) = Kᵀ F K`` stops being an essential matrix as ``log f``
  moves away from the estimate: the mean absolute slope of
  ``r(f) = (σ1 - σ2)/(σ1 + σ2)`` over ``log f ± step``. It is unit-free, 0 in the singular
  cases, and was measured to predict the per-pair error (error ≈ noise / conditioning).

No I/O here: pure numpy.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "KruppaConfig",
    "KruppaEquations",
    "KruppaMethod",
    "PairFocal",
    "PairStatus",
    "axes_coplanarity",
    "balance_scale_px",
    "essential_residual",
    "focal_from_fundamental",
    "focal_sharpness",
    "kruppa_equations",
    "normalise_fundamental",
]


class PairStatus(enum.StrEnum):
    """Outcome of the per-pair estimate. Only ``OK`` pairs are trusted by default."""

    OK = "ok"
    # A root exists but the pair hardly constrains f (see module docstring).
    NEAR_SINGULAR = "near-singular"
    # The selected equation(s) have no positive real root.
    NO_REAL_ROOT = "no-real-root"
    # σ2 ≈ 0: rank ≤ 1, not a fundamental matrix.
    RANK_DEFICIENT_F = "rank-deficient-F"
    # σ3 is not negligible: a rank-3 matrix, not a fundamental matrix.
    NOT_RANK_TWO = "not-rank-2"
    # F vanishes identically (t = 0 gives F = K⁻ᵀ[0]ₓRK⁻¹ = 0): no epipolar geometry.
    PURE_ROTATION = "pure-rotation"
    # Positive roots exist but none inside the plausible focal range.
    OUT_OF_RANGE = "out-of-range"
    # F has non-finite entries.
    INVALID_F = "invalid-F"


class KruppaMethod(enum.StrEnum):
    LINEAR = "linear"  # (4.12) and (4.13) in least squares
    QUADRATIC = "quadratic"  # (4.14)
    NONE = "none"  # no estimate was attempted (invalid F)


@dataclass(frozen=True, kw_only=True)
class KruppaConfig:
    """Settings of :func:`focal_from_fundamental`. Focal values are in pixels."""

    min_focal_factor: float = field(
        default=0.2,
        metadata={"help": "smallest plausible focal, as a multiple of max(width, height)"},
    )
    max_focal_factor: float = field(
        default=10.0,
        metadata={"help": "largest plausible focal, as a multiple of max(width, height)"},
    )
    linear_threshold: float = field(
        default=1e-3,
        metadata={
            "help": "thesis rule: use the linear equations when c1²/(c2²+c3²) is below this, "
            "in the normalised coordinates (unit-dependent)"
        },
    )
    normalization_scale_factor: float = field(
        default=2.0,
        metadata={
            "help": "pass 1 coordinate scale s = this × the largest plausible focal, so that "
            "f/s ≤ 1/this stays away from f/s = 1 where the SVD form degenerates"
        },
    )
    working_focal_units: float = field(
        default=3.0,
        metadata={
            "help": "second pass: re-solve in units where the first estimate is this many "
            "units (0 disables the second pass)"
        },
    )
    normalization_scale_px: float | None = field(
        default=None,
        metadata={"help": "explicit coordinate scale s in pixels (overrides the factor)"},
    )
    near_singular_threshold: float = field(
        default=0.02,
        metadata={
            "help": "conditioning below this flags the pair near-singular: moving f by 10% "
            "changes (σ1-σ2)/(σ1+σ2) of Kᵀ F K by less than 0.002"
        },
    )
    coplanarity_threshold: float = field(
        default=0.03,
        metadata={
            "help": "the linear equations are not used when axes_coplanarity at their root is "
            "below this (they are singular for coplanar optical axes); the quadratic is"
        },
    )
    sharpness_step: float = field(
        default=0.1,
        metadata={"help": "step in log f for the conditioning slope (0.1 = ±10.5%)"},
    )
    rank_one_tolerance: float = field(
        default=1e-8,
        metadata={"help": "σ2/σ1 below this (balanced coordinates) means rank ≤ 1"},
    )
    rank_three_tolerance: float = field(
        default=0.05,
        metadata={
            "help": "σ3/σ2 above this (balanced coordinates) means rank 3; below it the nearest "
            "rank-2 matrix is used"
        },
    )


_DEFAULT_CONFIG = KruppaConfig()


@dataclass(frozen=True, kw_only=True)
class KruppaEquations:
    """Coefficients of (4.12)-(4.14) in the unknown ``x = (f / scale_px)²``."""

    scale_px: float
    singular_values: tuple[float, float]  # a, b of the unit-norm normalised F'
    # (coefficient of x, constant term)
    linear_412: tuple[float, float]
    linear_413: tuple[float, float]
    quadratic: tuple[float, float, float]  # c1, c2, c3

    @property
    def quadratic_ratio(self) -> float:
        """The thesis' switch ``c1² / (c2² + c3²)`` (∞ when c2 = c3 = 0)."""
        c1, c2, c3 = self.quadratic
        den = c2 * c2 + c3 * c3
        return math.inf if den == 0.0 else c1 * c1 / den

    def linear_focal_px(self, which: int) -> float | None:
        """Root of (4.12) (``which=412``) or (4.13) (``which=413``); None if not positive."""
        coef, const = {412: self.linear_412, 413: self.linear_413}[which]
        return _focal_from_x(-const / coef if coef != 0.0 else math.nan, self.scale_px)

    def linear_least_squares_focal_px(self) -> float | None:
        """Both linear equations together, each scaled to a unit row ``[coef, const]``."""
        num = den = 0.0
        for coef, const in (self.linear_412, self.linear_413):
            norm2 = coef * coef + const * const
            if norm2 > 0.0:
                num += coef * const / norm2
                den += coef * coef / norm2
        return _focal_from_x(-num / den if den > 0.0 else math.nan, self.scale_px)

    def quadratic_focal_px(self) -> tuple[float, ...]:
        """Positive real roots of (4.14) in pixels, ascending (empty if none)."""
        c1, c2, c3 = self.quadratic
        scale = max(abs(c1), abs(c2), abs(c3))
        if scale == 0.0:
            return ()
        c1, c2, c3 = c1 / scale, c2 / scale, c3 / scale
        xs: list[float] = []
        if abs(c1) < 1e-14:  # degenerates to c2 x + c3 = 0
            if c2 != 0.0:
                xs.append(-c3 / c2)
        else:
            disc = c2 * c2 - 4.0 * c1 * c3
            if disc < 0.0:
                return ()
            # Numerically stable pair of roots (no cancellation in -c2 ± √disc).
            q = -0.5 * (c2 + math.copysign(math.sqrt(disc), c2))
            xs.append(q / c1)
            if q != 0.0:
                xs.append(c3 / q)
        roots = (_focal_from_x(x, self.scale_px) for x in xs)
        return tuple(sorted(r for r in roots if r is not None))


@dataclass(frozen=True, kw_only=True)
class PairFocal:
    """Per-pair result. ``focal_px`` is never NaN or ≤ 0: it is a value or None."""

    focal_px: float | None
    status: PairStatus
    # Unit-free slope of the essential-matrix residual in log f around focal_px (see module
    # docstring); 0 for singular or invalid pairs. Larger is better.
    conditioning: float
    method: str  # KruppaMethod value
    # All positive real roots, in px: (4.12), (4.13), then (4.14) ascending.
    candidates: tuple[float, ...]
    focal_linear_412_px: float | None = None
    focal_linear_413_px: float | None = None
    focal_quadratic_px: tuple[float, ...] = ()
    quadratic_ratio: float = math.inf  # c1²/(c2²+c3²) in the working units
    # Triple product of (baseline, axis 1, axis 2) at the focal used; 0 = coplanar axes.
    axes_coplanarity: float = 0.0
    # (σ1 - σ2)/(σ1 + σ2) of Kᵀ F K at focal_px: 0 when F is exactly explained.
    essential_residual: float = 1.0
    normalization_scale_px: float = 0.0
    # For joint estimation over pairs: F in coordinates (x - pp) / balance_scale_px, unit
    # Frobenius norm, row-major, same x2ᵀ F x1 = 0 convention. Empty for invalid F.
    fundamental_balanced: tuple[float, ...] = ()
    balance_scale_px: float = 1.0
    focal_range_px: tuple[float, float] = (0.0, math.inf)


def balance_scale_px(image_size: tuple[int, int]) -> float:
    """Scale making centred pixel coordinates O(1), so F's entries have comparable noise."""
    return 0.5 * float(max(image_size))


def normalise_fundamental(
    F: np.ndarray, *, principal_point: tuple[float, float], scale_px: float
) -> np.ndarray:
    """``T⁻ᵀ F T⁻¹ / ‖·‖`` for ``x_n = T x = (x - pp) / scale_px``; shape (3, 3)."""
    cx, cy = principal_point
    # T⁻¹ maps normalised to pixel coordinates: x = s x_n + pp.
    T_inv = np.array([[scale_px, 0.0, cx], [0.0, scale_px, cy], [0.0, 0.0, 1.0]])
    Fn = T_inv.T @ np.asarray(F, dtype=float) @ T_inv
    norm = float(np.linalg.norm(Fn))
    return Fn / norm if norm > 0.0 else Fn


def kruppa_equations(F_normalised: np.ndarray, *, scale_px: float) -> KruppaEquations:
    """Coefficients of (4.12)-(4.14) from ``F'`` in coordinates ``(x - pp) / scale_px``."""
    U, sv, Vt = np.linalg.svd(F_normalised)
    a, b = float(sv[0]), float(sv[1])
    u13, u23 = float(U[2, 0]), float(U[2, 1])
    v13, v23 = float(Vt[0, 2]), float(Vt[1, 2])
    f33 = a * u13 * v13 + b * u23 * v23  # = F'_33 of the rank-2 part
    return KruppaEquations(
        scale_px=scale_px,
        singular_values=(a, b),
        linear_412=(
            a * u13 * u23 * (1 - v13 * v13) + b * v13 * v23 * (1 - u23 * u23),
            u23 * v13 * f33,
        ),
        linear_413=(
            a * v13 * v23 * (1 - u13 * u13) + b * u13 * u23 * (1 - v23 * v23),
            u13 * v23 * f33,
        ),
        quadratic=(
            a * a * (1 - u13 * u13) * (1 - v13 * v13) - b * b * (1 - u23 * u23) * (1 - v23 * v23),
            a * a * (u13 * u13 + v13 * v13 - 2 * u13 * u13 * v13 * v13)
            - b * b * (u23 * u23 + v23 * v23 - 2 * u23 * u23 * v23 * v23),
            a * a * u13 * u13 * v13 * v13 - b * b * u23 * u23 * v23 * v23,
        ),
    )


def _focal_from_x(x: float, scale_px: float) -> float | None:
    if not math.isfinite(x) or x <= 0.0:
        return None
    return math.sqrt(x) * scale_px


def _essential_from(F_balanced: np.ndarray, balance_px: float, focal_px: float) -> np.ndarray:
    # Kᵀ F K with the principal point already removed: diag(k, k, 1) F_b diag(k, k, 1).
    k = focal_px / balance_px
    d = np.array([k, k, 1.0])
    return d[:, None] * F_balanced * d[None, :]


def essential_residual(F_balanced: np.ndarray, *, balance_px: float, focal_px: float) -> float:
    """``(σ1 - σ2)/(σ1 + σ2)`` of ``Kᵀ F K``: 0 iff the focal explains F exactly (Kruppa)."""
    sv = np.linalg.svd(_essential_from(F_balanced, balance_px, focal_px), compute_uv=False)
    total = float(sv[0] + sv[1])
    return float(sv[0] - sv[1]) / total if total > 0.0 else 1.0


def focal_sharpness(
    F_balanced: np.ndarray, *, balance_px: float, focal_px: float, step: float = 0.1
) -> float:
    """Mean absolute slope of :func:`essential_residual` per unit ``log f`` over ``±step``."""
    r0 = essential_residual(F_balanced, balance_px=balance_px, focal_px=focal_px)
    up = essential_residual(F_balanced, balance_px=balance_px, focal_px=focal_px * math.exp(step))
    down = essential_residual(
        F_balanced, balance_px=balance_px, focal_px=focal_px * math.exp(-step)
    )
    # Absolute one-sided slopes: on the V-shaped minimum and on either flank alike, flat ≈ 0.
    return (abs(up - r0) + abs(down - r0)) / (2.0 * step)


def axes_coplanarity(F_balanced: np.ndarray, *, balance_px: float, focal_px: float) -> float:
    """``|t̂ · (R z1 × z2)|`` for the optical axes z1, z2: 0 when they are coplanar."""
    E = _essential_from(F_balanced, balance_px, focal_px)
    norm = float(np.linalg.norm(E))
    # A true essential matrix has ‖E‖ = √2·|t|; E33 = z2ᵀ [t]ₓ R z1.
    return math.sqrt(2.0) * abs(float(E[2, 2])) / norm if norm > 0.0 else 0.0


@dataclass(frozen=True)
class _Solution:
    """One pass of the closed form in one set of units."""

    scale_px: float
    equations: KruppaEquations
    focal_px: float | None
    method: KruppaMethod
    focal_412_px: float | None
    focal_413_px: float | None
    focal_quadratic_px: tuple[float, ...]

    @property
    def candidates(self) -> tuple[float, ...]:
        linear = tuple(v for v in (self.focal_412_px, self.focal_413_px) if v is not None)
        return linear + self.focal_quadratic_px


def _solve(
    F: np.ndarray,
    F_balanced: np.ndarray,
    *,
    principal_point: tuple[float, float],
    balance_px: float,
    scale_px: float,
    focal_range_px: tuple[float, float],
    reference_px: float | None,
    config: KruppaConfig,
) -> _Solution:
    eqs = kruppa_equations(
        normalise_fundamental(F, principal_point=principal_point, scale_px=scale_px),
        scale_px=scale_px,
    )
    focal_min, focal_max = focal_range_px
    f_quad = eqs.quadratic_focal_px()

    def plausible(v: float | None) -> bool:
        return v is not None and focal_min <= v <= focal_max

    def linear() -> float | None:
        v = eqs.linear_least_squares_focal_px()
        if v is None or not plausible(v):
            return None
        # The linear equations lose their constant term (∝ F'33) when the optical axes are
        # coplanar, so near that configuration they return noise; the quadratic does not.
        coplanarity = axes_coplanarity(F_balanced, balance_px=balance_px, focal_px=v)
        return v if coplanarity >= config.coplanarity_threshold else None

    def quadratic() -> float | None:
        roots = [v for v in f_quad if plausible(v)]
        if not roots:
            return None
        if reference_px is not None:
            return min(roots, key=lambda v: abs(math.log(v / reference_px)))
        return min(
            roots,
            key=lambda v: essential_residual(F_balanced, balance_px=balance_px, focal_px=v),
        )

    # The thesis rule: (4.14) degenerates towards a linear equation when c1 is negligible.
    if eqs.quadratic_ratio < config.linear_threshold:
        order = ((KruppaMethod.LINEAR, linear), (KruppaMethod.QUADRATIC, quadratic))
    else:
        order = ((KruppaMethod.QUADRATIC, quadratic), (KruppaMethod.LINEAR, linear))
    focal, method = None, order[0][0]
    for candidate_method, solver in order:
        focal = solver()
        if focal is not None:
            method = candidate_method
            break
    return _Solution(
        scale_px=scale_px,
        equations=eqs,
        focal_px=focal,
        method=method,
        focal_412_px=eqs.linear_focal_px(412),
        focal_413_px=eqs.linear_focal_px(413),
        focal_quadratic_px=f_quad,
    )


def focal_from_fundamental(
    F: np.ndarray,
    *,
    principal_point: tuple[float, float],
    image_size: tuple[int, int],
    config: KruppaConfig = _DEFAULT_CONFIG,
) -> PairFocal:
    """Focal length (px) of two views sharing one camera, from their fundamental matrix.

    ``F`` (3×3) satisfies ``x2ᵀ F x1 = 0`` in pixels. Two passes of the closed form:

    1. in coarse units ``s = normalization_scale_factor × largest plausible focal`` (every
       plausible focal is ≤ 0.5 units, far from the degenerate ``f = s``) for a robust first
       value ``f₁``;
    2. in units ``s = f₁ / working_focal_units`` (the focal ≈ 3 units, image coordinates O(1)
       like Hartley's normalisation), which was measured to be less biased under noise. This
       value is reported; ``normalization_scale_px`` says which units were used.

    In each pass the thesis rule picks the equations: linear (4.12)+(4.13) in least squares if
    ``c1²/(c2²+c3²) < linear_threshold``, else the quadratic (4.14); if the picked one has no
    plausible root (or the linear ones are singular because the optical axes are coplanar) the
    other is used. Quadratic roots outside the plausible range are spurious (without noise the
    other root was always ≤ 0 in our tests); of two plausible ones, the one closer to ``f₁``
    (pass 2) or with the smaller :func:`essential_residual` (pass 1) is kept.

    Every outcome has a status; ``focal_px`` is a positive float or None, never NaN.
    """
    F = np.asarray(F, dtype=float)
    if F.shape != (3, 3):
        raise ValueError(f"F must be 3x3, got shape {F.shape}")
    width, height = image_size
    if width <= 0 or height <= 0:
        raise ValueError(f"image_size must be positive (width, height), got {image_size}")
    longest = float(max(width, height))
    focal_range = (config.min_focal_factor * longest, config.max_focal_factor * longest)
    balance = balance_scale_px(image_size)

    if not np.all(np.isfinite(F)):
        return _failure(PairStatus.INVALID_F, balance, focal_range)
    if not np.any(F):
        return _failure(PairStatus.PURE_ROTATION, balance, focal_range)
    F_balanced = normalise_fundamental(F, principal_point=principal_point, scale_px=balance)
    U, sv, Vt = np.linalg.svd(F_balanced)
    if sv[1] <= config.rank_one_tolerance * sv[0]:
        return _failure(PairStatus.RANK_DEFICIENT_F, balance, focal_range)
    if sv[2] > config.rank_three_tolerance * sv[1]:
        return _failure(PairStatus.NOT_RANK_TWO, balance, focal_range)
    # Nearest rank-2 matrix (Eckart-Young): the SVD form uses only the first two singular
    # triplets anyway, and the residual measures below need a true fundamental matrix.
    F_balanced = (U[:, :2] * sv[:2]) @ Vt[:2]
    F_balanced /= np.linalg.norm(F_balanced)

    def solve(scale_px: float, reference_px: float | None) -> _Solution:
        return _solve(
            F,
            F_balanced,
            principal_point=principal_point,
            balance_px=balance,
            scale_px=scale_px,
            focal_range_px=focal_range,
            reference_px=reference_px,
            config=config,
        )

    if config.normalization_scale_px is not None:
        solution = solve(config.normalization_scale_px, None)
    else:
        solution = solve(config.normalization_scale_factor * focal_range[1], None)
        if solution.focal_px is not None and config.working_focal_units > 0:
            refined = solve(solution.focal_px / config.working_focal_units, solution.focal_px)
            if refined.focal_px is not None:
                solution = refined

    focal = solution.focal_px
    # Diagnostics at the estimate, or at a typical focal when there is none.
    probe = focal if focal is not None else math.sqrt(focal_range[0] * focal_range[1])
    conditioning = focal_sharpness(
        F_balanced, balance_px=balance, focal_px=probe, step=config.sharpness_step
    )
    coplanarity = axes_coplanarity(F_balanced, balance_px=balance, focal_px=probe)
    if focal is None:
        linear = solution.equations.linear_least_squares_focal_px()
        positive = linear is not None or bool(solution.focal_quadratic_px)
        status = PairStatus.OUT_OF_RANGE if positive else PairStatus.NO_REAL_ROOT
    elif conditioning < config.near_singular_threshold:
        status = PairStatus.NEAR_SINGULAR
    else:
        status = PairStatus.OK
    return PairFocal(
        focal_px=focal,
        status=status,
        conditioning=conditioning,
        method=solution.method,
        candidates=solution.candidates,
        focal_linear_412_px=solution.focal_412_px,
        focal_linear_413_px=solution.focal_413_px,
        focal_quadratic_px=solution.focal_quadratic_px,
        quadratic_ratio=solution.equations.quadratic_ratio,
        axes_coplanarity=coplanarity,
        essential_residual=essential_residual(F_balanced, balance_px=balance, focal_px=probe),
        normalization_scale_px=solution.scale_px,
        fundamental_balanced=tuple(float(v) for v in F_balanced.ravel()),
        balance_scale_px=balance,
        focal_range_px=focal_range,
    )


def _failure(
    status: PairStatus, balance_px: float, focal_range_px: tuple[float, float]
) -> PairFocal:
    return PairFocal(
        focal_px=None,
        status=status,
        conditioning=0.0,
        method=KruppaMethod.NONE,
        candidates=(),
        balance_scale_px=balance_px,
        focal_range_px=focal_range_px,
    )
