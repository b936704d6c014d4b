"""The ``kruppa`` intrinsic initialiser: focal length from the database's fundamental matrices.

After matching, COLMAP's database holds a verified two-view geometry per image pair, with F in
the ``x2ᵀ F x1 = 0`` convention (image 1 = the pair's first image id). Each F gives a
closed-form focal (:func:`recon.calibration.kruppa.focal_from_fundamental`), the pairs are fused
robustly (:mod:`recon.calibration.fusion`), and the result becomes the focal prior of every
camera of that image size. When no focal can be had, the camera falls back to COLMAP's default
start with a warning, so mapping still runs.
"""

from __future__ import annotations

import enum
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
from recon.calibration.kruppa import KruppaConfig, PairFocal, focal_from_fundamental
from recon.sfm.fundamental import refit_fundamental


class FundamentalSource(enum.StrEnum):
    REFIT = "refit"
    COLMAP = "colmap"


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
                "refit: F re-estimated from its inliers (LMedS, then the normalised 8-point)"
            },
        )
        accept_low_confidence: bool = field(
            default=False,
            metadata={
                "help": "use a fused focal flagged low-confidence (near-singular pairs only, "
                "too few pairs, or pairs that disagree) instead of falling back"
            },
        )

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        refit = self.options.fundamental is FundamentalSource.REFIT
        rows = read_pair_geometries(context.database_path, with_points=refit)
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
        fallback = False
        for size, camera_ids in sorted(groups.items()):
            estimate, pair_rows = self._estimate_group(rows, set(camera_ids), size, principal)
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
            for camera_id in camera_ids:
                priors.append(
                    FocalPrior(
                        camera_id=camera_id,
                        focal_px=estimate.focal_px if usable else None,
                        source=(
                            f"kruppa {estimate.num_pairs_used}/{estimate.num_pairs} pairs"
                            + (f", ±{estimate.sigma_px:.1f} px" if estimate.sigma_px else "")
                            if usable
                            else "1.2·max(w, h) (kruppa fallback)"
                        ),
                    )
                )
        single = next(iter(fused.values())) if len(fused) == 1 else {}
        return IntrinsicsResult(
            priors=tuple(sorted(priors, key=lambda p: p.camera_id)),
            # A fallback is colmap-default, which refines: a default guess must not be frozen.
            refine_focal=self.options.refine or fallback,
            notes=tuple(notes),
            details={
                "pairs": table, "fused": single, "fused_by_size": fused, "fallback": fallback,
            },
        )

    def _estimate_group(
        self,
        rows: list[PairGeometryRow],
        camera_ids: set[int],
        size: tuple[int, int],
        principal: dict[int, tuple[float, float]],
    ) -> tuple[FocalEstimate, list[dict[str, Any]]]:
        pairs: list[PairFocal] = []
        inliers: list[int] = []
        ids: list[tuple[int, int]] = []
        table = []
        for row in rows:
            if row.camera_i not in camera_ids or row.camera_j not in camera_ids:
                continue
            entry = {"image_i": row.image_i, "image_j": row.image_j, "inliers": row.inliers,
                     "focal_px": None, "status": "", "conditioning": 0.0, "method": ""}
            F = row.F
            if F is not None and self.options.fundamental is FundamentalSource.REFIT:
                F = refit_fundamental(row.points_i, row.points_j)
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
        return fuse(pairs, num_inliers=inliers, image_ids=ids, config=config), table


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


def _estimate_dict(estimate: FocalEstimate) -> dict[str, Any]:
    data = asdict(estimate)
    return {k: (str(v) if hasattr(v, "value") else v) for k, v in data.items()}
