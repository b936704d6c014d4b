"""The fundamental matrix of two views from point matches: pure geometry, no I/O.

One implementation for every caller: the Harris + NCC front end (:mod:`recon.sfm.frontend`),
the Kruppa initialiser's refit of COLMAP's inliers
(:mod:`recon.calibration.kruppa_initialiser`) and the thesis' noise experiment
(:mod:`recon.calibration.experiment`).

Conventions
-----------
- ``F`` maps image-1 points to epipolar lines in image 2: ``x2ᵀ F x1 = 0`` for homogeneous
  pixel coordinates ``(x, y, 1)`` (COLMAP's convention; OpenCV's ``findFundamentalMat(pts1,
  pts2)`` returns the same ``F``). Points are ``(N, 2)`` px, both images in one pixel
  convention (the result is in that convention).
- The estimators return ``F`` as :func:`normalise_fundamental` leaves it: rank 2, unit
  Frobenius norm, its largest-magnitude entry positive.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = [
    "eight_point",
    "hartley_transform",
    "normalise_fundamental",
    "refine_sampson",
    "refit_fundamental",
    "sampson_distance_px",
]


def normalise_fundamental(F: np.ndarray) -> np.ndarray:
    """Rank-2 ``F`` (the nearest in Frobenius norm) with unit norm, largest entry positive."""
    U, s, Vt = np.linalg.svd(np.asarray(F, np.float64))
    F = U @ np.diag([s[0], s[1], 0.0]) @ Vt
    F = F / np.linalg.norm(F)
    flat = F.ravel()
    return F if flat[np.argmax(np.abs(flat))] > 0 else -F


def hartley_transform(points_px: np.ndarray) -> np.ndarray:
    """(3, 3) similarity moving the points' centroid to 0 and their mean distance to √2
    (Hartley 1997); the identity scale for coincident points."""
    centroid = points_px.mean(axis=0)
    spread = float(np.linalg.norm(points_px - centroid, axis=1).mean())
    s = math.sqrt(2.0) / spread if spread > 0 else 1.0
    return np.array([[s, 0.0, -s * centroid[0]], [0.0, s, -s * centroid[1]], [0.0, 0.0, 1.0]])


def _signed_sampson_px(F: np.ndarray, points1_px: np.ndarray, points2_px: np.ndarray) -> np.ndarray:
    """(N,) ``x2ᵀ F x1`` divided by its gradient norm w.r.t. the four coordinates (px)."""
    x1 = np.column_stack([points1_px, np.ones(len(points1_px))])
    x2 = np.column_stack([points2_px, np.ones(len(points2_px))])
    lines2 = x1 @ F.T  # epipolar lines in image 2, F x1
    lines1 = x2 @ F  # epipolar lines in image 1, Fᵀ x2
    algebraic = np.einsum("ij,ij->i", x2, lines2)
    gradient = np.hypot(np.hypot(lines2[:, 0], lines2[:, 1]), np.hypot(lines1[:, 0], lines1[:, 1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        # A point on both epipoles has no defined distance; count it as infinitely far.
        return np.where(gradient > 0, algebraic / gradient, np.inf)


def sampson_distance_px(
    F: np.ndarray, points1_px: np.ndarray, points2_px: np.ndarray
) -> np.ndarray:
    """(N,) Sampson distances of matches under ``F``: the first-order geometric error (px).

    The first-order distance of the 4-D point ``(x1, x2)`` to the epipolar variety: for
    isotropic pixel noise its sum of squares is the first-order maximum-likelihood cost, and at
    the true ``F`` noise of σ per coordinate gives an RMS of σ. ``F`` is (3, 3) with
    ``x2ᵀ F x1 = 0``; points are ``(N, 2)`` px in ``F``'s convention.
    """
    p1 = np.asarray(points1_px, np.float64).reshape(-1, 2)
    p2 = np.asarray(points2_px, np.float64).reshape(-1, 2)
    return np.abs(_signed_sampson_px(np.asarray(F, np.float64), p1, p2))


def refine_sampson(F: np.ndarray, points1_px: np.ndarray, points2_px: np.ndarray) -> np.ndarray:
    """The rank-2 ``F`` minimising the squared Sampson distances (px) of the given matches.

    The matches are taken as inliers (plain least squares). ``F`` is parametrised in Bartoli
    and Sturm's orthonormal form ``F = T2ᵀ U diag(1, σ, 0) Vᵀ T1`` (7 degrees of freedom,
    rank 2 by construction) in Hartley-normalised coordinates, which keeps the problem well
    conditioned whatever the image size; ``U`` and ``V`` are updated by rotation vectors. The
    residuals are the distances of the pixel-space ``F``: the noise is isotropic in pixels,
    not in the per-image normalised coordinates. Levenberg-Marquardt is monotone, so the cost
    never exceeds that of ``F``'s rank-2 projection. Returns a normalised ``F``.
    """
    # Imported here: scipy costs ~0.3 s, and `mocap --help` needs none of it.
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    p1 = np.asarray(points1_px, np.float64).reshape(-1, 2)
    p2 = np.asarray(points2_px, np.float64).reshape(-1, 2)
    T1, T2 = hartley_transform(p1), hartley_transform(p2)
    F_norm = np.linalg.inv(T2).T @ np.asarray(F, np.float64) @ np.linalg.inv(T1)
    U, s, Vt = np.linalg.svd(F_norm)
    # Orthogonal -> rotation: flipping the null vectors' sign leaves U diag(.., 0) Vᵀ unchanged.
    U[:, 2] *= np.sign(np.linalg.det(U))
    V = Vt.T
    V[:, 2] *= np.sign(np.linalg.det(V))

    def model(params: np.ndarray) -> np.ndarray:
        U_p = U @ Rotation.from_rotvec(params[0:3]).as_matrix()
        V_p = V @ Rotation.from_rotvec(params[3:6]).as_matrix()
        F_n = U_p @ np.diag([1.0, params[6], 0.0]) @ V_p.T
        return T2.T @ F_n @ T1

    def residuals(params: np.ndarray) -> np.ndarray:
        return _signed_sampson_px(model(params), p1, p2)

    start = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, s[1] / s[0]])
    # Plain least squares: a robust loss was measured to change nothing on the front end's
    # inliers (the wrong matches that survive lie along their epipolar lines).
    solution = least_squares(residuals, start, method="lm", x_scale="jac")
    return normalise_fundamental(model(solution.x))


def eight_point(points1_px: np.ndarray, points2_px: np.ndarray) -> np.ndarray | None:
    """Hartley-normalised 8-point ``F`` of all (N, 2) matches (OpenCV ``FM_8POINT``), or None
    when OpenCV finds none (fewer than 8 matches, degenerate points)."""
    p1 = np.ascontiguousarray(points1_px, dtype=np.float64).reshape(-1, 2)
    p2 = np.ascontiguousarray(points2_px, dtype=np.float64).reshape(-1, 2)
    if len(p1) < 8:
        return None
    F, _ = cv2.findFundamentalMat(p1, p2, cv2.FM_8POINT)
    if F is None or F.shape != (3, 3) or not np.isfinite(F).all() or not np.any(F):
        return None
    return normalise_fundamental(F)


def refit_fundamental(
    points1_px: np.ndarray | None, points2_px: np.ndarray | None
) -> np.ndarray | None:
    """``F`` from verified correspondences ((N, 2) px each), or None (fewer than 15).

    The thesis' robust step (LMedS) on already verified (e.g. COLMAP's RANSAC) inliers, then
    the normalised 8-point algorithm on the LMedS inliers: OpenCV's robust estimators return
    the model of their best minimal sample, noticeably worse than a least-squares refit on all
    inliers.
    """
    if points1_px is None or points2_px is None or len(points1_px) < 15:
        return None
    p1 = np.ascontiguousarray(points1_px, dtype=np.float64).reshape(-1, 2)
    p2 = np.ascontiguousarray(points2_px, dtype=np.float64).reshape(-1, 2)
    F, mask = cv2.findFundamentalMat(p1, p2, cv2.FM_LMEDS)
    if F is None or F.shape != (3, 3) or mask is None:
        return None
    keep = mask.ravel().astype(bool)
    refit = eight_point(p1[keep], p2[keep]) if keep.sum() >= 8 else None
    return refit if refit is not None else normalise_fundamental(F)
