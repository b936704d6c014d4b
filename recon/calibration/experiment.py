"""`mocap experiment kruppa-noise`: the thesis' synthetic noise experiment (§4.5.1), reproduced.

The scene (thesis §4.5.1.1)
---------------------------
Two planar grids of 12 × 10 = 120 points each (40 units apart), meeting at 135° along a
vertical ridge 1000 units straight ahead of camera 1; the ridge faces the camera. Both views
share ``K`` with f = 600 px, principal point (320, 240), 640 × 480 images. The world frame is
camera 1's. Camera 2 depends on the configuration:

- ``tilted``: it orbits the ridge point by ``orbit_deg`` about the vertical axis, still aimed at
  it, then tilts down by ``tilt_deg`` about its own x axis: the thesis' remedy for the
  singularity ("face the camera to the same point in the scene and tilt the camera slightly
  upwards or downwards", §4.6). The optical axes are not coplanar.
- ``coplanar``: the same without the tilt. Both axes pass through the ridge point and both
  centres are 1000 units from it: the singular configuration of a constant focal (every focal
  explains F, see :mod:`recon.calibration.kruppa`). The estimator must flag these pairs.
  Measured (1000 trials per σ, F by ``sampson``): all flagged without noise and at σ = 0.1
  px; 0.3-0.7% pass as ok at 0.25-0.75 px and 2-3% at 1-2 px, with median errors of 18-125%.
  Noise lifts their conditioning over the near-singular threshold (0.02), and from 1 px it
  overlaps that of the tilted pairs (coplanar 99th percentile 0.10, tilted minimum 0.047), so
  no threshold on one pair's conditioning can separate them all.
- ``coplanar-unequal`` (optional): coplanar axes, but camera 2 ``unequal_distance_ratio`` times
  farther from the ridge point. Only the linear equations are singular here, so the pairs are
  expected to be ok and accurate: coplanarity alone is not this estimator's singularity.

Each trial adds independent Gaussian noise (σ px, both coordinates, both images) to the
projections, estimates F (``estimator``) and runs
:func:`~recon.calibration.kruppa.focal_from_fundamental` (default settings).

Definitions (per configuration and σ, over the ``trials`` trials)
-----------------------------------------------------------------
``e_k = f̂_k / f − 1`` for every trial ``k`` whose pair status is ``ok`` (``n_ok`` of them):
flagged pairs are not estimates anyone would use, so they never enter the error figures.

- ``thesis_rel_error = |mean_k(f̂_k) / f − 1| = |mean_k e_k|``: the thesis' figure of merit
  ("The average of these 50 estimations is then taken as the estimated calibrated focal length
  [...] compared with the ground truth", §4.5.1.2). It measures bias plus the sampling noise of
  the mean: ``rel_error_of_mean`` is the same value signed, ``rel_error_of_mean_se =
  std(e)/√n_ok`` its standard error. At σ = 1 px one pair scatters by ~4-5%, so one batch of
  50 leaves ~0.5% of noise in this figure: compare levels with their SE in mind.
- ``mean_abs_rel_error = mean_k |e_k|`` and ``median_abs_rel_error = median_k |e_k|``: what one
  pair's estimate is typically worth.
- ``flagged_fraction = 1 − n_ok / trials``; ``status_counts`` per :class:`PairStatus`;
  ``median_abs_rel_error_any_status``: median |e| over every trial that returned a focal,
  whatever its status (for the coplanar scene: how wrong the flagged values are).

The F estimators (measured: σ = 1 px, tilted scene, 2000 trials for each of seeds 0, 1, 2;
``benchmarks/kruppa_synthetic.py``; mean |e|, pooled bias, thesis metric per batch of 50)
----------------------------------------------------------------------------------------------
- ``8-point``: Hartley-normalised 8-point on all points (OpenCV ``FM_8POINT``): 4.6%,
  +0.3…+0.5%, 0.67…0.87%. 0.2 ms per trial.
- ``lmeds-refit``: :func:`~recon.sfm.fundamental.refit_fundamental`, the Kruppa
  initialiser's ``fundamental=refit`` (LMedS, then 8-point on its inliers): 5.1…5.2%,
  +0.4…+0.65%, 0.70…0.85%; 4.5 ms. Without outliers LMedS only discards good points.
- ``sampson`` (default): 8-point, then the rank-2 F minimising the Sampson distances in pixels
  (first-order maximum likelihood for isotropic pixel noise): 3.7%, +0.2…+0.3%, 0.48…0.55%;
  2.6 ms. A full gold-standard fit (F and the 240 points on the reprojection error, sparse
  Levenberg-Marquardt) moved the focal by at most 0.1 px from this one (20 trials; Sampson
  vs 8-point: 17 px on average) at 20× the time, so it is not offered.

The closed form keeps a small positive bias whatever the F (+0.2…+0.5% at 1 px); a better F
mostly narrows the per-pair scatter, which is what the mean of 50 trials mostly measures.
"""

from __future__ import annotations

import csv
import enum
import math
import time
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from recon.calibration.kruppa import KruppaConfig, PairStatus, focal_from_fundamental
from recon.sfm.fundamental import eight_point, refine_sampson, refit_fundamental
from recon.workspace import atomic_output, write_json_atomic

__all__ = [
    "CSV_COLUMNS",
    "THESIS_REPORTED_REL_ERROR",
    "THESIS_REPORTED_SOURCE",
    "FundamentalEstimator",
    "KruppaNoiseConfig",
    "KruppaNoiseReport",
    "KruppaNoiseRow",
    "LevelErrors",
    "LevelTrials",
    "SceneConfiguration",
    "TwoViewScene",
    "build_scene",
    "compute_kruppa_noise",
    "estimate_fundamental",
    "run_kruppa_noise",
    "simulate_level",
    "summarise_level",
    "write_kruppa_noise",
]

THESIS_PRINCIPAL_POINT_PX = (320.0, 240.0)
THESIS_IMAGE_SIZE = (640, 480)  # (width, height)
THESIS_GRID_SHAPE = (12, 10)  # points along the slope, along the ridge: 120 per plane
THESIS_GRID_SPACING = 40.0  # scene units; not given in the thesis, chosen to fill the image
THESIS_PLANE_ANGLE_DEG = 135.0
# The peer figure: thesis §4.5.1.2, text under Figure 4.3 (seed file 000_5fd577acbb6375b8.txt,
# line 415), for the relative error of the mean of 50 estimates, σ = 0.1 … 2.0 px.
THESIS_REPORTED_REL_ERROR = 0.02
THESIS_REPORTED_SOURCE = (
    "thesis §4.5.1.2, Figure 4.3: \"the relative error of focal length is quite low (mostly "
    "around 2%) and it increases slowly with the noise level\""
)


class SceneConfiguration(enum.StrEnum):
    TILTED = "tilted"  # axes not coplanar (the thesis' design)
    COPLANAR = "coplanar"  # axes meet at the ridge, centres equidistant: singular
    COPLANAR_UNEQUAL = "coplanar-unequal"  # axes meet, centres not equidistant: regular

    @property
    def singular(self) -> bool:
        """Whether no focal can be recovered from F without noise (the pairs must be flagged)."""
        return self is SceneConfiguration.COPLANAR


class FundamentalEstimator(enum.StrEnum):
    EIGHT_POINT = "8-point"
    LMEDS_REFIT = "lmeds-refit"
    SAMPSON = "sampson"


def _help(text: str) -> dict[str, str]:
    return {"help": text}


@dataclass(frozen=True, kw_only=True)
class KruppaNoiseConfig:
    """Settings of `mocap experiment kruppa-noise` (thesis §4.5.1)."""

    sigmas_px: tuple[float, ...] = field(
        default=(0.1, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0),
        metadata=_help("Gaussian noise levels (std of each pixel coordinate), repeatable"),
    )
    trials: int = field(
        default=50,
        metadata=_help("noisy image pairs per level and configuration (the thesis used 50)"),
    )
    seed: int = field(
        default=0,
        metadata=_help("noise seed; each (configuration, σ) has its own stream from it"),
    )
    focal_px: float = field(default=600.0, metadata=_help("true focal length of both views"))
    out: Path = field(
        default=Path("workspaces/experiments/kruppa-noise"),
        metadata=_help("folder for table.csv, report.md, error_vs_noise.png, results.json"),
    )
    configurations: tuple[SceneConfiguration, ...] = field(
        default=(SceneConfiguration.TILTED, SceneConfiguration.COPLANAR),
        metadata=_help(
            "camera-2 placements, repeatable: " + ", ".join(c.value for c in SceneConfiguration)
        ),
    )
    estimator: FundamentalEstimator = field(
        default=FundamentalEstimator.SAMPSON,
        metadata=_help("how F is estimated from the noisy points"),
    )
    orbit_deg: float = field(
        default=30.0,
        metadata=_help("camera 2 orbits the ridge point by this angle about the vertical"),
    )
    tilt_deg: float = field(
        default=10.0,
        metadata=_help("downward tilt of camera 2 in the tilted configuration"),
    )
    distance: float = field(
        default=1000.0,
        metadata=_help("distance from camera 1 (and, except coplanar-unequal, camera 2) to "
                       "the ridge, in scene units"),
    )
    unequal_distance_ratio: float = field(
        default=1.3,
        metadata=_help("coplanar-unequal: camera 2's distance to the ridge point over camera 1's"),
    )

    def __post_init__(self) -> None:
        # The CLI hands repeatable flags over as strings: coerce here, where the types live.
        object.__setattr__(self, "sigmas_px", tuple(float(s) for s in self.sigmas_px))
        object.__setattr__(
            self, "configurations", tuple(SceneConfiguration(c) for c in self.configurations)
        )
        object.__setattr__(self, "estimator", FundamentalEstimator(self.estimator))
        object.__setattr__(self, "out", Path(self.out))
        if not self.sigmas_px or any(not (math.isfinite(s) and s >= 0) for s in self.sigmas_px):
            raise ValueError(f"sigmas_px must be finite and ≥ 0, got {self.sigmas_px}")
        if self.trials < 1:
            raise ValueError(f"trials must be ≥ 1, got {self.trials}")
        if not self.configurations or len(set(self.configurations)) != len(self.configurations):
            raise ValueError(f"configurations must be distinct, got {self.configurations}")
        for name in ("focal_px", "distance", "unequal_distance_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")


@dataclass(frozen=True)
class TwoViewScene:
    """Noise-free projections of the thesis object; camera 1 frame = world frame."""

    configuration: SceneConfiguration
    points_in_cam1: np.ndarray  # (N, 3), only points visible in both images
    pixels_in_image1: np.ndarray  # (N, 2)
    pixels_in_image2: np.ndarray  # (N, 2)
    cam2_from_cam1: tuple[np.ndarray, np.ndarray]  # (R, t)
    intrinsics: np.ndarray  # K, shared
    image_size: tuple[int, int]
    # |baseline · (axis1 × axis2)| with unit vectors: 0 iff the optical axes are coplanar.
    axes_triple_product: float

    @property
    def principal_point(self) -> tuple[float, float]:
        return float(self.intrinsics[0, 2]), float(self.intrinsics[1, 2])

    @property
    def true_fundamental(self) -> np.ndarray:
        """``K⁻ᵀ [t]ₓ R K⁻¹`` (``x2ᵀ F x1 = 0``), unit Frobenius norm."""
        R, t = self.cam2_from_cam1
        K_inv = np.linalg.inv(self.intrinsics)
        F = K_inv.T @ _skew(t) @ R @ K_inv
        return F / np.linalg.norm(F)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rotation(axis: Sequence[float], angle_deg: float) -> np.ndarray:
    # Imported here: scipy costs ~0.3 s, and `mocap --help` needs none of it.
    from scipy.spatial.transform import Rotation

    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return Rotation.from_rotvec(unit * math.radians(angle_deg)).as_matrix()


def _grid_points_in_cam1(distance: float) -> np.ndarray:
    """Two 120-point grids meeting at 135° along a vertical ridge ``distance`` ahead; (240, 3)."""
    along_slope, along_ridge = THESIS_GRID_SHAPE
    u, v = np.meshgrid(
        (np.arange(along_slope) + 0.5) * THESIS_GRID_SPACING,  # the ridge itself stays empty
        (np.arange(along_ridge) - (along_ridge - 1) / 2) * THESIS_GRID_SPACING,
    )
    half = math.radians(THESIS_PLANE_ANGLE_DEG / 2)
    ridge = np.array([0.0, 0.0, distance])
    # Both planes recede from camera 1 (+z) on either side: their in-plane slope directions
    # (±sin h, 0, cos h) are 2h = 135° apart.
    planes = [
        ridge
        + u.reshape(-1, 1) * np.array([side * math.sin(half), 0.0, math.cos(half)])
        + v.reshape(-1, 1) * np.array([0.0, 1.0, 0.0])
        for side in (-1.0, 1.0)
    ]
    return np.vstack(planes)


def build_scene(configuration: SceneConfiguration, config: KruppaNoiseConfig) -> TwoViewScene:
    """The noise-free two-view scene of one configuration (pure)."""
    configuration = SceneConfiguration(configuration)
    cx, cy = THESIS_PRINCIPAL_POINT_PX
    K = np.array([[config.focal_px, 0.0, cx], [0.0, config.focal_px, cy], [0.0, 0.0, 1.0]])
    points = _grid_points_in_cam1(config.distance)
    ridge = np.array([0.0, 0.0, config.distance])
    orbit = _rotation((0.0, 1.0, 0.0), config.orbit_deg)
    ratio = (
        config.unequal_distance_ratio
        if configuration is SceneConfiguration.COPLANAR_UNEQUAL
        else 1.0
    )
    centre2 = ridge - ratio * (orbit @ ridge)
    # orbit.T aims camera 2's +z at the ridge point; the tilt turns it about its own x axis
    # (image y points down, so a positive angle tilts the view down).
    tilt = config.tilt_deg if configuration is SceneConfiguration.TILTED else 0.0
    R2 = _rotation((1.0, 0.0, 0.0), tilt) @ orbit.T
    t2 = -R2 @ centre2

    in_cam2 = points @ R2.T + t2
    pixels = []
    for in_cam in (points, in_cam2):
        h = in_cam @ K.T
        pixels.append(h[:, :2] / h[:, 2:])
    width, height = THESIS_IMAGE_SIZE
    visible = (points[:, 2] > 0) & (in_cam2[:, 2] > 0)
    for px in pixels:
        visible &= (px[:, 0] >= 0) & (px[:, 0] <= width) & (px[:, 1] >= 0) & (px[:, 1] <= height)
    if visible.sum() < 8:
        raise ValueError(
            f"{configuration}: only {int(visible.sum())} points visible in both images"
        )
    axis2 = R2[2]  # camera 2's optical axis in camera 1 coordinates
    baseline = centre2 / np.linalg.norm(centre2)
    triple = abs(float(baseline @ np.cross(np.array([0.0, 0.0, 1.0]), axis2)))
    return TwoViewScene(
        configuration=configuration,
        points_in_cam1=points[visible],
        pixels_in_image1=pixels[0][visible],
        pixels_in_image2=pixels[1][visible],
        cam2_from_cam1=(R2, t2),
        intrinsics=K,
        image_size=THESIS_IMAGE_SIZE,
        axes_triple_product=triple,
    )


def estimate_fundamental(
    points1_px: np.ndarray, points2_px: np.ndarray, estimator: FundamentalEstimator
) -> np.ndarray | None:
    """F (``x2ᵀ F x1 = 0``, unit norm, rank 2) from (N, 2) pixel correspondences, or None.

    Every estimator is one of :mod:`recon.sfm.fundamental`'s.
    """
    if estimator is FundamentalEstimator.LMEDS_REFIT:
        return refit_fundamental(points1_px, points2_px)
    F = eight_point(points1_px, points2_px)
    if F is not None and estimator is FundamentalEstimator.SAMPSON:
        return refine_sampson(F, points1_px, points2_px)
    return F


@dataclass(frozen=True)
class LevelTrials:
    """Raw per-trial outcomes of one (configuration, σ) level."""

    focal_px: np.ndarray  # (trials,), NaN where the pair gave no focal
    statuses: tuple[PairStatus, ...]
    conditioning: np.ndarray  # (trials,)
    seconds: float


def _level_rng(
    seed: int, configuration: SceneConfiguration, sigma_px: float
) -> np.random.Generator:
    # One stream per (configuration, σ): a level's noise does not depend on which other levels
    # or configurations are run, so a small run reproduces rows of the full one.
    key = [seed, zlib.crc32(configuration.value.encode()), round(sigma_px * 1e6)]
    return np.random.default_rng(np.random.SeedSequence(key))


def simulate_level(
    scene: TwoViewScene,
    *,
    sigma_px: float,
    trials: int,
    estimator: FundamentalEstimator,
    seed: int,
    kruppa: KruppaConfig | None = None,
) -> LevelTrials:
    """``trials`` noisy pairs of ``scene`` → F → focal (pure, deterministic in ``seed``).

    A trial whose F cannot be estimated at all gets status ``invalid-F`` and no focal.
    """
    rng = _level_rng(seed, scene.configuration, sigma_px)
    kruppa = kruppa if kruppa is not None else KruppaConfig()
    focal = np.full(trials, np.nan)
    conditioning = np.zeros(trials)
    statuses: list[PairStatus] = []
    start = time.perf_counter()
    for k in range(trials):
        noisy1 = scene.pixels_in_image1 + rng.normal(0.0, sigma_px, scene.pixels_in_image1.shape)
        noisy2 = scene.pixels_in_image2 + rng.normal(0.0, sigma_px, scene.pixels_in_image2.shape)
        F = estimate_fundamental(noisy1, noisy2, estimator)
        if F is None:
            statuses.append(PairStatus.INVALID_F)
            continue
        pair = focal_from_fundamental(
            F,
            principal_point=scene.principal_point,
            image_size=scene.image_size,
            config=kruppa,
        )
        statuses.append(pair.status)
        conditioning[k] = pair.conditioning
        if pair.focal_px is not None:
            focal[k] = pair.focal_px
    return LevelTrials(
        focal_px=focal,
        statuses=tuple(statuses),
        conditioning=conditioning,
        seconds=time.perf_counter() - start,
    )


@dataclass(frozen=True, kw_only=True)
class LevelErrors:
    """The figures of one level; see the module docstring for the definitions."""

    trials: int
    n_ok: int
    flagged_fraction: float
    status_counts: dict[str, int]
    thesis_rel_error: float | None
    rel_error_of_mean: float | None
    rel_error_of_mean_se: float | None
    mean_abs_rel_error: float | None
    median_abs_rel_error: float | None
    n_with_focal: int
    median_abs_rel_error_any_status: float | None


def summarise_level(
    focal_px: np.ndarray, statuses: Sequence[PairStatus], *, true_focal_px: float
) -> LevelErrors:
    """Error figures over the ok trials (and the flagged ones separately); pure."""
    focal_px = np.asarray(focal_px, dtype=float)
    if len(focal_px) != len(statuses) or len(statuses) == 0:
        raise ValueError("one focal value (NaN for none) and one status per trial are needed")
    ok = np.array([s == PairStatus.OK for s in statuses]) & np.isfinite(focal_px)
    errors = focal_px[ok] / true_focal_px - 1.0
    any_status = focal_px[np.isfinite(focal_px)] / true_focal_px - 1.0
    counts = {s.value: 0 for s in PairStatus}
    for s in statuses:
        counts[PairStatus(s).value] += 1
    n_ok = int(ok.sum())
    bias = float(errors.mean()) if n_ok else None
    return LevelErrors(
        trials=len(statuses),
        n_ok=n_ok,
        flagged_fraction=1.0 - n_ok / len(statuses),
        status_counts=counts,
        thesis_rel_error=abs(bias) if bias is not None else None,
        rel_error_of_mean=bias,
        rel_error_of_mean_se=float(errors.std(ddof=1) / math.sqrt(n_ok)) if n_ok > 1 else None,
        mean_abs_rel_error=float(np.abs(errors).mean()) if n_ok else None,
        median_abs_rel_error=float(np.median(np.abs(errors))) if n_ok else None,
        n_with_focal=len(any_status),
        median_abs_rel_error_any_status=(
            float(np.median(np.abs(any_status))) if len(any_status) else None
        ),
    )


@dataclass(frozen=True, kw_only=True)
class KruppaNoiseRow:
    """One table row: a configuration at one noise level."""

    configuration: SceneConfiguration
    sigma_px: float
    errors: LevelErrors
    seconds: float
    focal_px: tuple[float | None, ...]  # per trial, None for no value
    statuses: tuple[PairStatus, ...]  # per trial


# Column order of table.csv; status_<name> columns follow, one per PairStatus.
CSV_COLUMNS: tuple[str, ...] = (
    "configuration",
    "sigma_px",
    "trials",
    "n_ok",
    "flagged_fraction",
    "thesis_rel_error",
    "rel_error_of_mean",
    "rel_error_of_mean_se",
    "mean_abs_rel_error",
    "median_abs_rel_error",
    "n_with_focal",
    "median_abs_rel_error_any_status",
    "seconds",
    *(f"status_{s.value.replace('-', '_')}" for s in PairStatus),
)


@dataclass(frozen=True, kw_only=True)
class SceneSummary:
    configuration: SceneConfiguration
    points_used: int
    axes_triple_product: float
    # focal_from_fundamental on the exact F: what the configuration allows without noise.
    noise_free_status: PairStatus
    noise_free_focal_px: float | None
    noise_free_conditioning: float


@dataclass(frozen=True)
class KruppaNoiseReport:
    config: KruppaNoiseConfig
    scenes: tuple[SceneSummary, ...]
    rows: tuple[KruppaNoiseRow, ...]
    seconds: float
    outputs: dict[str, Path] = field(default_factory=dict)

    def csv_rows(self) -> list[dict[str, Any]]:
        out = []
        for row in self.rows:
            e = row.errors
            values: dict[str, Any] = {
                "configuration": row.configuration.value,
                "sigma_px": row.sigma_px,
                "trials": e.trials,
                "n_ok": e.n_ok,
                "flagged_fraction": e.flagged_fraction,
                "thesis_rel_error": e.thesis_rel_error,
                "rel_error_of_mean": e.rel_error_of_mean,
                "rel_error_of_mean_se": e.rel_error_of_mean_se,
                "mean_abs_rel_error": e.mean_abs_rel_error,
                "median_abs_rel_error": e.median_abs_rel_error,
                "n_with_focal": e.n_with_focal,
                "median_abs_rel_error_any_status": e.median_abs_rel_error_any_status,
                "seconds": round(row.seconds, 4),
            }
            for status, count in e.status_counts.items():
                values[f"status_{status.replace('-', '_')}"] = count
            out.append(values)
        return out

    def as_json(self) -> dict[str, Any]:
        return {
            "format": "mocap-experiment-kruppa-noise-v1",
            "config": {k: _jsonable(v) for k, v in asdict(self.config).items()},
            "true_focal_px": self.config.focal_px,
            "principal_point_px": THESIS_PRINCIPAL_POINT_PX,
            "image_size": THESIS_IMAGE_SIZE,
            "thesis_reported_rel_error": THESIS_REPORTED_REL_ERROR,
            "thesis_reported_source": THESIS_REPORTED_SOURCE,
            "definitions": _DEFINITIONS,
            "scenes": [{k: _jsonable(v) for k, v in asdict(s).items()} for s in self.scenes],
            "rows": [
                row_csv | {"per_trial": {
                    "focal_px": list(row.focal_px),
                    "status": [s.value for s in row.statuses],
                }}
                for row, row_csv in zip(self.rows, self.csv_rows(), strict=True)
            ],
            "seconds": self.seconds,
        }

    def lines(self) -> list[str]:
        c = self.config
        out = [
            f"kruppa-noise: f = {c.focal_px:g} px, {c.trials} trials per level, F by "
            f"{c.estimator.value}, seed {c.seed}",
        ]
        for s in self.scenes:
            noise_free = "none" if s.noise_free_focal_px is None else f"{s.noise_free_focal_px:.4f}"
            out.append(
                f"  {s.configuration.value:<17} {s.points_used} points, axes triple product "
                f"{s.axes_triple_product:.3f}, noise-free: {s.noise_free_status.value} "
                f"(focal {noise_free} px, conditioning {s.noise_free_conditioning:.3f})"
            )
        out += [
            "",
            f"{'configuration':<17}{'σ px':>6}{'ok':>9}{'|err of mean|':>15}{'± SE':>8}"
            f"{'mean|err|':>11}{'median|err|':>13}{'flagged':>9}{'any-status med':>16}"
            f"{'s':>6}",
        ]
        for row in self.rows:
            e = row.errors
            out.append(
                f"{row.configuration.value:<17}{row.sigma_px:>6.2f}{f'{e.n_ok}/{e.trials}':>9}"
                f"{_pct(e.thesis_rel_error):>15}{_pct(e.rel_error_of_mean_se):>8}"
                f"{_pct(e.mean_abs_rel_error):>11}{_pct(e.median_abs_rel_error):>13}"
                f"{_pct(e.flagged_fraction, 0):>9}{_pct(e.median_abs_rel_error_any_status):>16}"
                f"{row.seconds:>6.2f}"
            )
        slipped = [
            c.value for c in self.config.configurations
            if c.singular and any(r.errors.n_ok for r in self.rows if r.configuration is c)
        ]
        if slipped:
            out += ["", f"note: {', '.join(slipped)} is singular: its ok figures rest on the few "
                    "noisy pairs that escaped the flag (see the flagged column)"]
        out += [
            "",
            "|err of mean| = |mean(f̂)/f - 1| over the ok trials (the thesis' metric); flagged = "
            "not ok; any-status med = median |f̂/f - 1| of every value returned, flagged or not",
            f"peer figure: ~{100 * THESIS_REPORTED_REL_ERROR:g}% ({THESIS_REPORTED_SOURCE})",
            f"total {self.seconds:.1f} s",
            *(f"{k:<10}{v}" for k, v in self.outputs.items()),
        ]
        return out

    def markdown(self) -> str:
        c = self.config
        lines = [
            "# Kruppa focal error against image noise (thesis §4.5.1, reproduced)",
            "",
            f"f = {c.focal_px:g} px, principal point {THESIS_PRINCIPAL_POINT_PX}, "
            f"{THESIS_IMAGE_SIZE[0]}×{THESIS_IMAGE_SIZE[1]} images; two grids of 120 points at "
            f"135°, ridge {c.distance:g} units ahead; camera 2 orbits by {c.orbit_deg:g}° "
            f"(tilted: and tilts down {c.tilt_deg:g}°). {c.trials} trials per level, F by "
            f"`{c.estimator.value}`, seed {c.seed}.",
            "",
            "## Definitions",
            "",
            *(f"- **{k}**: {v}" for k, v in _DEFINITIONS.items()),
            "",
            f"Peer figure: ~{100 * THESIS_REPORTED_REL_ERROR:g}% — {THESIS_REPORTED_SOURCE}.",
            "",
            "## Scenes",
            "",
            "| configuration | points | axes triple product | noise-free status | "
            "noise-free focal px | conditioning |",
            "|---|---:|---:|---|---:|---:|",
        ]
        for s in self.scenes:
            noise_free = "—" if s.noise_free_focal_px is None else f"{s.noise_free_focal_px:.4f}"
            lines.append(
                f"| {s.configuration.value} | {s.points_used} | {s.axes_triple_product:.3f} | "
                f"{s.noise_free_status.value} | {noise_free} | {s.noise_free_conditioning:.3f} |"
            )
        lines += [
            "",
            "## Results",
            "",
            "| configuration | σ px | ok | thesis metric | bias ± SE | mean abs | median abs | "
            "flagged | median abs, any status | statuses |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
        ]
        for row in self.rows:
            e = row.errors
            statuses = ", ".join(f"{k} {v}" for k, v in e.status_counts.items() if v)
            bias = (
                "—" if e.rel_error_of_mean is None
                else f"{_pct(e.rel_error_of_mean, sign=True)} ± {_pct(e.rel_error_of_mean_se)}"
            )
            lines.append(
                f"| {row.configuration.value} | {row.sigma_px:.2f} | {e.n_ok}/{e.trials} | "
                f"{_pct(e.thesis_rel_error)} | {bias} | {_pct(e.mean_abs_rel_error)} | "
                f"{_pct(e.median_abs_rel_error)} | {_pct(e.flagged_fraction, 0)} | "
                f"{_pct(e.median_abs_rel_error_any_status)} | {statuses} |"
            )
        lines += ["", "![error against noise](error_vs_noise.png)", ""]
        return "\n".join(lines)


_DEFINITIONS: dict[str, str] = {
    "e_k": "f̂_k / f − 1 for each trial whose pair status is ok (flagged pairs never count)",
    "thesis_rel_error": "|mean_k f̂_k / f − 1| over the ok trials: the thesis' metric (the "
    "average of the 50 estimates compared with the truth, §4.5.1.2); includes the sampling "
    "noise of the mean, see rel_error_of_mean_se",
    "rel_error_of_mean": "mean_k e_k, signed (the bias estimate)",
    "rel_error_of_mean_se": "std(e_k) / √n_ok, its standard error",
    "mean_abs_rel_error": "mean_k |e_k|: the typical error of one pair",
    "median_abs_rel_error": "median_k |e_k|",
    "flagged_fraction": "trials whose status is not ok, over all trials",
    "median_abs_rel_error_any_status": "median |f̂/f − 1| over every trial that returned a "
    "focal, flagged or not (how wrong the flagged values would have been)",
}


def _pct(value: float | None, digits: int = 2, *, sign: bool = False) -> str:
    if value is None:
        return "—"
    return f"{100 * value:{'+' if sign else ''}.{digits}f}%"


def _jsonable(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    return value


def compute_kruppa_noise(
    config: KruppaNoiseConfig, *, kruppa: KruppaConfig | None = None
) -> KruppaNoiseReport:
    """Every configuration at every σ (pure computation, no files)."""
    kruppa = kruppa if kruppa is not None else KruppaConfig()
    start = time.perf_counter()
    scenes: list[SceneSummary] = []
    rows: list[KruppaNoiseRow] = []
    for configuration in config.configurations:
        scene = build_scene(configuration, config)
        exact = focal_from_fundamental(
            scene.true_fundamental,
            principal_point=scene.principal_point,
            image_size=scene.image_size,
            config=kruppa,
        )
        scenes.append(
            SceneSummary(
                configuration=configuration,
                points_used=len(scene.points_in_cam1),
                axes_triple_product=scene.axes_triple_product,
                noise_free_status=exact.status,
                noise_free_focal_px=exact.focal_px,
                noise_free_conditioning=exact.conditioning,
            )
        )
        for sigma_px in config.sigmas_px:
            level = simulate_level(
                scene,
                sigma_px=sigma_px,
                trials=config.trials,
                estimator=config.estimator,
                seed=config.seed,
                kruppa=kruppa,
            )
            rows.append(
                KruppaNoiseRow(
                    configuration=configuration,
                    sigma_px=sigma_px,
                    errors=summarise_level(
                        level.focal_px, level.statuses, true_focal_px=config.focal_px
                    ),
                    seconds=level.seconds,
                    focal_px=tuple(None if math.isnan(v) else float(v) for v in level.focal_px),
                    statuses=level.statuses,
                )
            )
    return KruppaNoiseReport(
        config=config,
        scenes=tuple(scenes),
        rows=tuple(rows),
        seconds=time.perf_counter() - start,
    )


def _error_curves(report: KruppaNoiseReport) -> dict[str, list[float]]:
    """Curves in percent, NaN where a level has no value (matplotlib leaves a gap)."""

    def pct(values: list[float | None]) -> list[float]:
        return [math.nan if v is None else 100.0 * v for v in values]

    curves: dict[str, list[float]] = {}
    for configuration in report.config.configurations:
        rows = [r for r in report.rows if r.configuration is configuration]
        if configuration.singular:
            # Its ok-only figures rest on the few pairs that slipped through: show instead how
            # wrong the values are and how many were flagged.
            flagged = sum(r.errors.trials - r.errors.n_ok for r in rows)
            total = sum(r.errors.trials for r in rows)
            label = (f"{configuration.value}: median |error|, all values "
                     f"({100 * flagged / total:.0f}% flagged)")
            curves[label] = pct([r.errors.median_abs_rel_error_any_status for r in rows])
            continue
        curves[f"{configuration.value}: |error of the mean| (thesis)"] = pct(
            [r.errors.thesis_rel_error for r in rows]
        )
        curves[f"{configuration.value}: mean |error|"] = pct(
            [r.errors.mean_abs_rel_error for r in rows]
        )
        curves[f"{configuration.value}: median |error|"] = pct(
            [r.errors.median_abs_rel_error for r in rows]
        )
    return curves


def write_kruppa_noise(report: KruppaNoiseReport, out: Path) -> dict[str, Path]:
    """Write OUT/{table.csv, report.md, error_vs_noise.png, results.json}, each atomically."""
    # Imported here: matplotlib costs ~0.3 s, and `mocap --help` needs none of it.
    from recon import plots

    out.mkdir(parents=True, exist_ok=True)
    outputs = {
        "table": out / "table.csv",
        "report": out / "report.md",
        "plot": out / "error_vs_noise.png",
        "results": out / "results.json",
    }
    with atomic_output(outputs["table"]) as tmp, tmp.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(CSV_COLUMNS))
        writer.writeheader()
        for values in report.csv_rows():
            # Undefined figures (no ok trial) are empty cells, not "None".
            writer.writerow({k: "" if v is None else v for k, v in values.items()})
    with atomic_output(outputs["report"]) as tmp:
        tmp.write_text(report.markdown())
    c = report.config
    plots.error_curves(
        outputs["plot"],
        list(c.sigmas_px),
        _error_curves(report),
        xlabel="noise σ (px)",
        ylabel="relative focal error (%)",
        title=f"Kruppa focal vs noise: f = {c.focal_px:g} px, {c.trials} trials per level, "
        f"F by {c.estimator.value}",
    )
    write_json_atomic(outputs["results"], report.as_json())
    return outputs


def run_kruppa_noise(config: KruppaNoiseConfig) -> KruppaNoiseReport:
    """Compute the experiment, then write its four files under ``config.out``."""
    report = compute_kruppa_noise(config)
    return replace(report, outputs=write_kruppa_noise(report, config.out))
