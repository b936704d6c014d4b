"""Kruppa focal on the thesis' synthetic scene at σ = 1 px, against the thesis' reported ~2%.

    .venv/bin/python benchmarks/kruppa_synthetic.py [--trials 2000] [--batch 50] [--seed 0]

The scene and the F estimators are those of `mocap experiment kruppa-noise`
(:mod:`recon.calibration.experiment`): two 120-point grids at 135°, 1000 units ahead,
f = 600 px, camera 2 orbited 30° and tilted down 10° (optical axes not coplanar).

The figure: the thesis' metric, the relative error of the mean of 50 estimates, |mean(f̂)/f - 1|
("The average of these 50 estimations is then taken as the estimated calibrated focal length",
thesis §4.5.1.2). One batch of 50 is itself noisy (one pair scatters by ~4% at 1 px, so the
mean of 50 by ~0.6%), so the trials are split into batches of 50 and the figure is the average
of the batches' metrics, i.e. the expected value of the thesis' own procedure, with its
standard error over batches. Also printed: the pooled bias (the same metric with all trials,
its limit for many trials) and mean |f̂/f - 1| (one pair's typical error).

Peer figure: ~2%, thesis §4.5.1.2 under Figure 4.3 ("mostly around 2%").
Target: the figure ≤ 1% with the default estimator. Exit status 1 when it fails.

Issue 22 (``--pp-trials``): one pair cannot give a principal point (two Kruppa equations,
three unknowns), so the free-principal-point fit runs on a multi-view version of the thesis
scene: camera 1 and four views orbiting the ridge point by ±15°/±30° and tilted by ±5°/±10°
(10 pairs), and a generic scene of 8 views around a point cloud aimed at varied points; F by
Sampson. Each point has one noisy keypoint per image, shared by that image's pairs, and the
same draws at both offsets. Printed per σ: mean |focal error| of the centred closed form
(fused) at zero and at 20 px principal-point offset, and at 20 px offset of kruppa-pp and of
kruppa-pp-epipolar (every pair's inliers; `estimate_intrinsics_epipolar`), each the centred
value when its principal point is rejected, with their principal-point errors. Target: each
at 20 px ≤ centred at zero offset. Also: focals varying up to 2× across the views (per-image
mode, σ = 0.5 px), each within 1%.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from recon.calibration.experiment import (
    THESIS_REPORTED_REL_ERROR,
    THESIS_REPORTED_SOURCE,
    FundamentalEstimator,
    KruppaNoiseConfig,
    SceneConfiguration,
    build_scene,
    simulate_level,
)
from recon.calibration.kruppa import PairStatus

SIGMA_PX = 1.0
TARGET_REL_ERROR = 0.01


def _pct(value: float, sign: bool = False) -> str:
    return f"{100 * value:{'+' if sign else ''}.2f}%"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=2000, help="trials per estimator")
    parser.add_argument("--batch", type=int, default=50, help="trials per thesis-metric batch")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pp-trials", type=int, default=100,
                        help="multi-view trials for kruppa-pp and per-image (0: skip)")
    args = parser.parse_args()
    batches = args.trials // args.batch
    if batches < 2:
        parser.error("need at least two batches (--trials ≥ 2 × --batch)")

    default = KruppaNoiseConfig().estimator
    # The default first: it is the one the target applies to; the others are for comparison.
    estimators = [default, *(e for e in FundamentalEstimator if e is not default)]
    print(
        f"Kruppa focal, thesis scene (§4.5.1), σ = {SIGMA_PX:g} px, tilted camera 2, "
        f"{batches} batches of {args.batch} trials per estimator, seed {args.seed}"
    )
    print(f"peer figure: ~{_pct(THESIS_REPORTED_REL_ERROR)} — {THESIS_REPORTED_SOURCE}")
    print()
    print(
        f"{'F estimator':<13}{'ok':>11}{'thesis metric/50':>18}{'± SE':>8}"
        f"{'pooled bias':>13}{'± SE':>8}{'mean|err|':>11}{'± SE':>8}{'median|err|':>13}"
        f"{'vs thesis':>11}{'ms/trial':>10}"
    )
    verdict: tuple[float, float] | None = None
    for estimator in estimators:
        config = KruppaNoiseConfig(estimator=estimator, seed=args.seed, trials=args.trials)
        scene = build_scene(SceneConfiguration.TILTED, config)
        start = time.perf_counter()
        level = simulate_level(
            scene,
            sigma_px=SIGMA_PX,
            trials=batches * args.batch,
            estimator=estimator,
            seed=args.seed,
        )
        ms_per_trial = 1000 * (time.perf_counter() - start) / (batches * args.batch)
        ok = np.array([s == PairStatus.OK for s in level.statuses]) & np.isfinite(level.focal_px)
        errors = np.where(ok, level.focal_px / config.focal_px - 1.0, np.nan)
        # The thesis' metric per batch of 50, over that batch's ok trials.
        per_batch = np.abs(np.nanmean(errors.reshape(batches, args.batch), axis=1))
        figure = float(per_batch.mean())
        figure_se = float(per_batch.std(ddof=1) / math.sqrt(batches))
        valid = errors[ok]
        n = len(valid)
        bias, bias_se = float(valid.mean()), float(valid.std(ddof=1) / math.sqrt(n))
        abs_err = np.abs(valid)
        print(
            f"{estimator.value:<13}{f'{n}/{len(errors)}':>11}{_pct(figure):>18}"
            f"{_pct(figure_se):>8}{_pct(bias, sign=True):>13}{_pct(bias_se):>8}"
            f"{_pct(float(abs_err.mean())):>11}{_pct(float(abs_err.std(ddof=1) / math.sqrt(n))):>8}"
            f"{_pct(float(np.median(abs_err))):>13}"
            f"{figure / THESIS_REPORTED_REL_ERROR:>10.2f}×{ms_per_trial:>10.1f}"
        )
        if estimator is default:
            verdict = (figure, figure_se)
    assert verdict is not None
    figure, figure_se = verdict
    if args.pp_trials:
        _principal_point_and_per_image(args.pp_trials, args.seed)
    passed = figure <= TARGET_REL_ERROR
    print()
    print(
        f"target: thesis metric (expected |mean of {args.batch} estimates / f - 1|) ≤ "
        f"{_pct(TARGET_REL_ERROR)} with F by {default.value}: {_pct(figure)} ± {_pct(figure_se)} "
        f"({(TARGET_REL_ERROR - figure) / figure_se:+.1f} SE of margin) → "
        f"{'PASS' if passed else 'FAIL'}"
    )
    return 0 if passed else 1


def _multi_view_scene(offset_px: tuple[float, float], focals_px: list[float]):
    """Noise-free pixels of the thesis grids in five views: (K, R, t) per view and points."""
    from recon.calibration.experiment import _grid_points_in_cam1, _rotation

    distance = 1000.0
    points = _grid_points_in_cam1(distance)
    ridge = np.array([0.0, 0.0, distance])
    views = [(0.0, 0.0), (-30.0, 10.0), (-15.0, -5.0), (15.0, 5.0), (30.0, -10.0)]
    out = []
    for (orbit_deg, tilt_deg), focal in zip(views, focals_px, strict=True):
        orbit = _rotation((0.0, 1.0, 0.0), orbit_deg)
        centre = ridge - orbit @ ridge
        R = _rotation((1.0, 0.0, 0.0), tilt_deg) @ orbit.T
        K = np.array([[focal, 0, 320 + offset_px[0]], [0, focal, 240 + offset_px[1]], [0, 0, 1]])
        out.append((K, R, -R @ centre))
    return out, points


def _random_scene(
    rng: np.random.Generator, offset_px: tuple[float, float], focals_px: list[float] | None = None
):
    """A generic scene: views around a unit cloud of 400 points at 0.7-1.4× a distance that
    fills the image, aimed at varied points (as the fusion and kruppa_joint tests)."""
    focals_px = focals_px or [600.0] * 8
    points = rng.uniform(-1, 1, (400, 3)) * [1.0, 1.0, 0.6]
    distance = 1.6 * float(np.exp(np.mean(np.log(focals_px)))) / 320.0
    views = []
    for focal in focals_px:
        K = np.array([[focal, 0, 320 + offset_px[0]], [0, focal, 240 + offset_px[1]], [0, 0, 1]])
        d = rng.normal(size=3)
        d[2] = -abs(d[2]) - 0.5
        d /= np.linalg.norm(d)
        centre = distance * rng.uniform(0.7, 1.4) * d
        z = rng.normal(0, 0.35, 3) - centre
        z /= np.linalg.norm(z)
        x = np.cross(np.array([0, -1.0, 0]) + rng.normal(0, 0.1, 3), z)
        x /= np.linalg.norm(x)
        R = np.vstack([x, np.cross(z, x), z])
        views.append((K, R, -R @ centre))
    return views, points


def _noisy_pairs(views, points, sigma_px, rng):
    """(F, i, j, number of matches, pixels in i, pixels in j) for every pair seeing ≥ 30
    common points, F by Sampson. Each point has one noisy keypoint per image, shared by that
    image's pairs, and drawn for every point whether or not it is seen: the same `rng` state
    gives the same noise at every principal-point offset (paired trials)."""
    from recon.sfm.fundamental import eight_point, refine_sampson

    noise = rng.normal(0, sigma_px, (len(views), len(points), 2))
    pixels, inside = [], []
    for (K, R, t), view_noise in zip(views, noise, strict=True):
        in_cam = points @ R.T + t
        h = in_cam @ K.T
        px = h[:, :2] / h[:, 2:]
        pixels.append(px + view_noise)
        inside.append((in_cam[:, 2] > 0) & (px[:, 0] >= 0) & (px[:, 0] <= 640)
                      & (px[:, 1] >= 0) & (px[:, 1] <= 480))
    pairs = []
    for i in range(len(views)):
        for j in range(i + 1, len(views)):
            seen = inside[i] & inside[j]
            n = int(seen.sum())
            if n < 30:
                continue
            p1, p2 = pixels[i][seen], pixels[j][seen]
            pairs.append((refine_sampson(eight_point(p1, p2), p1, p2), i, j, n, p1, p2))
    return pairs


def _principal_point_and_per_image(trials: int, seed: int) -> None:
    from recon.calibration.fusion import fuse_pair_focals
    from recon.calibration.kruppa import focal_from_fundamental
    from recon.calibration.kruppa_joint import (
        EpipolarPair,
        JointPair,
        estimate_focal_and_principal_point,
        estimate_focals_per_camera,
        estimate_intrinsics_epipolar,
    )

    size, centre, focal = (640, 480), (320.0, 240.0), 600.0
    print()
    print(f"free principal point, {trials} trials per scene and σ; the same noise draws at "
          "both offsets (paired)")
    print(f"{'scene':<16}{'σ px':>6}{'centred@0':>11}{'centred@20':>12}{'kruppa-pp@20':>14}"
          f"{'accepted':>10}{'pp error px':>13}{'target':>8}{'epipolar@20':>13}{'accepted':>10}"
          f"{'pp error px':>13}{'target':>8}")
    for scene, sigma_px in (("thesis-5-views", 0.1), ("thesis-5-views", 0.5),
                            ("thesis-5-views", SIGMA_PX), ("random-8-views", 0.5),
                            ("random-8-views", SIGMA_PX)):
        rows: dict[str, list[float]] = {
            "centred@0": [], "centred@20": [], "kruppa-pp@20": [], "pp error px": [],
            "accepted": [], "epipolar@20": [], "epipolar pp px": [], "epipolar accepted": []}
        for trial in range(trials):
            for offset in ((0.0, 0.0), (20.0, 20.0)):
                rng = np.random.default_rng([seed, trial, round(sigma_px * 1000)])
                if scene == "thesis-5-views":
                    views, points = _multi_view_scene(offset, [focal] * 5)
                else:
                    views, points = _random_scene(rng, offset)
                pairs = _noisy_pairs(views, points, sigma_px, rng)
                closed = [focal_from_fundamental(F, principal_point=centre, image_size=size)
                          for F, *_ in pairs]
                fused = fuse_pair_focals(closed, num_inliers=[pair[3] for pair in pairs])
                if fused.focal_px is None:
                    continue
                centred_error = abs(fused.focal_px / focal - 1)
                if offset == (0.0, 0.0):
                    rows["centred@0"].append(centred_error)
                    continue
                rows["centred@20"].append(centred_error)
                ok = [k for k, p in enumerate(closed) if p.status == PairStatus.OK]
                fit = estimate_focal_and_principal_point(
                    [pairs[k][0] for k in ok], image_pairs=[pairs[k][1:3] for k in ok],
                    image_size=size, start_focal_px=fused.focal_px,
                    num_inliers=[pairs[k][3] for k in ok],
                )
                rows["accepted"].append(float(fit.accepted))
                if fit.accepted and fit.focal_px is not None and fit.principal_point_px:
                    rows["kruppa-pp@20"].append(abs(fit.focal_px / focal - 1))
                    rows["pp error px"].append(float(np.hypot(fit.principal_point_px[0] - 340,
                                                              fit.principal_point_px[1] - 260)))
                else:  # rejected: the centred result stands
                    rows["kruppa-pp@20"].append(centred_error)
                # kruppa-pp-epipolar: the same pairs' inliers, started from the centred focal.
                epi = estimate_intrinsics_epipolar(
                    [EpipolarPair(F=pairs[k][0], points_i=pairs[k][4], points_j=pairs[k][5],
                                  image_i=pairs[k][1], image_j=pairs[k][2]) for k in ok],
                    image_size=size, start_focal_px=fused.focal_px,
                )
                rows["epipolar accepted"].append(float(epi.accepted))
                if epi.accepted and epi.focal_px is not None and epi.principal_point_px:
                    rows["epipolar@20"].append(abs(epi.focal_px / focal - 1))
                    rows["epipolar pp px"].append(float(np.hypot(epi.principal_point_px[0] - 340,
                                                                 epi.principal_point_px[1] - 260)))
                else:
                    rows["epipolar@20"].append(centred_error)
        mean = {k: float(np.mean(v)) if v else math.nan for k, v in rows.items()}
        pp_err = f"{np.median(rows['pp error px']):.1f}" if rows["pp error px"] else "-"
        epi_pp = f"{np.median(rows['epipolar pp px']):.1f}" if rows["epipolar pp px"] else "-"
        passed = mean["kruppa-pp@20"] <= mean["centred@0"]
        epi_passed = mean["epipolar@20"] <= mean["centred@0"]
        print(f"{scene:<16}{sigma_px:>6g}{_pct(mean['centred@0']):>11}{_pct(mean['centred@20']):>12}"
              f"{_pct(mean['kruppa-pp@20']):>14}{100 * mean['accepted']:>9.0f}%{pp_err:>13}"
              f"{'PASS' if passed else 'FAIL':>8}{_pct(mean['epipolar@20']):>13}"
              f"{100 * mean['epipolar accepted']:>9.0f}%{epi_pp:>13}"
              f"{'PASS' if epi_passed else 'FAIL':>8}")
    print("(mean |focal error| of the fused focal; pp error: median over accepted fits, an axis "
          "held at the centre counts its full offset)")

    rng = np.random.default_rng(seed)
    # Per-image focals, up to 2× apart, σ = 0.5 px.
    print()
    print(f"per-image focals up to 2x apart, σ = 0.5 px, {trials} trials per scene: the worst "
          "camera's |focal error| per trial")
    for scene in ("thesis-5-views", "random-8-views"):
        worst = []
        for trial in range(trials):
            rng = np.random.default_rng([seed, trial, 500])
            if scene == "thesis-5-views":
                focals = [450.0, 900.0, 600.0, 750.0, 520.0]
                views, points = _multi_view_scene((0.0, 0.0), focals)
            else:
                focals = list(np.geomspace(450.0, 900.0, 8))
                rng.shuffle(focals)
                views, points = _random_scene(rng, (0.0, 0.0), focals)
            pairs = _noisy_pairs(views, points, 0.5, rng)
            result, _ = estimate_focals_per_camera(
                [JointPair(F=F, camera_i=i, camera_j=j, num_inliers=n)
                 for F, i, j, n, *_ in pairs],
                principal_points=dict.fromkeys(range(len(focals)), centre),
                image_sizes=dict.fromkeys(range(len(focals)), size),
            )
            errs = [abs(result[c].focal_px / focals[c] - 1) if result[c].focal_px else np.inf
                    for c in range(len(focals))]
            worst.append(max(errs))
        worst_arr = np.array(worst)
        print(f"  {scene:<16} median {_pct(float(np.median(worst_arr)))}, 90th percentile "
              f"{_pct(float(np.percentile(worst_arr, 90)))}; every camera within 1% in "
              f"{100 * np.mean(worst_arr < 0.01):.0f}% of trials, some camera without a focal "
              f"in {100 * np.mean(~np.isfinite(worst_arr)):.0f}%")

if __name__ == "__main__":
    sys.exit(main())
