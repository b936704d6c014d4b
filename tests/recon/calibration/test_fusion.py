"""Fusing per-pair focal estimates over many image pairs, against synthetic truth.

Scenes: several views of a point cloud with F estimated by OpenCV from noisy projections
(σ in px), some pairs with wrong matches, and a camera ring aimed at one point (the temple
configuration, singular for every pair).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from recon.calibration.fusion import (
    FusionConfig,
    FusionMethod,
    FusionStatus,
    estimate_focal_joint,
    fuse_pair_focals,
)
from recon.calibration.kruppa import KruppaMethod, PairFocal, PairStatus, focal_from_fundamental

SIZE = (640, 480)
PP = (320.0, 240.0)


def look_at(
    centre: np.ndarray, target: np.ndarray, up: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """cam_from_world (R, t) with the optical axis (+z) through ``target``."""
    z = (target - centre) / np.linalg.norm(target - centre)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    return R, -R @ centre


def project(K: np.ndarray, cam: tuple[np.ndarray, np.ndarray], points: np.ndarray) -> np.ndarray:
    R, t = cam
    x = (K @ (points @ R.T + t).T).T
    return x[:, :2] / x[:, 2:]


def multi_view_pairs(
    focal_px: float,
    *,
    layout: str,
    seed: int,
    sigma_px: float = 1.0,
    wrong_pairs: int = 0,
) -> tuple[list[PairFocal], list[int], list[tuple[int, int]]]:
    """Per-pair estimates for every pair of views seeing ≥ 30 common points.

    ``layout``: "generic" (views around the scene at varied distances, aimed at varied
    points) or "ring" (16 views on a horizontal circle aimed at the centre: coplanar axes,
    equidistant centres, with 0.1% jitter).
    """
    rng = np.random.default_rng(seed)
    K = np.array([[focal_px, 0, PP[0]], [0, focal_px, PP[1]], [0, 0, 1.0]])
    points = rng.uniform(-1, 1, (500, 3)) * [1.0, 1.0, 0.6]
    distance = 1.6 * focal_px / (0.5 * max(SIZE))
    cams = []
    if layout == "ring":
        for k in range(16):
            azimuth = 2 * math.pi * k / 16
            centre = distance * np.array([math.sin(azimuth), -0.4, -math.cos(azimuth)])
            cams.append(look_at(centre, rng.normal(0, 1e-3, 3), np.array([0, -1.0, 0])))
    else:
        for _ in range(10):
            d = rng.normal(size=3)
            d[2] = -abs(d[2]) - 0.5
            d /= np.linalg.norm(d)
            up = np.array([0, -1.0, 0]) + rng.normal(0, 0.1, 3)
            cams.append(look_at(distance * rng.uniform(0.7, 1.4) * d, rng.normal(0, 0.35, 3), up))
    pairs: list[PairFocal] = []
    inliers: list[int] = []
    ids: list[tuple[int, int]] = []
    for i in range(len(cams)):
        for j in range(i + 1, len(cams)):
            x1, x2 = project(K, cams[i], points), project(K, cams[j], points)
            seen = np.all((x1 >= 0) & (x1 < SIZE) & (x2 >= 0) & (x2 < SIZE), axis=1)
            angle = math.degrees(math.acos(np.clip(cams[i][0][2] @ cams[j][0][2], -1, 1)))
            if seen.sum() < 30 or angle > 60:
                continue
            n1 = x1[seen] + rng.normal(0, sigma_px, (seen.sum(), 2))
            n2 = x2[seen] + rng.normal(0, sigma_px, (seen.sum(), 2))
            count = int(seen.sum())
            if len(pairs) < wrong_pairs:  # wrong matches: most correspondences shuffled
                keep = rng.random(count) < 0.3
                n2 = np.where(keep[:, None], n2, n2[rng.permutation(count)])
                count = 20
            F, _ = cv2.findFundamentalMat(n1, n2, cv2.FM_8POINT)
            pairs.append(focal_from_fundamental(F, principal_point=PP, image_size=SIZE))
            inliers.append(count)
            ids.append((i, j))
    return pairs, inliers, ids


def pair(focal_px: float | None, status: PairStatus, conditioning: float = 0.1) -> PairFocal:
    return PairFocal(
        focal_px=focal_px,
        status=status,
        conditioning=conditioning,
        method=KruppaMethod.QUADRATIC,
        candidates=() if focal_px is None else (focal_px,),
    )


@pytest.mark.parametrize("estimator", [fuse_pair_focals, estimate_focal_joint])
@pytest.mark.parametrize("focal", [600.0, 1500.0])
def test_many_pairs_recover_the_focal_despite_wrong_and_near_singular_pairs(
    estimator, focal: float
) -> None:
    pairs, inliers, ids = multi_view_pairs(focal, layout="generic", seed=3, wrong_pairs=4)
    statuses = {p.status for p in pairs}
    assert PairStatus.OK in statuses and len(statuses) > 1  # a mixed bag, as in real data
    wrong = [p.focal_px for p in pairs[:4] if p.focal_px is not None]
    assert any(abs(v / focal - 1) > 0.05 for v in wrong)  # the wrong pairs really are wrong
    result = estimator(pairs, num_inliers=inliers, image_ids=ids)
    assert result.status == FusionStatus.OK
    assert result.focal_px == pytest.approx(focal, rel=0.01)
    assert result.sigma_px is not None and 0 < result.sigma_px < 0.02 * focal
    assert abs(result.focal_px - focal) <= 3 * result.sigma_px
    assert result.num_pairs == len(pairs)
    assert 3 <= result.num_pairs_used <= len(pairs)
    assert sum(n for _, n in result.status_counts) == len(pairs)


def test_uncertainty_covers_the_truth_across_scenes() -> None:
    within_2_sigma = []
    for seed in range(12):
        pairs, inliers, ids = multi_view_pairs(900.0, layout="generic", seed=100 + seed)
        result = fuse_pair_focals(pairs, num_inliers=inliers, image_ids=ids)
        assert result.focal_px is not None and result.sigma_px is not None
        within_2_sigma.append(abs(result.focal_px - 900.0) <= 2 * result.sigma_px)
    # A calibrated 1σ would put ~95% within 2σ; accept a modest overconfidence.
    assert np.mean(within_2_sigma) >= 0.8


def test_a_ring_aimed_at_one_point_is_flagged_not_trusted() -> None:
    # The temple configuration: every pair has coplanar axes and equidistant centres.
    pairs, inliers, ids = multi_view_pairs(1523.0, layout="ring", seed=5, sigma_px=0.5)
    assert len(pairs) >= 30
    not_ok = [p for p in pairs if p.status != PairStatus.OK]
    assert len(not_ok) >= 0.9 * len(pairs)
    assert all(p.focal_px is None or (math.isfinite(p.focal_px) and p.focal_px > 0) for p in pairs)
    for estimator in (fuse_pair_focals, estimate_focal_joint):
        result = estimator(pairs, num_inliers=inliers, image_ids=ids)
        assert result.status != FusionStatus.OK
        if result.focal_px is not None and result.sigma_px is not None:
            # Whatever it returns, it must not claim to be precise.
            assert result.sigma_px > 0.05 * result.focal_px


def test_robust_mean_ignores_outliers_and_non_ok_pairs() -> None:
    rng = np.random.default_rng(7)
    good = [pair(float(v), PairStatus.OK) for v in 1000 * np.exp(rng.normal(0, 0.02, 20))]
    bad = [pair(v, PairStatus.OK) for v in (310.0, 4200.0, 5000.0)]
    near_singular = [pair(v, PairStatus.NEAR_SINGULAR, 0.003) for v in (150.0, 9000.0)]
    failed = [pair(None, s, 0.0) for s in (PairStatus.NO_REAL_ROOT, PairStatus.PURE_ROTATION)]
    result = fuse_pair_focals(good + bad + near_singular + failed)
    assert result.status == FusionStatus.OK
    assert result.focal_px is not None
    assert result.focal_px == pytest.approx(1000.0, rel=0.01)
    assert result.sigma_px is not None and result.sigma_px < 20.0
    assert abs(result.focal_px - 1000.0) <= 3 * result.sigma_px
    assert result.num_pairs == 27
    assert result.num_pairs_used <= 20
    assert dict(result.status_counts) == {
        "ok": 23,
        "near-singular": 2,
        "no-real-root": 1,
        "pure-rotation": 1,
    }


def test_inlier_counts_and_conditioning_weigh_the_pairs() -> None:
    # Two clusters: many matches and sharp conditioning at 800, few and blunt at 1000.
    strong = [pair(800.0 * (1 + d), PairStatus.OK, 0.2) for d in (-0.01, 0.0, 0.01)]
    weak = [pair(1000.0 * (1 + d), PairStatus.OK, 0.03) for d in (-0.01, 0.0, 0.005, 0.01)]
    inliers = [2000] * 3 + [40] * 4
    result = fuse_pair_focals(strong + weak, num_inliers=inliers)
    assert result.focal_px == pytest.approx(800.0, rel=0.02)
    unweighted = fuse_pair_focals(strong + weak, config=FusionConfig(inlier_cap=1))
    assert unweighted.focal_px is not None and unweighted.focal_px < 900.0  # conditioning
    with pytest.raises(ValueError, match="inlier counts"):
        fuse_pair_focals(strong, num_inliers=[10])
    with pytest.raises(ValueError, match="image id pairs"):
        estimate_focal_joint(strong, image_ids=[(0, 1)])


def test_all_failed_or_empty_input_gives_no_focal() -> None:
    failed = [
        pair(None, PairStatus.NO_REAL_ROOT, 0.0),
        pair(None, PairStatus.RANK_DEFICIENT_F, 0.0),
        pair(None, PairStatus.OUT_OF_RANGE, 0.0),
    ]
    for pairs in (failed, []):
        for estimator in (fuse_pair_focals, estimate_focal_joint):
            result = estimator(pairs)
            assert result.status == FusionStatus.NO_VALID_PAIRS
            assert result.focal_px is None and result.sigma_px is None
            assert result.num_pairs_used == 0 and result.num_pairs == len(pairs)
            assert result.message


def test_only_near_singular_pairs_give_a_low_confidence_estimate_with_honest_spread() -> None:
    # Sixteen values scattered by a factor e^±0.5: averaging them would claim σ ≈ 12%, but
    # near-singular values are not noisy measurements of f, so σ must be their spread.
    values = 1200.0 * np.exp(np.random.default_rng(8).normal(0, 0.5, 16))
    result = fuse_pair_focals([pair(float(v), PairStatus.NEAR_SINGULAR, 0.004) for v in values])
    assert result.status == FusionStatus.LOW_CONFIDENCE
    assert "near-singular" in result.message
    assert result.focal_px is not None and values.min() <= result.focal_px <= values.max()
    assert result.sigma_px is not None and result.sigma_px > 0.3 * result.focal_px
    strict = fuse_pair_focals(
        [pair(float(v), PairStatus.NEAR_SINGULAR, 0.004) for v in values],
        config=FusionConfig(use_near_singular_fallback=False),
    )
    assert strict.status == FusionStatus.NO_VALID_PAIRS and strict.focal_px is None


def test_a_single_pair_is_low_confidence_without_a_made_up_sigma() -> None:
    result = fuse_pair_focals([pair(1234.0, PairStatus.OK)])
    assert result.status == FusionStatus.LOW_CONFIDENCE
    assert result.focal_px == pytest.approx(1234.0)
    assert result.sigma_px is None
    assert result.method == FusionMethod.PER_PAIR
