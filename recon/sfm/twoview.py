"""A metric model from exactly two photos (thesis ch. 5): essential matrix, the pose that puts
the points in front of both cameras, triangulation, then bundle adjustment.

COLMAP's incremental mapper is built for many views and often rejects a lone pair (its initial
pair checks). With two photos the geometry is fully given by the verified two-view geometry in
the database and the cameras' focal (from Kruppa when available): ``E = K2ᵀ F K1``. The result is
up to scale; the baseline is set to 1.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pycolmap

from recon.errors import UserError

MAX_REPROJECTION_ERROR_PX = 4.0
# Below this median displacement of the verified matches the photos are one view twice (the
# same photo, or a copy re-encoded): the essential matrix is undefined and so is the pose.
MIN_MEDIAN_PARALLAX_PX = 1.0


def two_view_model(database_path: Path, images_dir: Path, *, refine_focal: bool
                   ) -> pycolmap.Reconstruction:
    with pycolmap.Database.open(database_path) as db:
        images = sorted(db.read_all_images(), key=lambda im: im.image_id)
        if len(images) != 2:
            raise UserError(f"two-view reconstruction needs 2 images, the database has "
                            f"{len(images)}")
        cameras = {c.camera_id: c for c in db.read_all_cameras()}
        keypoints = [db.read_keypoints(im.image_id)[:, :2].astype(np.float64) for im in images]
        pair_ids, geometries = db.read_two_view_geometries()
    usable = [g for g in geometries if len(g.inlier_matches) >= 15]
    if not usable:
        raise UserError(f"the two photos in {images_dir} share too few verified matches")
    geometry = usable[0]
    matches = np.asarray(geometry.inlier_matches, dtype=np.int64)
    names = " and ".join(sorted(im.name for im in images))
    parallax_px = median_parallax_px(keypoints[0], keypoints[1], matches)
    if parallax_px < MIN_MEDIAN_PARALLAX_PX:
        raise UserError(f"the photos {names} are identical (their matches move by "
                        f"{parallax_px:.2f} px): take the second photo from another place")
    if geometry.config == pycolmap.TwoViewGeometryConfiguration.PANORAMIC:
        # COLMAP's verdict when the matches fit a rotation alone (tiny triangulation angles).
        raise UserError(f"the camera only turned between {names} (no baseline to "
                        "triangulate from): move it between the photos")
    cam1, cam2 = cameras[images[0].camera_id], cameras[images[1].camera_id]
    K1, K2 = cam1.calibration_matrix(), cam2.calibration_matrix()
    # COLMAP keypoints have pixel centres at +0.5, as do its calibration matrices: consistent.
    x1 = _normalised(keypoints[0][matches[:, 0]], K1)
    x2 = _normalised(keypoints[1][matches[:, 1]], K2)
    E, mask = cv2.findEssentialMat(x1, x2, np.eye(3), method=cv2.RANSAC, prob=0.999,
                                   threshold=MAX_REPROJECTION_ERROR_PX / cam1.mean_focal_length())
    if E is None or E.shape != (3, 3):
        raise UserError("no essential matrix fits the two photos' matches")
    # The cheirality test picks, of the four (R, t), the one with the points in front of both.
    _, R, t, mask = cv2.recoverPose(E, x1, x2, np.eye(3), mask=mask)
    keep = mask.ravel() > 0
    if keep.sum() < 15:
        raise UserError(f"too few matches of {names} fit one camera motion "
                        f"({keep.sum()} of {len(matches)}); the photos may show no camera motion")
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t.reshape(3, 1)])
    X = cv2.triangulatePoints(P1, P2, x1[keep].T, x2[keep].T)
    X = (X[:3] / X[3]).T
    kept_matches = matches[keep]
    depth1, depth2 = X[:, 2], (X @ R.T + t.ravel())[:, 2]
    in_front = (depth1 > 0) & (depth2 > 0)
    X, kept_matches = X[in_front], kept_matches[in_front]
    if len(X) < 15:
        raise UserError("too few matches triangulate in front of both cameras")

    model = pycolmap.Reconstruction()
    for camera in {cam1.camera_id: cam1, cam2.camera_id: cam2}.values():
        model.add_camera_with_trivial_rig(camera)
    poses = [pycolmap.Rigid3d(), pycolmap.Rigid3d(pycolmap.Rotation3d(R), t.ravel())]
    for image, kps, pose in zip(images, keypoints, poses, strict=True):
        model.add_image_with_trivial_frame(
            pycolmap.Image(name=image.name, keypoints=kps, camera_id=image.camera_id,
                           image_id=image.image_id),
            pose,
        )
    for xyz, (i, j) in zip(X, kept_matches, strict=True):
        track = pycolmap.Track()
        track.add_element(images[0].image_id, int(i))
        track.add_element(images[1].image_id, int(j))
        model.add_point3D(xyz, track)
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_focal_length = refine_focal
    options.print_summary = False
    pycolmap.bundle_adjustment(model, options)
    # Up to scale: one baseline unit.
    centre = model.images[images[1].image_id].projection_center()
    model.transform(pycolmap.Sim3d(1.0 / float(np.linalg.norm(centre)), pycolmap.Rotation3d(),
                                   np.zeros(3)))
    model.extract_colors_for_all_images(str(images_dir))
    return model


def median_parallax_px(keypoints1: np.ndarray, keypoints2: np.ndarray,
                       matches: np.ndarray) -> float:
    """Median image distance (px) between matched keypoints ((N, 2) each; matches (M, 2))."""
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    if len(matches) == 0:
        return float("nan")
    return float(np.median(np.linalg.norm(
        keypoints1[matches[:, 0], :2] - keypoints2[matches[:, 1], :2], axis=1)))


def _normalised(points_px: np.ndarray, K: np.ndarray) -> np.ndarray:
    homogeneous = np.column_stack([points_px, np.ones(len(points_px))])
    return (homogeneous @ np.linalg.inv(K).T)[:, :2]
