"""A second chance for the images the first mapping left out: robust features, then registration
into the existing model with its intrinsics held.

Why the images failed is read from the first pass (:func:`unregistered_reasons`):

- ``too-few-matches``: fewer 2D-3D correspondences (verified matches to a registered image's
  triangulated keypoints) than COLMAP's absolute-pose minimum (30 inliers): no pose can be
  accepted from them;
- ``ambiguous-pose``: enough correspondences, yet no pose had enough inliers (they disagree,
  e.g. repeated or symmetric structure).

:func:`retry_unregistered` then

1. re-extracts those images and their neighbours (the registered images they share the most raw
   matches with) with affine-covariant, domain-size-pooled SIFT (COLMAP's
   ``estimate_affine_shape`` and ``domain_size_pooling``), and matches them with guided matching;
2. appends those keypoints and descriptors after each image's first-pass ones in a copy of the
   database (so every keypoint index of the first model stays valid), with their matches;
3. rebuilds the first model's poses and intrinsics on that database, triangulates, and continues
   COLMAP's incremental mapper from it, which registers what it can and ends with a global
   bundle adjustment of poses and points.

The first model's cameras are held constant throughout. Only when that leaves images out is a
second attempt made with them refined (as the first pass refined them), kept if it registers
more: a first model of a few images can have a focal so wrong that right poses are rejected
(measured: five ring views and a photo of something else, first model 3 views at 1875 px).

Measured on the temple sparse ring (benchmarks/sfm_registration.py): refining the cameras after
the three retried images joined moved the focal from 1525 px to 1574-1580 px (3.3-3.8% off the
true 1523 px) and its radial distortion from -0.10 to -0.33..-0.40 for a reprojection error
0.5% lower: the ring's poses do not pin focal and distortion apart. Held, the focal stays the
first pass's and all 16 images register. Re-mapping every image with robust features instead
gave 1550-1574 px and twice the reprojection error (0.43 against 0.22 px): affine-shape
keypoints are located less precisely, which is why they are only added where the first-pass
features failed.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from recon.sfm.images import MIN_IMAGE_SIDE_PX

TOO_FEW_MATCHES = "too-few-matches"
AMBIGUOUS_POSE = "ambiguous-pose"
# COLMAP's IncrementalMapperOptions.abs_pose_min_num_inliers default: a pose needs this many.
MIN_POSE_CORRESPONDENCES = 30


@dataclass(frozen=True)
class Unregistered:
    """Why one image is not in the model, from the matches of the database it was mapped on."""

    reason: str  # TOO_FEW_MATCHES or AMBIGUOUS_POSE
    verified_matches: int  # inlier matches to registered images
    correspondences: int  # of its keypoints, those matched to a triangulated keypoint

    def describe(self) -> str:
        what = "too few matches" if self.reason == TOO_FEW_MATCHES else "ambiguous pose"
        return (f"{what} ({self.correspondences} 2D-3D correspondences, "
                f"{self.verified_matches} verified matches to registered images)")

    def as_dict(self) -> dict[str, Any]:
        return {"reason": self.reason, "verified_matches": self.verified_matches,
                "correspondences": self.correspondences}


@dataclass(frozen=True)
class RetryResult:
    model: pycolmap.Reconstruction  # the first model with the retried images, or a copy of it
    database_path: Path  # the database whose keypoints the model's points2D index
    retried: tuple[str, ...]  # images unregistered after the first pass
    neighbours: tuple[str, ...]  # registered images re-extracted with them
    registered: tuple[str, ...]  # retried images now in the model
    failed: dict[str, Unregistered] = field(default_factory=dict)  # still out, and why
    # "held": the first model's cameras held; "refined": refined in a second attempt, after
    # held ones left images out; "first": the retry gained nothing, the first model stands.
    intrinsics: str = "held"
    seconds: dict[str, float] = field(default_factory=dict)  # wall time of each stage


def registered_names(model: pycolmap.Reconstruction) -> set[str]:
    return {im.name for im in model.images.values() if im.has_pose}


def unregistered_reasons(
    database_path: Path, model: pycolmap.Reconstruction,
    min_correspondences: int = MIN_POSE_CORRESPONDENCES,
) -> dict[str, Unregistered]:
    """Why each image of the database is not registered in ``model``, by name."""
    registered = {im.image_id: im for im in model.images.values() if im.has_pose}
    with pycolmap.Database.open(database_path) as db:
        names = {im.image_id: im.name for im in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
    # Image ids are the database's: the model was mapped on it.
    out_ids = {i for i, name in names.items() if i not in registered}
    verified = dict.fromkeys(out_ids, 0)
    triangulated: dict[int, set[int]] = {i: set() for i in out_ids}
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        i, j = pycolmap.pair_id_to_image_pair(pair_id)
        inliers = np.asarray(geometry.inlier_matches).reshape(-1, 2)
        for mine, other, column in ((i, j, 0), (j, i, 1)):
            if mine not in out_ids or other not in registered or not len(inliers):
                continue
            verified[mine] += len(inliers)
            points2D = registered[other].points2D
            for k, theirs in zip(inliers[:, column], inliers[:, 1 - column], strict=True):
                if points2D[int(theirs)].has_point3D():
                    triangulated[mine].add(int(k))
    return {
        names[i]: Unregistered(
            reason=TOO_FEW_MATCHES if len(triangulated[i]) < min_correspondences
            else AMBIGUOUS_POSE,
            verified_matches=verified[i],
            correspondences=len(triangulated[i]),
        )
        for i in sorted(out_ids, key=lambda i: names[i])
    }


def robust_extraction_options(
    extraction: pycolmap.FeatureExtractionOptions,
) -> pycolmap.FeatureExtractionOptions:
    """``extraction`` with affine-covariant, domain-size-pooled SIFT (COLMAP's CPU SIFT)."""
    extraction.sift.estimate_affine_shape = True
    extraction.sift.domain_size_pooling = True
    return extraction


def robust_matching_options(
    matching: pycolmap.FeatureMatchingOptions,
) -> pycolmap.FeatureMatchingOptions:
    """``matching`` with guided matching: after verification, matches along the epipolar
    geometry are added."""
    matching.guided_matching = True
    return matching


def neighbours_of(database_path: Path, images: Iterable[str], candidates: Iterable[str],
                  count: int) -> list[str]:
    """For each of ``images``, the ``count`` of ``candidates`` with the most raw matches."""
    with pycolmap.Database.open(database_path) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        pair_ids, counts = db.read_num_matches()
    raw = {pycolmap.pair_id_to_image_pair(p): n for p, n in zip(pair_ids, counts, strict=True)}

    def matches(a: str, b: str) -> int:
        i, j = ids[a], ids[b]
        return raw.get((min(i, j), max(i, j)), 0)

    pool = sorted(candidates)
    chosen: set[str] = set()
    for name in images:
        ranked = sorted(pool, key=lambda other: -matches(name, other))
        chosen.update(other for other in ranked[:count] if matches(name, other) > 0)
    return sorted(chosen)


def _append_features(merged_path: Path, robust_path: Path) -> int:
    """Append ``robust_path``'s keypoints, descriptors and verified matches after those of
    ``merged_path`` (images by name). Returns the number of verified pairs added."""
    empty = np.zeros((0, 2), np.int64)
    with pycolmap.Database.open(robust_path) as robust, \
            pycolmap.Database.open(merged_path) as merged:  # fmt: skip
        ids = {im.name: im.image_id for im in merged.read_all_images()}
        robust_names = {im.image_id: im.name for im in robust.read_all_images()}
        offset: dict[str, int] = {}
        descriptors = {}
        for name, image_id in ids.items():
            old = merged.read_descriptors(image_id)
            descriptors[image_id] = old
            if name not in robust_names.values():
                continue
            robust_id = next(i for i, n in robust_names.items() if n == name)
            keypoints = merged.read_keypoints(image_id)
            offset[name] = len(keypoints)
            merged.update_keypoints(image_id, np.vstack([keypoints,
                                                         robust.read_keypoints(robust_id)]))
            new = robust.read_descriptors(robust_id)
            descriptors[image_id] = pycolmap.FeatureDescriptors(
                type=old.type, data=np.vstack([old.data, new.data]))
        # A database holds one descriptor blob per image and cannot update one: rewrite all.
        merged.clear_descriptors()
        for image_id, blob in descriptors.items():
            merged.write_descriptors(image_id, blob)
        pair_ids, geometries = robust.read_two_view_geometries()
        added = 0
        for pair_id, geometry in zip(pair_ids, geometries, strict=True):
            if len(geometry.inlier_matches) == 0:
                continue
            i, j = pycolmap.pair_id_to_image_pair(pair_id)
            a, b = robust_names[i], robust_names[j]
            shift = np.array([offset[a], offset[b]], np.int64)
            matches = robust.read_matches(i, j).astype(np.int64) + shift
            inliers = np.asarray(geometry.inlier_matches, np.int64) + shift
            id_a, id_b = ids[a], ids[b]
            swapped = id_a > id_b
            if swapped:
                # The merged database may number the two images the other way round.
                id_a, id_b = id_b, id_a
                matches, inliers = matches[:, ::-1], inliers[:, ::-1]
            old_matches = (merged.read_matches(id_a, id_b).astype(np.int64)
                           if merged.exists_matches(id_a, id_b) else empty)
            if merged.exists_matches(id_a, id_b):
                merged.delete_matches(id_a, id_b)
            merged.write_matches(id_a, id_b, np.vstack([old_matches, matches]).astype(np.uint32))
            exists = merged.exists_two_view_geometry(id_a, id_b)
            old = merged.read_two_view_geometry(id_a, id_b) if exists else None
            old_inliers = (np.asarray(old.inlier_matches, np.int64).reshape(-1, 2)
                           if old is not None else empty)
            combined = pycolmap.TwoViewGeometry()
            if old is not None and len(old_inliers) >= len(inliers):
                # The first pass's geometry explains more matches: keep its model.
                combined.config, combined.F, combined.E, combined.H = (
                    old.config, old.F, old.E, old.H)
            else:
                combined.config = geometry.config
                # x2ᵀ F x1 = 0 from image i to j; numbered the other way, F transposes.
                transpose = (lambda m: None if m is None else m.T) if swapped else (lambda m: m)
                combined.F, combined.E = transpose(geometry.F), transpose(geometry.E)
                combined.H = (None if geometry.H is None
                              else np.linalg.inv(geometry.H) if swapped else geometry.H)
            combined.inlier_matches = np.vstack([old_inliers, inliers]).astype(np.uint32)
            if exists:
                merged.update_two_view_geometry(id_a, id_b, combined)
            else:
                merged.write_two_view_geometry(id_a, id_b, combined)
            added += 1
    return added


def _posed_model(first: pycolmap.Reconstruction, database_path: Path) -> pycolmap.Reconstruction:
    """The first model's cameras, poses and points on the images of ``database_path`` (by
    name), with that database's keypoints: the start for triangulating the new matches."""
    model = pycolmap.Reconstruction()
    with pycolmap.Database.open(database_path) as db:
        for camera in db.read_all_cameras():
            if camera.camera_id in first.cameras:
                camera.params = first.cameras[camera.camera_id].params
            model.add_camera_with_trivial_rig(camera)
        for image in db.read_all_images():
            posed = first.find_image_with_name(image.name)
            if posed is None or not posed.has_pose:
                continue
            if image.frame_id != image.image_id:
                raise RuntimeError(f"{image.name}: frame {image.frame_id} is not image "
                                   f"{image.image_id}; the retry expects COLMAP's single images")
            keypoints = db.read_keypoints(image.image_id)[:, :2].astype(np.float64)
            model.add_image_with_trivial_frame(
                pycolmap.Image(name=image.name, keypoints=keypoints, camera_id=image.camera_id,
                               image_id=image.image_id),
                posed.cam_from_world(),
            )
    # The first model's points, as they are: their keypoint indices are valid in a database
    # that only appended keypoints. (Triangulated anew from the poses they came out fewer, and
    # none at all from a first model of three views: its tracks were mostly two-view, which
    # COLMAP's triangulator ignores.)
    for point in first.points3D.values():
        model.add_point3D(point.xyz, pycolmap.Track(point.track.elements), point.color)
    return model


def retry_unregistered(
    database_path: Path,
    images_dir: Path,
    first: pycolmap.Reconstruction,
    work_dir: Path,
    *,
    extraction: pycolmap.FeatureExtractionOptions,
    matching: pycolmap.FeatureMatchingOptions,
    mapping: pycolmap.IncrementalPipelineOptions,
    neighbours: int = 4,
    device: pycolmap.Device = pycolmap.Device.cpu,
    next_image_callback: Callable[[], None] | None = None,
) -> RetryResult:
    """Register the images of ``database_path`` that ``first`` lacks (see the module doc).

    ``work_dir`` (created, must not exist) receives ``database.db`` (the first-pass database
    with the robust features appended: the returned model's keypoint indices refer to it) and
    scratch files, removed before returning. ``extraction``/``matching`` are the first pass's
    options (made robust here) and ``mapping`` its mapper options; ``first`` is not changed.
    Without a gain the returned model is a copy of ``first``.
    """
    with pycolmap.Database.open(database_path) as db:
        cameras = {c.camera_id: c for c in db.read_all_cameras()}
        sizes = {im.name: (cameras[im.camera_id].width, cameras[im.camera_id].height)
                 for im in db.read_all_images()}
    all_names = sorted(sizes)
    done = registered_names(first)
    retried = [n for n in all_names if n not in done]
    # COLMAP's covariant (affine-shape) detector crashes the process (SIGSEGV in
    # vl_covdet_detect) on a 1x1 image, and no image this small registers anyway.
    extracted = [n for n in retried if min(sizes[n]) >= MIN_IMAGE_SIDE_PX]
    chosen = neighbours_of(database_path, extracted, done, neighbours)
    work_dir.mkdir(parents=True)
    if not extracted:
        shutil.rmtree(work_dir)
        return RetryResult(pycolmap.Reconstruction(first), database_path, tuple(retried), (),
                           (), unregistered_reasons(database_path, first), intrinsics="first")
    timings: dict[str, float] = {}
    started = time.perf_counter()
    robust_db, merged_db = work_dir / "robust.db", work_dir / "database.db"
    # Camera grouping does not matter here: only keypoints, descriptors and matches are used.
    pycolmap.extract_features(robust_db, images_dir, image_names=sorted(extracted + chosen),
                              camera_mode=pycolmap.CameraMode.PER_IMAGE,
                              extraction_options=robust_extraction_options(extraction),
                              device=device)
    timings["extraction"] = time.perf_counter() - started
    started = time.perf_counter()
    pycolmap.match_exhaustive(robust_db, matching_options=robust_matching_options(matching),
                              device=device)
    timings["matching"] = time.perf_counter() - started
    started = time.perf_counter()
    shutil.copy2(database_path, merged_db)
    _append_features(merged_db, robust_db)
    robust_db.unlink()

    timings["merge"] = time.perf_counter() - started
    started = time.perf_counter()
    triangulated_dir = work_dir / "triangulated"
    triangulated_dir.mkdir()
    posed = _posed_model(first, merged_db)
    model = pycolmap.triangulate_points(posed, merged_db, images_dir, triangulated_dir,
                                        clear_points=False, options=mapping)
    model.write(triangulated_dir)
    timings["triangulation"] = time.perf_counter() - started
    started = time.perf_counter()
    best, intrinsics = None, "held"
    for attempt in ("held", "refined"):
        options = pycolmap.IncrementalPipelineOptions(mapping.todict())
        options.multiple_models = False
        # The continued model is kept if it is at least the first one (COLMAP would discard
        # one under min_model_size, as a first model of a small set can be).
        options.min_model_size = min(options.min_model_size, first.num_reg_images())
        if attempt == "held":
            # The first model's intrinsics stay as they are (see the module doc); a retried
            # image with a camera of its own may still refine that one.
            options.constant_cameras = set(first.cameras)
        mapped_dir = work_dir / f"mapped-{attempt}"
        mapped_dir.mkdir()
        models = pycolmap.incremental_mapping(merged_db, images_dir, mapped_dir,
                                              options=options, input_path=triangulated_dir,
                                              next_image_callback=next_image_callback)
        shutil.rmtree(mapped_dir)
        model = max(models.values(), key=lambda m: m.num_reg_images(), default=None)
        if model is not None and model.num_reg_images() > (
                first.num_reg_images() if best is None else best.num_reg_images()):
            best, intrinsics = model, attempt
        if best is not None and best.num_reg_images() == len(all_names):
            break
        # Held intrinsics that are wrong (a first model of a few images) reject right poses:
        # the images left out then get a second attempt with the intrinsics refined, as
        # COLMAP refines them, kept only when it registers more.
    timings["mapping"] = time.perf_counter() - started
    shutil.rmtree(triangulated_dir)
    if best is None:
        # No gain: the first model stands, with the reasons the first pass gave.
        return RetryResult(pycolmap.Reconstruction(first), database_path, tuple(retried),
                           tuple(chosen), (), unregistered_reasons(database_path, first),
                           intrinsics="first", seconds=timings)
    now = registered_names(best)
    return RetryResult(
        model=best,
        database_path=merged_db,
        retried=tuple(retried),
        neighbours=tuple(chosen),
        registered=tuple(n for n in retried if n in now),
        failed=unregistered_reasons(merged_db, best),
        intrinsics=intrinsics,
        seconds=timings,
    )
