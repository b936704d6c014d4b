"""Structure from motion through pycolmap: features → matches → intrinsics → mapping + BA.

Each step is a function from a workspace to files in it (see :mod:`recon.workspace`):

=============  ==========================  ==============================================
step           writes                      reads
=============  ==========================  ==============================================
features       database.db (keypoints)     images/
matches        database.db (matches, F)    database.db
intrinsics     database.db (focal priors)  database.db, an ``intrinsics`` plugin
mapping        sparse/0, sparse/1, ...     database.db, images/
=============  ==========================  ==============================================

Each is skipped when its output exists and its fingerprint (its own config and the
fingerprints of the steps it reads) matches the one recorded in ``run.json``.
"""

from __future__ import annotations

import contextlib
import enum
import importlib
import shutil
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

import plugins
from plugins.protocols import CameraInfo, IntrinsicsContext, IntrinsicsResult
from recon.errors import UserError
from recon.progress import bar, count_rows, polled
from recon.sfm.images import camera_key
from recon.sfm.retry import (
    RetryResult,
    Unregistered,
    retry_unregistered,
    robust_extraction_options,
    robust_matching_options,
    unregistered_reasons,
)
from recon.workspace import StepRecord, Timer, Workspace, atomic_output, fingerprint


class CameraMode(enum.StrEnum):
    AUTO = "auto"
    SINGLE = "single"
    PER_IMAGE = "per-image"
    PER_FOLDER = "per-folder"


class Matcher(enum.StrEnum):
    AUTO = "auto"
    EXHAUSTIVE = "exhaustive"
    SEQUENTIAL = "sequential"


class FrontEnd(enum.StrEnum):
    SIFT = "colmap-sift"
    HARRIS_NCC = "harris-ncc"


class Features(enum.StrEnum):
    DEFAULT = "default"
    ROBUST = "robust"


# Exhaustive matching is quadratic; beyond this many images `auto` switches to sequential.
EXHAUSTIVE_MAX_IMAGES = 150


@dataclass(frozen=True, kw_only=True)
class SfMConfig:
    """Settings of the sparse reconstruction. Field help is the CLI's help."""

    intrinsics: str = field(
        default="colmap-default",
        metadata={"help": "intrinsic initialiser plugin (see `mocap plugins`)"},
    )
    intrinsics_options: tuple[str, ...] = field(
        default=(),
        metadata={
            "help": "an option of the initialiser as KEY=VALUE (repeatable; see `mocap plugins`)",
            "flags": ("-O", "--intrinsics-option"),
            "metavar": "KEY=VALUE",
        },
    )
    camera_model: str = field(
        default="SIMPLE_RADIAL",
        metadata={"help": "COLMAP camera model (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, ...)"},
    )
    camera_mode: CameraMode = field(
        default=CameraMode.AUTO,
        metadata={
            "help": "which images share intrinsics; auto: one camera when all photos have the "
            "same size and EXIF camera and focal length, else one per image"
        },
    )
    front_end: FrontEnd = field(
        default=FrontEnd.SIFT,
        metadata={
            "help": "colmap-sift: COLMAP's SIFT features and matching; harris-ncc: the "
            "thesis' Harris corners, NCC matching and robust F (recon.sfm.frontend), for "
            "small baselines between consecutive photos"
        },
    )
    max_image_size: int = field(
        default=3200,
        metadata={"help": "downscale images to this many pixels on the long side for features"},
    )
    max_num_features: int = field(default=8192, metadata={"help": "SIFT features per image"})
    features: Features = field(
        default=Features.DEFAULT,
        metadata={
            "help": "default: COLMAP's SIFT and matching; robust: affine-covariant, "
            "domain-size-pooled SIFT and guided matching from the start (slower, and less "
            "precise keypoints: on the temple ring the focal came out 1.7-3.3 percent long)"
        },
    )
    matcher: Matcher = field(
        default=Matcher.AUTO,
        metadata={
            "help": f"exhaustive, sequential (video order), or auto (exhaustive up to "
            f"{EXHAUSTIVE_MAX_IMAGES} images)"
        },
    )
    sequential_overlap: int = field(
        default=10, metadata={"help": "sequential matching: neighbours matched per image"}
    )
    refine_focal: bool | None = field(
        default=None,
        metadata={"help": "refine focal in BA (default: as the initialiser says)"},
    )
    retry_unregistered: bool = field(
        default=True,
        metadata={
            "help": "when the first mapping leaves images out, re-extract them and their "
            "neighbours with robust features and register them into the model, its "
            "intrinsics held (recon.sfm.retry); never runs when every image registers"
        },
    )
    retry_neighbours: int = field(
        default=4,
        metadata={"help": "retry: registered images re-extracted with each unregistered one "
                          "(those it shares the most matches with)"},
    )
    num_threads: int = field(default=-1, metadata={"help": "threads (-1: all cores)"})
    seed: int = field(default=0, metadata={"help": "random seed, for repeatable runs"})

    def __post_init__(self) -> None:
        if self.camera_model not in _CAMERA_MODELS:
            raise UserError(
                f"unknown camera model {self.camera_model!r}; choose from "
                + ", ".join(sorted(_CAMERA_MODELS))
            )
        if self.max_image_size < 100:
            raise UserError(f"--max-image-size {self.max_image_size} is too small (min 100)")
        # Checked here, before COLMAP sees them: COLMAP aborts the process (SIGABRT) on an
        # overlap of 0 and fails obscurely on no features (issue 23).
        if self.max_num_features < 1:
            raise UserError(f"--max-num-features {self.max_num_features}: give at least 1")
        if self.sequential_overlap < 1:
            raise UserError(f"--sequential-overlap {self.sequential_overlap}: give at least 1 "
                            "(each image is matched with that many following images)")
        if self.retry_neighbours < 1:
            raise UserError(f"--retry-neighbours {self.retry_neighbours}: give at least 1")
        if self.features == Features.ROBUST and self.front_end == FrontEnd.HARRIS_NCC:
            raise UserError("--features robust is SIFT's; it does not apply to "
                            "--front-end harris-ncc")


_CAMERA_MODELS = {
    "SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV",
    "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "OPENCV_FISHEYE", "THIN_PRISM_FISHEYE",
}


def _config_dict(config: Any, *names: str) -> dict[str, Any]:
    return {n: getattr(config, n) for n in names}


def _device() -> pycolmap.Device:
    return pycolmap.Device.cuda if pycolmap.has_cuda else pycolmap.Device.cpu


class DeferredRecordings:
    """Recording jobs of the SfM steps, run on one background thread once mapping starts.

    Extraction and matching keep both cores busy, incremental mapping of a small set only one;
    importing rerun (~0.3 s) and writing the features, matches and intrinsics recordings then
    costs no wall time. Jobs read only finished files (the renamed database), and
    :meth:`finish` waits for them, so a step's recording exists when ``run_sfm`` returns.
    """

    def __init__(self) -> None:
        self._jobs: list[tuple[Callable[..., None], tuple[Any, ...]]] = []
        self._pool: ThreadPoolExecutor | None = None
        self._futures: list[Future[None]] = []

    def submit(self, job: Callable[..., None], *args: Any) -> None:
        if self._pool is None:
            self._jobs.append((job, args))
        else:
            self._futures.append(self._pool.submit(job, *args))

    def start(self) -> None:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="recordings")
            self._futures.append(self._pool.submit(importlib.import_module, "recon.recording"))
            for job, args in self._jobs:
                self._futures.append(self._pool.submit(job, *args))
            self._jobs.clear()

    def finish(self) -> None:
        """Run what is left and wait; re-raise the first job's error."""
        self.start()
        assert self._pool is not None
        try:
            for future in self._futures:
                future.result()
        finally:
            self._pool.shutdown()


def _record(recordings: DeferredRecordings | None, job: Callable[..., None], *args: Any) -> None:
    if recordings is None:
        job(*args)
    else:
        recordings.submit(job, *args)


# Features ------------------------------------------------------------------------------------
def resolve_camera_mode(ws: Workspace, mode: CameraMode) -> CameraMode:
    if mode is not CameraMode.AUTO:
        return mode
    keys = {camera_key(ws.images_dir / n) for n in ws.image_names()}
    return CameraMode.SINGLE if len(keys) == 1 else CameraMode.PER_IMAGE


def extract_features(
    ws: Workspace, config: SfMConfig, *, overwrite: bool = False,
    recordings: DeferredRecordings | None = None,
) -> StepRecord:
    names = ws.image_names()
    if len(names) < 2:
        raise UserError(f"{ws.images_dir} holds {len(names)} image(s); SfM needs at least 2")
    mode = resolve_camera_mode(ws, config.camera_mode)
    settings = {
        **_config_dict(config, "camera_model", "max_image_size", "max_num_features"),
        "front_end": str(config.front_end),
        "camera_mode": str(mode),
        "images": names,
    }
    if config.features == Features.ROBUST:
        # Only when set, so that the default's fingerprint (and existing workspaces) stay.
        settings["features"] = str(config.features)
    fp = fingerprint("features", settings)
    if done := ws.reusable("features", fp, ws.database_path, overwrite=overwrite):
        return done

    reader = pycolmap.ImageReaderOptions(camera_model=config.camera_model)
    extraction = _extraction_options(config)
    if config.features == Features.ROBUST:
        _refuse_tiny_images(ws, names)
        robust_extraction_options(extraction)
    colmap_mode = {
        CameraMode.SINGLE: pycolmap.CameraMode.SINGLE,
        CameraMode.PER_IMAGE: pycolmap.CameraMode.PER_IMAGE,
        CameraMode.PER_FOLDER: pycolmap.CameraMode.PER_FOLDER,
    }[mode]
    with Timer() as timer, atomic_output(ws.database_path) as db:
        if config.front_end is FrontEnd.HARRIS_NCC:
            _extract_harris(ws, db, names, colmap_mode, reader, config)
        else:
            with polled(len(names), "features", "img", count_rows(db, "keypoints")):
                pycolmap.extract_features(
                    db,
                    ws.images_dir,
                    image_names=names,
                    camera_mode=colmap_mode,
                    reader_options=reader,
                    extraction_options=extraction,
                    device=_device(),
                )
        with pycolmap.Database.open(db) as database:
            num_images = database.num_images()
            num_keypoints = database.num_keypoints()
            num_cameras = database.num_cameras()
            read = {image.name for image in database.read_all_images()}
        if num_images != len(names):
            # COLMAP says which only in a WARNING line, hidden by default: name them here.
            unread = [name for name in names if name not in read]
            shown = ", ".join(unread[:5]) + (f" and {len(unread) - 5} more"
                                             if len(unread) > 5 else "")
            raise UserError(f"COLMAP could not read {len(unread)} of {len(names)} images in "
                            f"{ws.images_dir}: {shown} (convert them to JPEG or PNG)")
    _record(recordings, _log_features, ws, _feature_rows(ws.database_path))
    return ws.record_step(
        "features",
        fp,
        outputs=[ws.database_path],
        config=settings | {"images": len(names)},
        seconds=timer.seconds,
        summary={"images": num_images, "cameras": num_cameras, "keypoints": num_keypoints},
    )


def _refuse_tiny_images(ws: Workspace, names: list[str]) -> None:
    """COLMAP's covariant (affine-shape) SIFT detector crashes the process (SIGSEGV) on a 1x1
    image, where the default detector skips it: refuse such images up front, by name."""
    from PIL import Image

    from recon.sfm.images import MIN_IMAGE_SIDE_PX

    tiny = []
    for name in names:
        with Image.open(ws.images_dir / name) as image:
            if min(image.size) < MIN_IMAGE_SIDE_PX:
                tiny.append(f"{name} ({image.size[0]}x{image.size[1]})")
    if tiny:
        raise UserError(f"--features robust cannot read images under {MIN_IMAGE_SIDE_PX} px on a "
                        f"side (COLMAP's affine-shape detector crashes on them): "
                        f"{', '.join(tiny[:5])}; remove them or use the default features")


def _extraction_options(config: SfMConfig) -> pycolmap.FeatureExtractionOptions:
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.max_image_size = config.max_image_size
    extraction.num_threads = config.num_threads
    extraction.sift.max_num_features = config.max_num_features
    return extraction


def _matching_options(config: SfMConfig) -> pycolmap.FeatureMatchingOptions:
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = config.num_threads
    return matching


def _harris_config(config: SfMConfig) -> Any:
    from recon.sfm.frontend import HarrisNccConfig

    return HarrisNccConfig(max_image_size=config.max_image_size,
                           max_corners=config.max_num_features)


def _extract_harris(
    ws: Workspace,
    db: Path,
    names: list[str],
    mode: pycolmap.CameraMode,
    reader: pycolmap.ImageReaderOptions,
    config: SfMConfig,
) -> None:
    """Cameras and images as COLMAP would create them, with Harris corners as keypoints."""
    import cv2

    from recon.sfm.frontend import detect_corners

    pycolmap.Database.open(db).close()  # import_images wants an existing database
    pycolmap.import_images(db, ws.images_dir, camera_mode=mode, image_names=names,
                           options=reader)
    harris = _harris_config(config)
    progress = bar(len(names), "corners", "img")
    with pycolmap.Database.open(db) as database:
        for image in database.read_all_images():
            gray = cv2.imread(str(ws.images_dir / image.name), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise UserError(f"cannot read image {ws.images_dir / image.name}")
            # Corners are (N, 2) px with pixel centres at +0.5, COLMAP's keypoint convention.
            database.write_keypoints(image.image_id, detect_corners(gray, harris))
            progress.update(1)
    progress.close()


def _match_harris(ws: Workspace, db: Path, pairs: list[tuple[str, str]] | None,
                  config: SfMConfig) -> None:
    """NCC matches and robust F of each pair, written as COLMAP matches and geometries."""
    from recon.sfm.frontend import run_front_end

    names = ws.image_names()
    total = len(names) + (len(pairs) if pairs is not None else len(names) * (len(names) - 1) // 2)
    progress = bar(total, "matching", "step")

    def advance(done: int, _total: int) -> None:
        progress.n = done
        progress.refresh()

    result = run_front_end({n: ws.images_dir / n for n in names}, _harris_config(config),
                           pairs=pairs, progress=advance)
    progress.close()
    with pycolmap.Database.open(db) as database:
        ids = {im.name: im.image_id for im in database.read_all_images()}
        for name in names:
            # The front end detects corners exactly as the features step did.
            if len(database.read_keypoints(ids[name])) != len(result.corners[name]):
                raise UserError(f"corners of {name} changed since the features step; "
                                "rerun with --overwrite")
        for (a, b), geometry in result.pairs.items():
            matches = np.asarray(geometry.matches, dtype=np.uint32).reshape(-1, 2)
            database.write_matches(ids[a], ids[b], matches)
            tvg = pycolmap.TwoViewGeometry()
            if geometry.status == "ok" and geometry.F is not None:
                tvg.config = pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED
                tvg.F = geometry.F
                tvg.inlier_matches = np.asarray(geometry.inlier_matches, dtype=np.uint32)
            else:
                tvg.config = pycolmap.TwoViewGeometryConfiguration.DEGENERATE
            database.write_two_view_geometry(ids[a], ids[b], tvg)


def _sequential_pairs(names: list[str], overlap: int) -> list[tuple[str, str]]:
    return [(names[i], names[j]) for i in range(len(names))
            for j in range(i + 1, min(len(names), i + 1 + overlap))]


def _feature_rows(database_path: Path) -> list[tuple[str, np.ndarray, int, int, np.ndarray]]:
    """(image name, K, width, height, keypoints (N, 2)) of every image, sorted by name: what
    the features recording shows, read here so that the deferred recording job never opens
    the database while mapping writes it (SQLite would refuse one of them under load)."""
    with pycolmap.Database.open(database_path) as db:
        cameras = {c.camera_id: c for c in db.read_all_cameras()}
        rows = []
        for image in sorted(db.read_all_images(), key=lambda im: im.name):
            cam = cameras[image.camera_id]
            rows.append((image.name, cam.calibration_matrix(), cam.width, cam.height,
                         db.read_keypoints(image.image_id)[:, :2].copy()))  # fmt: skip
    return rows


def _log_features(ws: Workspace, rows: list[tuple[str, np.ndarray, int, int, np.ndarray]]
                  ) -> None:  # fmt: skip
    from recon import recording

    with recording.step_recording(ws.log_path("features"), "features") as rec:
        for name, K, width, height, keypoints in rows:
            recording.log_camera_image(
                rec,
                image_name=name,
                image_path=ws.images_dir / name,
                K=K,
                width=width,
                height=height,
                # COLMAP keypoints have pixel centres at +0.5; Rerun's 2D space too.
                points2D=keypoints,
            )
        recording.log_series(rec, "image", "stats/keypoints_per_image",
                             [len(row[4]) for row in rows])


# Matches -------------------------------------------------------------------------------------
def match_features(
    ws: Workspace, config: SfMConfig, *, overwrite: bool = False,
    recordings: DeferredRecordings | None = None,
) -> StepRecord:
    upstream = ws.require_step("features", f"no features yet; run `mocap sfm {ws.root}`",
                               f"mocap sfm {ws.root}")
    num_images = upstream.summary["images"]
    matcher = config.matcher
    if matcher is Matcher.AUTO:
        matcher = Matcher.EXHAUSTIVE if num_images <= EXHAUSTIVE_MAX_IMAGES else Matcher.SEQUENTIAL
    settings = {"matcher": str(matcher), "sequential_overlap": config.sequential_overlap}
    robust = upstream.config.get("features") == Features.ROBUST
    if robust:
        settings["guided_matching"] = True
    fp = fingerprint("matches", settings, upstream.fingerprint)
    if done := ws.reusable("matches", fp, ws.database_path, overwrite=overwrite):
        return done

    matching = _matching_options(config)
    if robust:
        robust_matching_options(matching)
    with Timer() as timer, atomic_output(ws.database_path, seed_from=ws.database_path) as db:
        with pycolmap.Database.open(db) as database:
            # Stale matches from other settings would be kept by COLMAP, which skips known pairs.
            database.clear_matches()
            database.clear_two_view_geometries()
        if upstream.config.get("front_end") == FrontEnd.HARRIS_NCC:
            sequential = matcher is Matcher.SEQUENTIAL
            names = ws.image_names()
            pairs = _sequential_pairs(names, config.sequential_overlap) if sequential else None
            _match_harris(ws, db, pairs, config)
        elif matcher is Matcher.EXHAUSTIVE:
            total = num_images * (num_images - 1) // 2
            with polled(total, "matching", "pair", count_rows(db, "two_view_geometries")):
                pycolmap.match_exhaustive(db, matching_options=matching, device=_device())
        else:
            pairing = pycolmap.SequentialPairingOptions()
            pairing.overlap = config.sequential_overlap
            total = num_images * min(config.sequential_overlap, num_images - 1)
            with polled(total, "matching", "pair", count_rows(db, "two_view_geometries")):
                pycolmap.match_sequential(
                    db, matching_options=matching, pairing_options=pairing, device=_device()
                )
        pairs = verified_pairs(db)
    _record(recordings, _log_matches, ws, pairs)
    verified = [p for p in pairs if p["inliers"] > 0]
    return ws.record_step(
        "matches",
        fp,
        updated=[ws.database_path],
        config=settings,
        seconds=timer.seconds,
        summary={"pairs": len(pairs), "verified_pairs": len(verified)},
    )


def verified_pairs(database_path: Path) -> list[dict[str, Any]]:
    """Every matched image pair with its verified inlier count and geometry type."""
    with pycolmap.Database.open(database_path) as db:
        names = {im.image_id: im.name for im in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
    rows = []
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        i, j = pycolmap.pair_id_to_image_pair(pair_id)
        rows.append(
            {
                "image_i": names[i],
                "image_j": names[j],
                "inliers": len(geometry.inlier_matches),
                "config": pycolmap.TwoViewGeometryConfiguration(int(geometry.config)).name,
            }
        )
    return sorted(rows, key=lambda r: (r["image_i"], r["image_j"]))


def _log_matches(ws: Workspace, pairs: list[dict[str, Any]]) -> None:
    from recon import recording

    with recording.step_recording(ws.log_path("matches"), "matches") as rec:
        recording.log_series(rec, "pair", "stats/inliers_per_pair", [p["inliers"] for p in pairs])
        recording.log_table(rec, "tables/pairs", "Verified image pairs", pairs)


# Intrinsics ----------------------------------------------------------------------------------
def database_cameras(database_path: Path) -> tuple[CameraInfo, ...]:
    with pycolmap.Database.open(database_path) as db:
        by_camera: dict[int, list[str]] = defaultdict(list)
        for image in db.read_all_images():
            by_camera[image.camera_id].append(image.name)
        return tuple(
            CameraInfo(
                camera_id=c.camera_id,
                model=c.model.name,
                width=c.width,
                height=c.height,
                image_names=tuple(sorted(by_camera[c.camera_id])),
            )
            for c in sorted(db.read_all_cameras(), key=lambda c: c.camera_id)
        )


def initialise_intrinsics(
    ws: Workspace, config: SfMConfig, *, overwrite: bool = False,
    recordings: DeferredRecordings | None = None,
) -> StepRecord:
    upstream = ws.require_step("matches", f"no matches yet; run `mocap sfm {ws.root}`",
                               f"mocap sfm {ws.root}")
    settings = {"intrinsics": config.intrinsics, "options": list(config.intrinsics_options)}
    fp = fingerprint("intrinsics", settings, upstream.fingerprint)
    if done := ws.reusable("intrinsics", fp, ws.database_path, overwrite=overwrite):
        return done

    initialiser = plugins.create("intrinsics", config.intrinsics, config.intrinsics_options)
    with Timer() as timer, atomic_output(ws.database_path, seed_from=ws.database_path) as db:
        cameras = database_cameras(db)
        result: IntrinsicsResult = initialiser.initialise(
            IntrinsicsContext(database_path=db, images_dir=ws.images_dir, cameras=cameras)
        )
        applied = _write_focal_priors(db, result)
    _record(recordings, _log_intrinsics, ws, config.intrinsics, applied)
    return ws.record_step(
        "intrinsics",
        fp,
        updated=[ws.database_path],
        config=settings,
        seconds=timer.seconds,
        summary={
            "cameras": applied,
            "refine_focal": result.refine_focal,
            "notes": list(result.notes),
            "details": dict(result.details),
        },
    )


def _log_intrinsics(ws: Workspace, name: str, applied: list[dict[str, Any]]) -> None:
    from recon import recording

    with recording.step_recording(ws.log_path("intrinsics"), "intrinsics") as rec:
        recording.log_table(rec, "tables/intrinsics", f"Focal priors ({name})", applied)


def _write_focal_priors(database_path: Path, result: IntrinsicsResult) -> list[dict[str, Any]]:
    by_id = {p.camera_id: p for p in result.priors}
    applied = []
    with pycolmap.Database.open(database_path) as db:
        for camera in db.read_all_cameras():
            prior = by_id.get(camera.camera_id)
            if prior is None:
                raise UserError(f"intrinsics plugin gave no focal for camera {camera.camera_id}")
            if prior.focal_px is None:
                # COLMAP's own starting guess, and no prior: the mapper may re-estimate it.
                camera.focal_length = 1.2 * max(camera.width, camera.height)
                camera.has_prior_focal_length = False
            else:
                if not (np.isfinite(prior.focal_px) and prior.focal_px > 0):
                    raise UserError(
                        f"intrinsics plugin gave focal {prior.focal_px} for camera "
                        f"{camera.camera_id}; expected a positive number of pixels"
                    )
                camera.focal_length = float(prior.focal_px)
                camera.has_prior_focal_length = True
            if prior.principal_point_px is not None:
                cx, cy = (float(v) for v in prior.principal_point_px)
                if not (0 <= cx <= camera.width and 0 <= cy <= camera.height):
                    raise UserError(
                        f"intrinsics plugin gave principal point ({cx}, {cy}) for camera "
                        f"{camera.camera_id}, outside its {camera.width}x{camera.height} image"
                    )
                camera.principal_point_x, camera.principal_point_y = cx, cy
            db.update_camera(camera)
            applied.append(
                {
                    "camera_id": camera.camera_id,
                    "focal_px": float(camera.focal_length),
                    "prior": prior.focal_px is not None,
                    "source": prior.source,
                    "principal_point_px": [float(camera.principal_point_x),
                                           float(camera.principal_point_y)],
                }
            )
    return applied


# Mapping -------------------------------------------------------------------------------------
def map_sparse(
    ws: Workspace, config: SfMConfig, *, overwrite: bool = False,
    recordings: DeferredRecordings | None = None,
) -> StepRecord:
    upstream = ws.require_step(
        "intrinsics", f"intrinsics not initialised; run `mocap sfm {ws.root}`",
        f"mocap sfm {ws.root}")
    refine = config.refine_focal
    if refine is None:
        refine = upstream.summary["refine_focal"]
    settings = {"refine_focal": refine, "seed": config.seed,
                "retry_unregistered": config.retry_unregistered,
                "retry_neighbours": config.retry_neighbours}
    fp = fingerprint("mapping", settings, upstream.fingerprint)
    if done := ws.reusable("mapping", fp, ws.model_dir, overwrite=overwrite):
        return done

    pycolmap.set_random_seed(config.seed)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = config.num_threads
    options.random_seed = config.seed
    # COLMAP's incremental pipeline ends each model with a global bundle adjustment (unless the
    # last one already was global), so this step is mapping *and* bundle adjustment.
    options.ba_refine_focal_length = refine
    options.mapper.abs_pose_refine_focal_length = refine
    num_images = len(ws.image_names())
    # COLMAP discards models under 10 images; a smaller photo set is still a valid model.
    options.min_model_size = min(options.min_model_size, num_images)
    with Timer() as timer, atomic_output(ws.sparse_dir) as out:
        raw = out / "unsorted"
        raw.mkdir(parents=True)
        progress = bar(num_images, "mapping", "img")
        # Registered-image count after each registration, logged once mapping is done.
        registrations: list[int] = []

        def on_image() -> None:
            registrations.append(len(registrations) + 1)
            progress.update(1)

        if recordings is not None:
            # Mapping keeps one core busy at most on small sets: write the queued recordings
            # (and import rerun) on the other one meanwhile.
            recordings.start()
        retry_report: dict[str, Any] | None = None
        try:
            if num_images == 2:
                # The thesis' two-photo case: E from the verified F and the focal, the pose
                # in front of both cameras, triangulation, BA (recon.sfm.twoview).
                from recon.sfm.twoview import two_view_model

                models = {0: two_view_model(ws.database_path, ws.images_dir,
                                            refine_focal=refine)}
                registrations += [1, 2]
                progress.update(2)
            else:
                with _colmap_errors_restated():
                    models = pycolmap.incremental_mapping(
                        ws.database_path, ws.images_dir, raw, options=options,
                        next_image_callback=on_image,
                    )
            if not models:
                raise UserError(f"mapping registered no images in {ws.root}: "
                                f"{_why_no_model(ws.database_path)}")
            ordered = sorted(models.values(), key=lambda r: r.num_reg_images(), reverse=True)
            if ordered[0].num_reg_images() < num_images and num_images > 2:
                ordered[0], retry_report = _second_pass(
                    ws, config, ordered[0], options, out / "retry", on_image)
        finally:
            progress.close()
        for index, model in enumerate(ordered):
            (out / str(index)).mkdir()
            model.write(out / str(index))
        shutil.rmtree(raw)
        summary = model_summary(ordered[0], num_images) | {"models": len(ordered)}
        if retry_report is not None:
            summary["retry"] = retry_report
        _log_mapping(ws, ordered[0], registrations)
    return ws.record_step("mapping", fp, outputs=[ws.model_dir], config=settings,
                          seconds=timer.seconds, summary=summary)


def _second_pass(
    ws: Workspace, config: SfMConfig, first: pycolmap.Reconstruction,
    options: pycolmap.IncrementalPipelineOptions, work_dir: Path,
    on_image: Callable[[], None],
) -> tuple[pycolmap.Reconstruction, dict[str, Any]]:
    """The images ``first`` lacks, with why, retried when the settings allow
    (:func:`recon.sfm.retry.retry_unregistered`). Returns the model to keep and the report of
    the mapping summary's ``retry`` entry; the retry's database is left in ``work_dir``
    (``sparse/retry/database.db``) only when its model is kept."""
    reasons = unregistered_reasons(ws.database_path, first)
    report: dict[str, Any] = {
        "unregistered_first_pass": {name: r.as_dict() for name, r in reasons.items()},
        "ran": False,
    }
    features = ws.step("features")
    robust_already = features is not None and features.config.get("features") == Features.ROBUST
    harris = features is not None and features.config.get("front_end") == FrontEnd.HARRIS_NCC
    if not config.retry_unregistered or robust_already or harris:
        report["skipped"] = ("--no-retry-unregistered" if not config.retry_unregistered
                             else "the features are already robust" if robust_already
                             else "the Harris + NCC front end has no robust variant")
        report["failed"] = report["unregistered_first_pass"]
        return first, report
    started = time.perf_counter()
    try:
        with _colmap_errors_restated():
            result: RetryResult = retry_unregistered(
                ws.database_path, ws.images_dir, first, work_dir,
                extraction=_extraction_options(config),
                matching=_matching_options(config),
                mapping=options,
                neighbours=config.retry_neighbours,
                device=_device(),
                next_image_callback=on_image,
            )
    except (RuntimeError, ValueError) as error:
        # The retry is a second chance: its failure must not cost the first model.
        shutil.rmtree(work_dir, ignore_errors=True)
        report.update(ran=True, error=str(error).strip().splitlines()[-1],
                      failed=report["unregistered_first_pass"],
                      seconds=round(time.perf_counter() - started, 3))
        return first, report
    if result.database_path != work_dir / "database.db":
        shutil.rmtree(work_dir, ignore_errors=True)
    report.update(
        ran=True,
        retried=list(result.retried),
        neighbours=list(result.neighbours),
        registered=list(result.registered),
        failed={name: r.as_dict() for name, r in result.failed.items()},
        database=(str(Path("sparse") / "retry" / "database.db")
                  if work_dir.exists() else None),
        intrinsics=result.intrinsics,
        stage_seconds={k: round(v, 3) for k, v in result.seconds.items()},
        first_pass_registered=first.num_reg_images(),
        first_pass_mean_reprojection_error_px=first.compute_mean_reprojection_error(),
        seconds=round(time.perf_counter() - started, 3),
    )
    return result.model, report


def _why_no_model(database_path: Path) -> str:
    """Why mapping found no initial pair, from the verified pairs in the database."""
    from recon.sfm.twoview import MIN_MEDIAN_PARALLAX_PX, median_parallax_px

    with pycolmap.Database.open(database_path) as db:
        pair_ids, geometries = db.read_two_view_geometries()
        verified = [(pycolmap.pair_id_to_image_pair(pair_id), geometry)
                    for pair_id, geometry in zip(pair_ids, geometries, strict=True)
                    if len(geometry.inlier_matches) >= 15]
        keypoints = {i: db.read_keypoints(i)[:, :2]
                     for i in {i for pair, _ in verified for i in pair}}
    if verified and all(
        median_parallax_px(keypoints[i], keypoints[j], geometry.inlier_matches)
        < MIN_MEDIAN_PARALLAX_PX
        for (i, j), geometry in verified
    ):
        return ("the photos are copies of one view (their matches do not move): take them "
                "from different places")
    no_baseline = (pycolmap.TwoViewGeometryConfiguration.PANORAMIC,
                   pycolmap.TwoViewGeometryConfiguration.PLANAR_OR_PANORAMIC)
    if verified and all(geometry.config in no_baseline for _, geometry in verified):
        return ("every matched pair fits a pure rotation or a plane: move the camera between "
                "the photos (see logs/matches.rrd for verified pairs)")
    return "the photos do not overlap enough (see logs/matches.rrd for verified pairs)"


# glog severities, as pycolmap.logging.minloglevel takes them.
_GLOG_ERROR, _GLOG_FATAL = 2, 3


@contextlib.contextmanager
def _colmap_errors_restated() -> Iterator[None]:
    """COLMAP's ERROR lines hidden while a call runs whose failure we report in our own words
    (mapping's "Failed to create any sparse model" before our one-line error).

    Only at the CLI's quiet level (ERROR: `_quiet_colmap` in recon/cli.py): with ``-v``, or for a
    library caller who left glog at its default, every COLMAP line still shows.
    """
    logging = pycolmap.logging
    quiet = logging.minloglevel == _GLOG_ERROR
    if quiet:
        logging.minloglevel = _GLOG_FATAL
    try:
        yield
    finally:
        if quiet:
            logging.minloglevel = _GLOG_ERROR


def model_summary(model: pycolmap.Reconstruction, num_images: int) -> dict[str, Any]:
    return {
        "images": num_images,
        "registered": model.num_reg_images(),
        "points": model.num_points3D(),
        "mean_reprojection_error_px": model.compute_mean_reprojection_error(),
        "mean_track_length": model.compute_mean_track_length(),
        "cameras": [
            {
                "camera_id": cam_id,
                "model": cam.model.name,
                "width": cam.width,
                "height": cam.height,
                "params": [float(v) for v in cam.params],
                "focal_px": float(cam.mean_focal_length()),
            }
            for cam_id, cam in sorted(model.cameras.items())
        ],
    }


def cams_from_world(model: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Registered images' poses: name → (3, 4) ``cam_from_world`` [R | t]."""
    return {
        im.name: im.cam_from_world().matrix()
        for im in model.images.values()
        if im.has_pose
    }


def per_image_reprojection_error(model: pycolmap.Reconstruction) -> dict[str, float]:
    """Mean reprojection error in pixels of each registered image's triangulated points."""
    errors: dict[str, float] = {}
    for image in model.images.values():
        if not image.has_pose:
            continue
        residuals = []
        for p2d in image.points2D:
            if p2d.has_point3D():
                projected = image.project_point(model.points3D[p2d.point3D_id].xyz)
                if projected is not None:
                    residuals.append(np.linalg.norm(projected - p2d.xy))
        errors[image.name] = float(np.mean(residuals)) if residuals else float("nan")
    return errors


def _log_mapping(ws: Workspace, model: pycolmap.Reconstruction, registrations: list[int]
                 ) -> None:
    from recon import recording

    with recording.step_recording(ws.log_path("mapping"), "mapping") as rec:
        recording.log_series(rec, "registration", "stats/registered_images", registrations)
        _log_model(rec, ws, model)


def _log_model(rec: Any, ws: Workspace, model: pycolmap.Reconstruction) -> None:
    from recon import recording

    ids = sorted(model.points3D)
    if ids:
        xyz = np.array([model.points3D[i].xyz for i in ids])
        rgb = np.array([model.points3D[i].color for i in ids], dtype=np.uint8)
        recording.log_points(rec, xyz, rgb)
    for image in sorted(model.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            continue
        cam = model.cameras[image.camera_id]
        observed = np.array([p.xy for p in image.points2D if p.has_point3D()]).reshape(-1, 2)
        recording.log_camera_image(
            rec,
            image_name=image.name,
            image_path=ws.images_dir / image.name,
            K=cam.calibration_matrix(),
            width=cam.width,
            height=cam.height,
            cam_from_world=image.cam_from_world().matrix(),
            points2D=observed,
        )
    errors = per_image_reprojection_error(model)
    names = sorted(errors)
    # Bars, not a curve: the mapping recording's timeline is `registration` (its blueprint's).
    recording.log_bars(rec, "stats/reprojection_error_px", [errors[n] for n in names])
    recording.log_table(
        rec,
        "tables/images",
        "Registered images",
        [{"index": i, "image": n, "reprojection_error_px": errors[n]} for i, n in enumerate(names)],
    )


# The whole chain -----------------------------------------------------------------------------
@dataclass(frozen=True)
class SfMSummary:
    workspace: Path
    steps: dict[str, StepRecord]
    reused: tuple[str, ...]

    @property
    def mapping(self) -> dict[str, Any]:
        return self.steps["mapping"].summary

    def lines(self) -> list[str]:
        m = self.mapping
        intr = self.steps["intrinsics"]
        out = [
            f"workspace   {self.workspace}",
            f"registered  {m['registered']} of {m['images']} images"
            + (f" (largest of {m['models']} models)" if m["models"] > 1 else ""),
            *retry_lines(m.get("retry")),
            f"points      {m['points']}  (mean track length {m['mean_track_length']:.2f})",
            f"reprojection error  {m['mean_reprojection_error_px']:.3f} px (mean)",
        ]
        priors = {c["camera_id"]: c for c in intr.summary["cameras"]}
        for cam in m["cameras"][:4]:
            prior = priors.get(cam["camera_id"], {})
            out.append(
                f"camera {cam['camera_id']}    {cam['model']} {cam['width']}x{cam['height']}"
                f"  focal {cam['focal_px']:.1f} px  (start {prior.get('focal_px', 0):.1f}, "
                f"{prior.get('source', '?')})"
            )
        if len(m["cameras"]) > 4:
            out.append(f"            ... and {len(m['cameras']) - 4} more cameras")
        for note in intr.summary.get("notes", []):
            out.append(f"note        {note}")
        times = "  ".join(
            f"{name} {rec.seconds:.1f}s" + (" (reused)" if name in self.reused else "")
            for name, rec in self.steps.items()
        )
        out += [
            f"time        {times}",
            f"model       {self.workspace / 'sparse' / '0'}  (COLMAP binary)",
            f"view        mocap view {self.workspace}",
        ]
        return out


def _reason_text(reason: dict[str, Any]) -> str:
    return Unregistered(**reason).describe()


def retry_lines(retry: dict[str, Any] | None) -> list[str]:
    """The summary lines of the mapping step's ``retry`` entry: which images the first pass
    left out and why, what the retry registered, and why the rest stayed out."""
    if retry is None:
        return []
    first = retry["unregistered_first_pass"]
    out = []
    if retry.get("registered") is not None:
        out.append(f"retry       {len(first)} left out by the first pass, re-matched with robust "
                   f"features: {len(retry['registered'])} registered ({retry['seconds']:.1f} s)"
                   + (", the intrinsics refined: held, they left images out"
                      if retry.get("intrinsics") == "refined" else ""))
        for name in retry["registered"]:
            out.append(f"            {name}: {_reason_text(first[name])} at first")
    elif "error" in retry:
        out.append(f"retry       failed ({retry['error']}); the first model is kept")
    elif "skipped" in retry:
        out.append(f"retry       not run: {retry['skipped']}")
    for name, reason in retry["failed"].items():
        out.append(f"unregistered {name}: {_reason_text(reason)}")
    return out


STEPS = (
    ("features", extract_features),
    ("matches", match_features),
    ("intrinsics", initialise_intrinsics),
    ("mapping", map_sparse),
)


def run_sfm(ws: Workspace, config: SfMConfig, *, overwrite: bool = False) -> SfMSummary:
    """All SfM steps in order; each resumes from what the workspace already holds."""
    recordings = DeferredRecordings()
    steps: dict[str, StepRecord] = {}
    reused = []
    for name, step in STEPS:
        before = ws.step(name)
        steps[name] = step(ws, config, overwrite=overwrite, recordings=recordings)
        if before is not None and before == steps[name]:
            reused.append(name)
    recordings.finish()
    return SfMSummary(ws.root, steps, tuple(reused))
