"""The ``kruppa`` intrinsic initialiser: focal length from the database's fundamental matrices.

After matching, COLMAP's database holds a verified two-view geometry per image pair, with F in
the ``x2ᵀ F x1 = 0`` convention (image 1 = the pair's first image id). Each F gives a
closed-form focal (:func:`recon.calibration.kruppa.focal_from_fundamental`), the pairs are fused
robustly (:mod:`recon.calibration.fusion`), and the result becomes the focal prior of every
camera of that image size. When no focal can be had, the camera falls back to COLMAP's default
start with a warning, so mapping still runs.

Two variants (:mod:`recon.calibration.kruppa_joint`):

- ``principal_point=free`` (the ``kruppa-pp`` plugin): focal and principal point together by
  robust least squares over the ok pairs, started from the closed form, gated by the pairs'
  conditioning and the fit's uncertainty; a principal point rejected (outside the image,
  poorly constrained, too few pairs) leaves exactly the centred ``kruppa`` result. The fit
  uses F refitted from each pair's inliers (Sampson): COLMAP's stored F of two images of one
  camera comes from its shared-focal solver, exactly consistent with the image centre
  (measured on fountain-P11: median residual 4e-16), so it carries no principal point.
  ``principal_point=epipolar`` fits the same unknowns to the inliers' Sampson distances, one
  relative pose per pair (:func:`recon.calibration.kruppa_joint.estimate_intrinsics_epipolar`),
  over every pair with an F and enough inliers.
- ``camera_mode=per-image``: one focal per COLMAP camera (one per image when features were
  extracted with ``--camera-mode per-image``), Bougnoux's formula for pairs of two cameras.
"""

from __future__ import annotations

import enum
import math
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from plugins.protocols import FocalPrior, IntrinsicsContext, IntrinsicsResult, Plugin
from recon.calibration.fusion import (
    FocalEstimate,
    FusionConfig,
    FusionMethod,
    FusionStatus,
    estimate_focal_joint,
    fuse_pair_focals,
)
from recon.calibration.kruppa import KruppaConfig, PairFocal, PairStatus, focal_from_fundamental
from recon.calibration.kruppa_joint import (
    EpipolarPair,
    JointPair,
    PrincipalPointEstimate,
    estimate_focal_and_principal_point,
    estimate_focals_per_camera,
    estimate_intrinsics_epipolar,
)
from recon.sfm.fundamental import refine_sampson, refit_fundamental


class FundamentalSource(enum.StrEnum):
    REFIT = "refit"
    REFIT_SAMPSON = "refit-sampson"
    COLMAP = "colmap"


class PrincipalPointMode(enum.StrEnum):
    CENTRE = "centre"  # the camera's principal point (COLMAP: the image centre), the thesis'
    FREE = "free"  # estimated with the focal over all ok pairs
    # estimated with the focal from the ok pairs' inliers (Sampson distances, one relative pose
    # per pair): the maximum-likelihood form of FREE
    EPIPOLAR = "epipolar"


class FocalMode(enum.StrEnum):
    SHARED = "shared"  # one focal per image size (all photos of one camera)
    PER_IMAGE = "per-image"  # one focal per COLMAP camera


# Geometries whose F is an estimated fundamental matrix (DEGENERATE, PLANAR, PANORAMIC ... are
# not: their F is absent or meaningless for self-calibration).
_WITH_F = {"UNCALIBRATED", "CALIBRATED"}


@dataclass(frozen=True)
class PairGeometryRow:
    image_i: str
    image_j: str
    image_id_i: int
    image_id_j: int
    camera_i: int
    camera_j: int
    config: str
    inliers: int
    F: np.ndarray | None
    """(3, 3) with x_jᵀ F x_i = 0 (pixels, COLMAP's +0.5 pixel-centre convention)."""
    points_i: np.ndarray | None = None
    """(inliers, 2) keypoint positions in image i of the verified inlier matches (px)."""
    points_j: np.ndarray | None = None


def read_pair_geometries(
    database_path: Path, *, with_points: bool = False
) -> list[PairGeometryRow]:
    """Every verified pair of a COLMAP database, with its F where it has one.

    ``with_points`` also loads the inlier correspondences, for refitting F.
    """
    # Imported here: `mocap plugins` imports this module only to describe the plugin.
    import pycolmap

    with pycolmap.Database.open(database_path) as db:
        images = {im.image_id: im for im in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
        keypoints = (
            {i: db.read_keypoints(i)[:, :2] for i in images} if with_points else {}
        )
    rows = []
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        i, j = pycolmap.pair_id_to_image_pair(pair_id)
        config = pycolmap.TwoViewGeometryConfiguration(int(geometry.config)).name
        F = np.asarray(geometry.F, dtype=np.float64) if config in _WITH_F else None
        if F is not None and (not np.all(np.isfinite(F)) or not np.any(F)):
            F = None
        matches = np.asarray(geometry.inlier_matches, dtype=np.int64).reshape(-1, 2)
        points = (
            (keypoints[i][matches[:, 0]], keypoints[j][matches[:, 1]]) if with_points
            else (None, None)
        )
        rows.append(
            PairGeometryRow(
                image_i=images[i].name,
                image_j=images[j].name,
                image_id_i=i,
                image_id_j=j,
                camera_i=images[i].camera_id,
                camera_j=images[j].camera_id,
                config=config,
                inliers=len(matches),
                F=F,
                points_i=points[0],
                points_j=points[1],
            )
        )
    return sorted(rows, key=lambda r: (r.image_i, r.image_j))


class KruppaInitialiser(Plugin):
    description = (
        "closed-form focal from each pair's F (degenerated Kruppa equations, thesis ch. 4), "
        "fused robustly over pairs"
    )

    @dataclass(frozen=True, kw_only=True)
    class Options:
        refine: bool = field(
            default=True, metadata={"help": "let bundle adjustment refine the Kruppa focal"}
        )
        fusion: FusionMethod = field(
            default=FusionMethod.PER_PAIR,
            metadata={"help": "per-pair-robust-mean (thesis) or joint-kruppa-residual"},
        )
        min_inliers: int = field(
            default=30, metadata={"help": "pairs with fewer verified inliers are not used"}
        )
        fundamental: FundamentalSource = field(
            default=FundamentalSource.COLMAP,
            metadata={
                "help": "colmap: the F of each verified two-view geometry in the database; "
                "refit: F re-estimated from its inliers (LMedS, then the normalised 8-point); "
                "refit-sampson: that F refined on the inliers' Sampson distances"
            },
        )
        accept_low_confidence: bool = field(
            default=False,
            metadata={
                "help": "use a fused focal flagged low-confidence (near-singular pairs only, "
                "too few pairs, or pairs that disagree) instead of falling back"
            },
        )
        principal_point: PrincipalPointMode = field(
            default=PrincipalPointMode.CENTRE,
            metadata={
                "help": "centre: the camera's principal point (the image centre), as the "
                "thesis; free: estimated with the focal over all ok pairs (kruppa-pp), kept "
                "only when well constrained and inside the image; epipolar: the same from the "
                "ok pairs' inliers (Sampson distances, one relative pose per pair)"
            },
        )
        principal_point_fundamental: FundamentalSource = field(
            default=FundamentalSource.REFIT_SAMPSON,
            metadata={
                "help": "F used by principal_point=free: refit-sampson (default) or refit from "
                "each pair's inliers; colmap's F of one camera carries no principal point"
            },
        )
        camera_mode: FocalMode = field(
            default=FocalMode.SHARED,
            metadata={
                "help": "shared: one focal per image size; per-image: one focal per COLMAP "
                "camera (extract with --camera-mode per-image for one per image), from its "
                "pairs (Bougnoux's formula across cameras), fused robustly"
            },
        )

        def __post_init__(self) -> None:
            if (self.principal_point is not PrincipalPointMode.CENTRE
                    and self.camera_mode is FocalMode.PER_IMAGE):
                raise ValueError(
                    f"principal_point={self.principal_point} needs camera_mode=shared (one "
                    "focal and principal point for all images); per-image focals use each "
                    "camera's principal point"
                )

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        free = self.options.principal_point is not PrincipalPointMode.CENTRE
        refit = self.options.fundamental is not FundamentalSource.COLMAP or free
        rows = read_pair_geometries(context.database_path, with_points=refit)
        if self.options.camera_mode is FocalMode.PER_IMAGE:
            return self._initialise_per_camera(context, rows)
        # One constant focal is assumed within a group of cameras of the same image size (all
        # the photos of one camera, whatever COLMAP's camera mode split them into).
        groups: dict[tuple[int, int], list[int]] = defaultdict(list)
        for camera in context.cameras:
            groups[(camera.width, camera.height)].append(camera.camera_id)
        principal = _principal_points(context.database_path)
        priors: list[FocalPrior] = []
        notes: list[str] = []
        table: list[dict[str, Any]] = []
        fused: dict[str, Any] = {}
        principal_fits: dict[str, Any] = {}
        fallback = False
        for size, camera_ids in sorted(groups.items()):
            estimate, pair_rows, ok_pairs, used_pairs = self._estimate_group(
                rows, set(camera_ids), size, principal
            )
            table += pair_rows
            fused[f"{size[0]}x{size[1]}"] = _estimate_dict(estimate)
            # A lone pair (two photos) that is itself well conditioned is trusted: there is no
            # spread to measure an uncertainty from, which is all that flags it.
            lone_ok_pair = estimate.num_pairs_used == 1 and dict(estimate.status_counts) == {
                "ok": 1
            }
            usable = estimate.focal_px is not None and (
                estimate.status == FusionStatus.OK
                or lone_ok_pair
                or self.options.accept_low_confidence
            )
            label = f"{size[0]}x{size[1]} cameras"
            if not usable:
                fallback = True
                found = (
                    f"{estimate.focal_px:.1f} px, {estimate.status}"
                    if estimate.focal_px is not None else str(estimate.status)
                )
                notes.append(
                    f"kruppa: no trustworthy focal for {label} ({found}; "
                    f"{_counts(estimate)}); falling back to colmap-default"
                )
            elif lone_ok_pair and estimate.status != FusionStatus.OK:
                notes.append(
                    f"kruppa: one image pair only: {label} focal {estimate.focal_px:.1f} px from "
                    "it alone, without an uncertainty"
                )
            elif estimate.status != FusionStatus.OK:
                notes.append(
                    f"kruppa: {label} focal {estimate.focal_px:.1f} px is {estimate.status} "
                    f"(±{estimate.sigma_px or 0:.1f} px), used as asked"
                )
            focal_px = estimate.focal_px if usable else None
            principal_px: tuple[float, float] | None = None
            source = (
                f"kruppa {estimate.num_pairs_used}/{estimate.num_pairs} pairs"
                + (f", ±{estimate.sigma_px:.1f} px" if estimate.sigma_px else "")
            )
            if free and usable and focal_px is not None:
                # The epipolar fit has no closed-form singularity to avoid: a pair near-singular
                # for the focal alone still constrains K with the others (fountain-P11 database
                # 2, 400 inliers per pair, 45 ok of 51 pairs: -0.23%, 5.0 px off; all 51: -0.05%,
                # 7.3 px).
                epipolar = self.options.principal_point is PrincipalPointMode.EPIPOLAR
                fit = self._fit_principal_point(
                    used_pairs if epipolar else ok_pairs, size, focal_px
                )
                principal_fits[f"{size[0]}x{size[1]}"] = _principal_dict(fit)
                if fit.accepted and fit.focal_px is not None:
                    focal_px, principal_px = fit.focal_px, fit.principal_point_px
                    assert principal_px is not None
                    source = (
                        f"kruppa-pp ({self.options.principal_point}) {fit.num_pairs} pairs: "
                        "principal point "
                        f"({principal_px[0]:.1f}, {principal_px[1]:.1f}) px"
                    )
                else:
                    notes.append(
                        f"kruppa: principal point of {label} rejected ({fit.status}: "
                        f"{fit.message}); keeping the image centre and the closed-form focal "
                        f"{focal_px:.1f} px"
                    )
            elif free:
                principal_fits[f"{size[0]}x{size[1]}"] = {
                    "status": "not-fit", "message": "no trustworthy closed-form focal to start from"
                }
            for camera_id in camera_ids:
                priors.append(
                    FocalPrior(
                        camera_id=camera_id,
                        focal_px=focal_px,
                        source=source if usable else "1.2·max(w, h) (kruppa fallback)",
                        principal_point_px=principal_px,
                    )
                )
        single = next(iter(fused.values())) if len(fused) == 1 else {}
        single_pp = next(iter(principal_fits.values())) if len(principal_fits) == 1 else {}
        return IntrinsicsResult(
            priors=tuple(sorted(priors, key=lambda p: p.camera_id)),
            # A fallback is colmap-default, which refines: a default guess must not be frozen.
            refine_focal=self.options.refine or fallback,
            notes=tuple(notes),
            details={
                "pairs": table, "fused": single, "fused_by_size": fused, "fallback": fallback,
                "camera_mode": str(self.options.camera_mode),
                "principal_point_mode": str(self.options.principal_point),
                "principal_point": single_pp, "principal_point_by_size": principal_fits,
            },
        )

    def _fit_principal_point(
        self,
        ok_pairs: list[tuple[PairGeometryRow, np.ndarray]],
        size: tuple[int, int],
        start_focal_px: float,
    ) -> PrincipalPointEstimate:
        config = KruppaConfig()
        longest = float(max(size))
        focal_range = (config.min_focal_factor * longest, config.max_focal_factor * longest)
        if self.options.principal_point is PrincipalPointMode.EPIPOLAR:
            pairs = []
            for row, F in ok_pairs:
                F_fit = _fundamental(row, self.options.principal_point_fundamental, fallback=F)
                if F_fit is None or row.points_i is None or row.points_j is None:
                    continue
                pairs.append(EpipolarPair(F=F_fit, points_i=row.points_i,
                                          points_j=row.points_j, image_i=row.image_id_i,
                                          image_j=row.image_id_j))
            return estimate_intrinsics_epipolar(
                pairs, image_size=size, start_focal_px=start_focal_px,
                focal_range_px=focal_range,
            )
        fundamentals, ids, inliers = [], [], []
        for row, F in ok_pairs:
            F_fit = _fundamental(row, self.options.principal_point_fundamental, fallback=F)
            if F_fit is None:
                continue
            fundamentals.append(F_fit)
            ids.append((row.image_id_i, row.image_id_j))
            inliers.append(row.inliers)
        return estimate_focal_and_principal_point(
            fundamentals, image_pairs=ids, image_size=size, start_focal_px=start_focal_px,
            num_inliers=inliers, focal_range_px=focal_range,
        )

    def _initialise_per_camera(
        self, context: IntrinsicsContext, rows: list[PairGeometryRow]
    ) -> IntrinsicsResult:
        principal = _principal_points(context.database_path)
        sizes = {c.camera_id: (c.width, c.height) for c in context.cameras}
        notes: list[str] = []
        shared = [c for c in context.cameras if len(c.image_names) > 1]
        if shared:
            notes.append(
                f"kruppa per-image: {len(shared)} camera(s) hold several images (camera "
                f"{shared[0].camera_id}: {len(shared[0].image_names)}), so they get one focal "
                "each; extract features with --camera-mode per-image for one focal per image"
            )
        pairs: list[JointPair] = []
        for row in rows:
            if row.F is None or row.inliers < self.options.min_inliers:
                continue
            F = _fundamental(row, self.options.fundamental, fallback=row.F)
            if F is None:
                continue
            pairs.append(JointPair(F=F, camera_i=row.camera_i, camera_j=row.camera_j,
                                   num_inliers=row.inliers))
        focals, pair_table = estimate_focals_per_camera(
            pairs, principal_points=principal, image_sizes=sizes
        )
        priors = []
        per_camera = []
        fallback = False
        for camera in context.cameras:
            est = focals[camera.camera_id]
            per_camera.append({"camera_id": camera.camera_id, "images": list(camera.image_names),
                               "focal_px": est.focal_px, "focal_median_px": est.focal_median_px,
                               "sigma_px": est.sigma_px, "pairs_used": est.num_pairs_used,
                               "pairs": est.num_pairs})
            if est.focal_px is None:
                fallback = True
                notes.append(
                    f"kruppa per-image: no trustworthy focal for camera {camera.camera_id} "
                    f"({camera.image_names[0]}: {est.message}; {est.num_pairs} pairs); "
                    "falling back to colmap-default"
                )
            priors.append(FocalPrior(
                camera_id=camera.camera_id,
                focal_px=est.focal_px,
                source=(f"kruppa per-image {est.num_pairs_used}/{est.num_pairs} pairs"
                        if est.focal_px is not None else "1.2·max(w, h) (kruppa fallback)"),
            ))
        names = {c.camera_id: c.image_names[0] for c in context.cameras}
        table = [
            {"image_i": names.get(int(p["camera_i"]), ""), "image_j": names.get(
                int(p["camera_j"]), ""), **p,
             "focal_px": None, "conditioning": min(float(p["conditioning_i"]),
                                                   float(p["conditioning_j"]))}
            for p in pair_table
        ]
        return IntrinsicsResult(
            priors=tuple(sorted(priors, key=lambda p: p.camera_id)),
            refine_focal=self.options.refine or fallback,
            notes=tuple(notes),
            details={"pairs": table, "fused": {}, "cameras": per_camera, "fallback": fallback,
                     "camera_mode": str(self.options.camera_mode),
                     "principal_point_mode": str(self.options.principal_point)},
        )

    def _estimate_group(
        self,
        rows: list[PairGeometryRow],
        camera_ids: set[int],
        size: tuple[int, int],
        principal: dict[int, tuple[float, float]],
    ) -> tuple[
        FocalEstimate,
        list[dict[str, Any]],
        list[tuple[PairGeometryRow, np.ndarray]],
        list[tuple[PairGeometryRow, np.ndarray]],
    ]:
        """The fused focal, the per-pair table, the pairs the closed form found ok and every
        pair with an F and enough inliers."""
        pairs: list[PairFocal] = []
        ok_pairs: list[tuple[PairGeometryRow, np.ndarray]] = []
        used_pairs: list[tuple[PairGeometryRow, np.ndarray]] = []
        inliers: list[int] = []
        ids: list[tuple[int, int]] = []
        table = []
        for row in rows:
            if row.camera_i not in camera_ids or row.camera_j not in camera_ids:
                continue
            entry = {"image_i": row.image_i, "image_j": row.image_j, "inliers": row.inliers,
                     "focal_px": None, "status": "", "conditioning": 0.0, "method": ""}
            F = row.F
            if F is not None:
                F = _fundamental(row, self.options.fundamental, fallback=F)
            if F is None:
                entry["status"] = f"no-F ({row.config.lower()})"
            elif row.inliers < self.options.min_inliers:
                entry["status"] = "too-few-inliers"
            else:
                pair = focal_from_fundamental(
                    F, principal_point=principal[row.camera_i], image_size=size,
                    config=KruppaConfig(),
                )
                entry.update(focal_px=pair.focal_px, status=str(pair.status),
                             conditioning=pair.conditioning, method=pair.method)
                pairs.append(pair)
                if pair.status == PairStatus.OK:
                    ok_pairs.append((row, F))
                used_pairs.append((row, F))
                inliers.append(row.inliers)
                ids.append((row.image_id_i, row.image_id_j))
            table.append(entry)
        fuse = (
            estimate_focal_joint
            if self.options.fusion is FusionMethod.JOINT
            else fuse_pair_focals
        )
        # Two photos give one pair: its estimate is all there is (the thesis' chapter 5 case),
        # so fewer pairs than the usual minimum do not make it low-confidence by themselves.
        config = FusionConfig(min_pairs=max(1, min(FusionConfig().min_pairs, len(pairs))))
        estimate = fuse(pairs, num_inliers=inliers, image_ids=ids, config=config)
        return estimate, table, ok_pairs, used_pairs


class KruppaPrincipalPointInitialiser(KruppaInitialiser):
    """``kruppa`` with ``principal_point=free``: focal and principal point together."""

    description = (
        "kruppa with a free principal point: focal and principal point by robust least squares "
        "over all well-conditioned pairs, kept only when well constrained and inside the image"
    )

    @dataclass(frozen=True, kw_only=True)
    class Options(KruppaInitialiser.Options):
        principal_point: PrincipalPointMode = field(
            default=PrincipalPointMode.FREE,
            metadata={"help": "free (this plugin's point), epipolar (from the pairs' inliers) "
                              "or centre (the same as kruppa)"},
        )


def _fundamental(
    row: PairGeometryRow, source: FundamentalSource, *, fallback: np.ndarray | None
) -> np.ndarray | None:
    """The pair's F from ``source`` (COLMAP's is ``fallback``); None when it cannot be had."""
    if source is FundamentalSource.COLMAP:
        return fallback
    if row.points_i is None or row.points_j is None:
        return None
    F = refit_fundamental(row.points_i, row.points_j)
    if F is not None and source is FundamentalSource.REFIT_SAMPSON:
        F = refine_sampson(F, row.points_i, row.points_j)
    return F


def _principal_points(database_path: Path) -> dict[int, tuple[float, float]]:
    import pycolmap

    with pycolmap.Database.open(database_path) as db:
        return {
            c.camera_id: (float(c.principal_point_x), float(c.principal_point_y))
            for c in db.read_all_cameras()
        }


def _counts(estimate: FocalEstimate) -> str:
    counts = ", ".join(f"{n} {s}" for s, n in estimate.status_counts) or "no pairs"
    return f"pairs: {counts}"


def _principal_dict(fit: PrincipalPointEstimate) -> dict[str, Any]:
    data = asdict(fit)
    data["status"] = str(fit.status)
    # JSON has no infinity: an axis held at the centre has no standard error.
    if fit.sigma_principal_point_px is not None:
        data["sigma_principal_point_px"] = [
            v if math.isfinite(v) else None for v in fit.sigma_principal_point_px
        ]
    return data


def _estimate_dict(estimate: FocalEstimate) -> dict[str, Any]:
    data = asdict(estimate)
    return {k: (str(v) if hasattr(v, "value") else v) for k, v in data.items()}
