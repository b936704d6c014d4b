"""`mocap silhouettes`: foreground masks of every camera's video frames (thesis section 6.2.1).

Reads a video workspace (`tracking.rig.video`) and writes::

    WS/silhouettes/<camera>/<frame:06d>.png   uint8 masks, 255 foreground / 0 background,
                                              frame index 0-based, one per processed frame
    WS/silhouettes/<camera>/unknown.png       pixels whose background is unknown (255), with
                                              --background-images only, when there are any
    WS/silhouettes/cameras.json               the cameras the silhouettes agree with: the
                                              calibration, corrected by silhouette coherence
                                              (`tracking.silhouettes.coherence`) when other
                                              frames confirm the correction
    WS/logs/silhouettes.rrd                   cameras, sample frames with their masks,
                                              backgrounds, foreground fraction over frames
    WS/run.json                               step ``silhouettes``: config and summary

The background model of each camera comes from one of four sources (the README says which to
use when). **Background plates**, recorded before the subject walks in: photos
(``--background-images``) or a clip (``--background-video``) of the empty scene per camera
(`background_plates` pairs them with the cameras by name). With ``--plates clean`` (the
default) they are the model (6.2.1): the mean and standard deviation of a camera's photos, or
the median and spread of frames spread over its clip (`plate_model`); one photo cannot show its
own spread, which a noise model stands in for (`BackgroundModel.from_photo`: the photo's
measured noise, and half a pixel of misalignment at edges). Each frame's exposure is matched to
the plate (`tracking.silhouettes.subtraction.exposure_gain`) before it is classified, and the
plates are refused in one line when they leave most of the image foreground in every one of a
few frames spread over the video (another camera's plate, a camera that moved). A camera
without a plate, when the others have one, is refused unless ``--median-fallback``. With
``--plates cluttered`` (photos that may show people or objects the video does not, as the
Pose2Sim demo's calibration shots do), the median below stays the model and the photos complete
it where the subject moved (`with_background_photo`). Without plates, either the per-pixel mean
and standard deviation of frames that show the empty scene (``--background frames:A-B``, the
thesis' method; at most ``--background-samples`` of them, spread over A-B), or, when no such
frames exist (the Pose2Sim demo), the temporal median and median absolute deviation of
``--background-samples`` frames spread evenly over the whole video (``--background median``),
then again over the frames where each pixel is not foreground (``--background-passes``;
`BackgroundModel.from_sequence`): right wherever the subject covers a pixel in fewer than half
of them, so a subject who hardly moves becomes background: a camera whose silhouettes span the
same pixels in most frames is reported, and where they went marked unknown
(`held_by_median`). `background_sample` and
`background_model` are that choice and that model (benchmarks/silhouettes_cdnet.py scores
the whole step). Each processed frame is then classified
(`tracking.silhouettes.subtraction`: foreground / background / shadow thresholds,
morphological clean-up) at full resolution.

``--first``, ``--last`` and ``--frame-step`` choose the processed frames. The summary gives per
camera the foreground fraction (min / median / max over frames) and lists frames whose
silhouette is empty or touches the image border (the subject leaving the view); these are
warnings, printed by the CLI. All masks go to ``silhouettes.partial/`` first, which replaces
``silhouettes/`` only when every camera is done.

Under `mocap batch` (:func:`cameras_mapped_by`) the background models are a task per camera and
the classification a task per run of about a dozen frames of a camera (:func:`frame_chunks`),
with the very results of a plain run, which does one camera after the other in its process.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import enum
import itertools
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from recon.cameras import Camera, write_cameras_json
from recon.errors import UserError
from recon.progress import bar
from recon.sfm.images import IMAGE_SUFFIXES
from recon.workspace import (
    StepRecord,
    Timer,
    Workspace,
    atomic_output,
    file_digest,
    fingerprint,
)
from tracking.rig.video import STEP as INIT_STEP
from tracking.rig.video import (
    VIDEO_SUFFIXES,
    content_box,
    name_in_file_name,
    read_frames,
    read_video_frames,
    video_info,
    video_path,
    workspace_cameras,
)
from tracking.silhouettes.coherence import CoherenceConfig, CoherenceResult, refine_rig
from tracking.silhouettes.hull import HullCheckConfig, consistent_silhouettes
from tracking.silhouettes.subtraction import (
    PHOTO_MISALIGNMENT_PX,
    BackgroundModel,
    SilhouetteConfig,
    component_hulls,
    disc,
    exposure_gain,
    fill_holes,
    matched_exposure,
    noise_sigma,
    silhouette_from_frame,
)

STEP = "silhouettes"
CAMERAS_NAME = "cameras.json"
"""In ``WS/silhouettes``: the cameras the silhouettes agree with (`tracked_cameras`)."""
UNKNOWN_NAME = "unknown.png"
"""``silhouettes/<camera>/unknown.png``: the camera's pixels whose background is unknown (255),
left out of the tracking energy and of the silhouette IoU; written only when there are any."""
_BACKGROUND_FORMAT = re.compile(r"^(median|frames:(\d+)-(\d+))$")


class Plates(enum.StrEnum):
    """What the background plates show (``--plates``)."""

    CLEAN = "clean"
    """Only the empty scene: they are the background model."""
    CLUTTERED = "cluttered"
    """Maybe people or objects the video does not show: they complete the median."""



@dataclass(frozen=True, kw_only=True)
class SilhouettesConfig:
    """Settings of the silhouettes step. Field help is the CLI's help."""

    background: str = field(
        default="median",
        metadata={"help": "background model: 'median' (temporal median of frames spread over "
                  "the whole video, for footage without an empty scene) or 'frames:A-B' (mean "
                  "and spread of frames A..B, 0-based and inclusive, that show the empty scene)"},
    )
    background_samples: int = field(
        default=21,
        metadata={"help": "frames in the background model, spread evenly over the video (or "
                  "over A-B); an even number is rounded up to odd; memory: that many decoded "
                  "frames"},
    )
    background_passes: int = field(
        default=2,
        metadata={"help": "passes of the median background: each after the first leaves out, "
                  "per pixel, the frames where the previous one saw the subject"},
    )  # fmt: skip
    first: int = field(default=0, metadata={"help": "first frame to process (0-based)"})
    last: int | None = field(
        default=None, metadata={"help": "last frame to process, inclusive (default: the last)"})
    frame_step: int = field(
        default=1, metadata={"help": "process every N-th frame from --first (1: all)"})
    background_images: Path | None = field(
        default=None,
        metadata={"metavar": "DIR",
                  "help": "folder of background plates: photos of the empty scene taken by "
                  "the fixed cameras, one or more per camera, each with the camera's name in "
                  "its file name (cam01.png, cam01_2.jpg for cam01) or in a subfolder named "
                  "like the camera; at the video's size or the calibrated size the video was "
                  "scaled from. With --plates clean they are the background model: the mean "
                  "and spread of a camera's photos (one photo: its colours, with a spread "
                  "from its measured noise and half a pixel of misalignment at edges)"},
    )  # fmt: skip
    background_video: Path | None = field(
        default=None,
        metadata={"metavar": "DIR",
                  "help": "folder of background clips: a video of the empty scene per "
                  "camera, named like the camera's video (cam01.mp4, or a subfolder cam01/); "
                  "the background model is the median and spread of --background-samples "
                  "frames spread over it (its mean and spread when it is clean, and still the "
                  "empty scene when someone walked through it)"},
    )  # fmt: skip
    plates: Plates = field(
        default=Plates.CLEAN,
        metadata={"help": "'clean': the plates show only the empty scene and are the "
                  "background model, each frame's exposure matched to them; 'cluttered': "
                  "the photos may show people or objects the video does not (the Pose2Sim "
                  "demo's calibration shots): the temporal median stays the model and a photo "
                  "fills in only where the subject moved and the video confirms it"},
    )  # fmt: skip
    median_fallback: bool = field(
        default=False,
        metadata={"help": "with plates, a camera that has none uses the temporal median of "
                  "its video (default: refuse, naming the camera)"},
    )  # fmt: skip
    logged_frames: int = field(
        default=5,
        metadata={"help": "frames per camera logged with their masks to logs/silhouettes.rrd"},
    )
    thresholds: SilhouetteConfig = field(
        default_factory=SilhouetteConfig,
        metadata={"help": "classification thresholds and clean-up (SilhouetteConfig flags)"},
    )
    hull: HullCheckConfig = field(
        default_factory=HullCheckConfig,
        metadata={"help": "multi-view consistency of the silhouettes (HullCheckConfig flags)"},
    )
    coherence: CoherenceConfig = field(
        default_factory=CoherenceConfig,
        metadata={"help": "the cameras' correction by silhouette coherence (CoherenceConfig "
                  "flags)"},
    )  # fmt: skip

    def __post_init__(self) -> None:
        if _BACKGROUND_FORMAT.match(self.background) is None:
            raise UserError(f"--background {self.background!r}: expected 'median' or "
                            "'frames:A-B' (for example frames:0-29)")
        span = self.background_frames
        if span is not None and span[0] > span[1]:
            raise UserError(f"--background {self.background}: A must not exceed B")
        for name, low in (("background_samples", 1), ("background_passes", 1), ("first", 0),
                          ("frame_step", 1),
                          ("logged_frames", 0)):
            if getattr(self, name) < low:
                raise UserError(f"--{name.replace('_', '-')} must be >= {low}, "
                                f"got {getattr(self, name)}")
        if self.last is not None and self.last < self.first:
            raise UserError(f"--last {self.last} is before --first {self.first}")
        try:
            object.__setattr__(self, "plates", Plates(self.plates))
        except ValueError:
            raise UserError(f"--plates {self.plates!r}: expected "
                            f"{' or '.join(p.value for p in Plates)}") from None
        if self.background_images is not None and self.background_video is not None:
            raise UserError("give --background-images or --background-video, not both")
        if self.plate_flag is not None and self.background_frames is not None:
            raise UserError(f"{self.plate_flag} is the background; with --background "
                            f"{self.background} the empty scene is in the video: give one")
        if self.plates == "cluttered" and self.background_video is not None:
            raise UserError("--plates cluttered takes --background-images (photos that may "
                            "show what the video does not), not --background-video")

    @property
    def plate_folder(self) -> Path | None:
        """The folder of the background plates (photos or clips), None without."""
        return self.background_images if self.background_images is not None \
            else self.background_video

    @property
    def plate_flag(self) -> str | None:
        """``--background-images`` or ``--background-video``, whichever is given."""
        if self.background_images is not None:
            return "--background-images"
        return "--background-video" if self.background_video is not None else None

    @property
    def plates_are_model(self) -> bool:
        """Whether clean plates are the background model (else the median, or frames A-B)."""
        return self.plate_folder is not None and self.plates == "clean"

    @property
    def background_frames(self) -> tuple[int, int] | None:
        """(A, B) of ``frames:A-B``, None for the median."""
        found = _BACKGROUND_FORMAT.match(self.background)
        if found is None or found.group(2) is None:
            return None
        return int(found.group(2)), int(found.group(3))


def background_sample(count: int, config: SilhouettesConfig) -> list[int]:
    """Indexes (0-based, increasing) of the frames of a `count`-frame video that the background
    model is built from: with ``--background median`` an odd number, ``background_samples``
    rounded up, spread evenly over the whole video; with ``frames:A-B`` up to
    ``background_samples`` spread over A-B (which must lie in the video). They are decoded
    and held in memory at once."""
    span = config.background_frames
    if span is None:
        return _spread(count, config.background_samples, odd=True)
    if span[1] > count - 1:
        raise UserError(f"--background {config.background}: the videos end at frame "
                        f"{count - 1}")
    return [span[0] + i for i in
            _spread(span[1] - span[0] + 1, config.background_samples, odd=False)]


def background_model(frames: list[np.ndarray], config: SilhouettesConfig) -> BackgroundModel:
    """The background model of one camera from its `background_sample` frames, each (H, W, 3)
    uint8: their mean and standard deviation for ``frames:A-B`` (empty scene), else the temporal
    median and spread (`BackgroundModel.from_sequence` with ``background_passes`` passes and
    the step's classification ``thresholds``). Background photos are added to the latter
    apart (`with_background_photo`). The CDnet benchmark scores this very function."""
    if config.background_frames is not None:
        return BackgroundModel.from_frames(frames)
    return BackgroundModel.from_sequence(frames, config.thresholds,
                                         passes=config.background_passes)


_MIN_PHOTO_AGREEMENT = 0.3
"""Least fraction of the pixels away from the subject where a camera's background photo must
agree with its video's median (a photo from another camera or position agrees nearly nowhere;
the Pose2Sim demo's photos agree on 79-93%)."""


def with_background_photo(model: BackgroundModel, frames: list[np.ndarray], photo: np.ndarray,
                          thresholds: SilhouetteConfig | None = None,
                          ) -> tuple[BackgroundModel, np.ndarray, dict[str, Any]]:  # fmt: skip
    """The median background `model` of `frames` with a photo of the empty scene (H, W, 3)
    uint8 put in where the subject moved; the pixels whose background is unknown (H, W) bool;
    and what was done (``area``: fraction of the image taken from the photo; ``unknown``:
    fraction unknown; ``agreement``: fraction of the rest where the photo matches the median;
    ``gain``: per-channel factor applied to the photo).

    Where the subject stands in most frames the median *is* the subject (a person balancing on
    one spot: the torso and shorts). Where it moved is known: the union of its silhouettes
    against `model` over `frames`, closed over 3% of the image's larger side, grown by 1% and
    with its holes filled (what the subject always covers is enclosed by where it moved). There
    the photo, brought to the video's exposure by a per-channel gain measured where both
    agree, is the background, with no spread of its own (the classification's ``min_std``
    floor), wherever the video confirms it: the photo is background in one of the frames at
    least, or the pixel belongs to a patch of unconfirmed pixels enclosed by confirmed ones
    (what the subject never uncovers). A photo shot at another time may show people or
    objects the video does not: such a patch borders pixels where the photo always matches,
    and there the median stays, but where the subject moved neither is to be trusted: there
    the background is *unknown* (`UNKNOWN_NAME`): the multi-view check does not carve with
    those pixels, and the tracker leaves them out of its energy.
    """
    thresholds = thresholds or SilhouetteConfig()
    if photo.shape != model.shape:
        raise ValueError(f"photo is {photo.shape} but the background model is {model.shape}")
    h, w = photo.shape[:2]
    moved = np.zeros((h, w), np.uint8)
    for frame in frames:
        moved |= silhouette_from_frame(frame, model, thresholds).astype(np.uint8)
    size = max(h, w)
    region = cv2.morphologyEx(moved, cv2.MORPH_CLOSE, disc(_odd(0.03 * size)))
    region = cv2.dilate(region, disc(_odd(0.01 * size)))
    region = fill_holes(region, h * w).astype(bool)
    picture = photo.astype(np.float32)
    std = np.maximum(model.std, np.float32(thresholds.min_std))
    agree = (np.abs(picture - model.mean) < thresholds.lower_sigma * std).all(axis=2) & ~region
    agreement = float(agree.sum() / max(1, (~region).sum()))
    if agreement < _MIN_PHOTO_AGREEMENT:
        return model, np.zeros((h, w), bool), {"area": 0.0, "unknown": 0.0,
                                               "agreement": agreement, "gain": None}
    gain = [float(np.median(model.mean[..., c][agree] / np.maximum(picture[..., c][agree], 1.0)))
            for c in range(picture.shape[2])]  # fmt: skip
    picture *= np.asarray(gain, np.float32)
    # How often each pixel shows the photo's background (within the lower threshold).
    shown = np.zeros((h, w), np.float32)
    tolerance = thresholds.lower_sigma * thresholds.min_std
    for frame in frames:
        shown += (np.abs(frame.astype(np.float32) - picture) < tolerance).all(axis=2)
    shown /= len(frames)
    use = region & (shown > 0)
    use |= region & _enclosed(shown == 0, shown, round(0.01 * size), within=region)
    unknown = region & ~use
    inside = use[..., None]
    combined = BackgroundModel(np.where(inside, picture, model.mean),
                               np.where(inside, np.float32(0), model.std))
    return combined, unknown, {"area": float(use.mean()), "unknown": float(unknown.mean()),
                               "agreement": agreement, "gain": gain}


_ENCLOSED_MAX_STATIC = 0.15
"""A patch of pixels where the photo is never background counts as the subject's hidden core
when at most this fraction of its rim shows the photo's background nearly always (90% of the
frames); foreign objects in the Pose2Sim photos have 22-34% of their rim static."""


def _enclosed(unconfirmed: np.ndarray, shown: np.ndarray, rim_px: int, within: np.ndarray
              ) -> np.ndarray:  # fmt: skip
    """The patches of `unconfirmed` (H, W) bool that meet `within` and whose rim (`rim_px`
    wide) is at most `_ENCLOSED_MAX_STATIC` static (the photo shown in 90% of the frames or
    more)."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(unconfirmed.astype(np.uint8),
                                                               connectivity=8)
    keep = np.zeros(count, bool)
    ring = disc(_odd(2 * rim_px + 1))
    for k in np.unique(labels[within & unconfirmed]):
        x, y, cw, ch = stats[k, :4]
        x0, y0 = max(0, x - rim_px - 1), max(0, y - rim_px - 1)
        x1 = min(unconfirmed.shape[1], x + cw + rim_px + 1)
        y1 = min(unconfirmed.shape[0], y + ch + rim_px + 1)
        patch = (labels[y0:y1, x0:x1] == k).astype(np.uint8)
        rim = cv2.dilate(patch, ring).astype(bool) & ~patch.astype(bool)
        if rim.any():
            keep[k] = (shown[y0:y1, x0:x1][rim] >= 0.9).mean() <= _ENCLOSED_MAX_STATIC
    return keep[labels]


def _odd(length: float) -> int:
    """An odd structuring-element diameter of at least 3 pixels near `length`."""
    return max(3, round(length) | 1)


def background_plates(config: SilhouettesConfig, cameras: Sequence[Camera]
                      ) -> dict[str, list[Path]]:  # fmt: skip
    """Camera name -> its plates (``config.background_images`` photos, or
    ``config.background_video`` clips), sorted: the files whose name contains the camera's
    name as a word, case and separators ignored like the videos' names (``cam01_ext.png``
    for cam01 or cam_01, not for cam010), and every such file in a subfolder named like the
    camera. Files of other types and hidden ones are left alone. One-line errors: a missing
    folder, no plate at all, a plate or subfolder that names no camera or two, and a camera
    without a plate while others have one (unless ``median_fallback``: it is left out)."""
    folder, flag = config.plate_folder, config.plate_flag
    if folder is None or flag is None:
        return {}
    suffixes = IMAGE_SUFFIXES if config.background_images is not None else VIDEO_SUFFIXES
    what = "images" if config.background_images is not None else "videos"
    if not folder.is_dir():
        raise UserError(f"{flag} {folder}: no such folder")
    names = ", ".join(c.name for c in cameras)
    found: dict[str, list[Path]] = {}
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith("."):
            continue
        if entry.is_dir():
            owners = [c for c in cameras if name_in_file_name(c.name).fullmatch(entry.name.lower())]
            files = sorted(p for p in entry.iterdir() if p.is_file()
                           and not p.name.startswith(".") and p.suffix.lower() in suffixes)
        elif entry.suffix.lower() in suffixes:
            owners = [c for c in cameras if name_in_file_name(c.name).search(entry.stem.lower())]
            files = [entry]
        else:
            continue
        if entry.is_dir() and not files:
            continue
        if len(owners) != 1:
            which = ("names no camera" if not owners else
                     f"names {len(owners)} cameras ({', '.join(c.name for c in owners)})")
            raise UserError(f"{flag}: {entry} {which}; name each plate after its camera "
                            f"({names}) or put it in a folder named like it")
        found.setdefault(owners[0].name, []).extend(files)
    if not found:
        raise UserError(f"{flag} {folder}: no {what} ({', '.join(suffixes)}) that name a "
                        f"camera ({names})")
    missing = [c.name for c in cameras if c.name not in found]
    if missing and not config.median_fallback:
        raise UserError(f"{flag} {folder}: no plate for camera(s) {', '.join(missing)} while "
                        "the others have one; add theirs, or give --median-fallback to use "
                        "the temporal median of their video")
    return {name: sorted(paths) for name, paths in found.items()}


def read_background_image(path: Path, camera: Camera) -> np.ndarray:
    """A photo (H, W, 3) uint8 at the camera's video size (`plate_at_video_size`)."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise UserError(f"cannot read background image {path}")
    return plate_at_video_size(image, camera, path)


def plate_at_video_size(image: np.ndarray, camera: Camera, path: Path) -> np.ndarray:
    """A plate (photo or clip frame, (h, w, 3) uint8) at the camera's video size: as it is,
    or, when it has the size the video was scaled from (`tracking.rig.video` letterboxed
    videos), scaled by the same factor and centred between black bars; any other size is a
    one-line error that names ``path``."""
    h, w = image.shape[:2]
    if (h, w) == (camera.height, camera.width):
        return image
    s = min(camera.width / w, camera.height / h)
    if abs(s - 1.0) > 0.1:
        raise UserError(f"background plate {path.name} is {w}x{h}, camera {camera.name}'s "
                        f"video {camera.width}x{camera.height}")
    pad_x, pad_y = (camera.width - s * w) / 2, (camera.height - s * h) / 2
    # Pixel centres at +0.5 on both sides: x_video = s * x_photo + pad, in OpenCV's integer
    # centres x' = s * x + (s / 2 + pad - 1 / 2).
    warp = np.float32([[s, 0, s / 2 + pad_x - 0.5], [0, s, s / 2 + pad_y - 0.5]])
    return cv2.warpAffine(image, warp, (camera.width, camera.height), flags=cv2.INTER_LINEAR)


def plate_model(paths: Sequence[Path], camera: Camera, config: SilhouettesConfig, *,
                video: bool) -> tuple[BackgroundModel, dict[str, Any]]:  # fmt: skip
    """The background model of one camera's clean plates and how it was made (``model``,
    ``frames``, and for one photo its ``noise_sigma`` per channel), each plate at the video's
    size (`plate_at_video_size`):

    * photos (``video`` False): two or more, their mean and standard deviation
      (`BackgroundModel.from_frames`); one, `BackgroundModel.from_photo`;
    * clips: ``background_samples`` frames (rounded up to odd) spread over all of the
      camera's clips, their temporal median and spread with ``background_passes`` passes
      (`BackgroundModel.from_sequence`, as the median background): the mean and standard
      deviation of a clean clip, and still the empty scene when someone walked through it
      (on CDnet highway, a clip of the 469 frames before the scored range, cars passing in
      all of them: F 0.335 with the mean and spread of every frame).
    """
    if not video:
        photos = [read_background_image(p, camera) for p in paths]
        if len(photos) == 1:
            model = BackgroundModel.from_photo(photos[0])
            sigma = [round(float(v), 2) for v in noise_sigma(photos[0])]
            return model, {"model": "one photo: spread from its noise and "
                           f"{PHOTO_MISALIGNMENT_PX} px of misalignment", "frames": 1,
                           "noise_sigma": sigma}
        return BackgroundModel.from_frames(photos), {
            "model": f"mean and spread of {len(photos)} photos", "frames": len(photos)}
    counts = [video_info(path)[0] for path in paths]
    starts = np.cumsum([0, *counts])
    picked = _spread(int(starts[-1]), config.background_samples, odd=True)
    frames = []
    for k, path in enumerate(paths):
        local = [i - int(starts[k]) for i in picked if starts[k] <= i < starts[k + 1]]
        frames += [plate_at_video_size(frame, camera, path)
                   for _, frame in read_video_frames(path, local)]
    model = BackgroundModel.from_sequence(frames, config.thresholds,
                                          passes=config.background_passes)
    clips = f"{len(paths)} clips" if len(paths) > 1 else "its clip"
    return model, {"model": f"median and spread of {len(frames)} frames spread over {clips} "
                   f"({int(starts[-1])} frames)", "frames": len(frames)}


_PLATE_CHECK_FRAMES = 5
"""Processed frames, spread over the sequence, that each camera's plates are checked on."""
_PLATE_MAX_FOREGROUND = 0.5
"""A plate that leaves more than this fraction of the image foreground in every checked frame
is refused: another camera's plate, a camera that moved, or a plate that shows the subject."""


HELD_GROUP = 0.03
"""Silhouette components closer than this fraction of the image's larger side are one
subject's in `held_by_median` (`component_hulls`)."""
HELD_SHARE = 0.25
"""A camera's temporal median is taken to hold the subject when the pixels that its
silhouettes span in at least half of their frames come to this share of its median silhouette
or more (`held_by_median`). Measured with the step's silhouettes (components grouped within
3% / 6% of the larger side): the synthetic walk of benchmarks/silhouettes_kinds.py 3.1-3.4 /
4.5-4.6 in the two cameras it walks towards and away from, 0.00 in the two it crosses, 0.00 in
all four when it walks diagonally; the same towards / away from 2 cameras at 320x240
(tests/tracking/silhouettes/test_kinds.py) 1.7-2.6 / 2.7-3.8; the Pose2Sim demo (a person
keeping to a mat, no plate) 2.5-2.8 / 3.0-4.2; CDnet highway's traffic 0.10 / 0.19."""


def held_by_median(covered: np.ndarray, fractions: Sequence[float]) -> np.ndarray | None:
    """(H, W) bool: the pixels of a camera whose temporal median background cannot be trusted,
    or None. The median shows the subject wherever it stood in most of the frames (walking
    towards or away from the camera, keeping to one spot), and the silhouettes miss it there.
    Found from the silhouettes themselves (``covered``, `_FramesResult.covered`: per pixel, the
    frames whose silhouette, the convex hulls of its components grouped within
    `HELD_GROUP`, spans it): the pixels spanned in at least half of the frames with a silhouette
    (the median's breaking point) must come to `HELD_SHARE` of the median silhouette's area
    (``fractions``: per frame, the silhouette's fraction of the image). Those pixels
    underestimate the harm, since the silhouettes they come from miss the subject (in the
    synthetic walk towards a camera at 320x240, 22-31% of what the silhouettes miss lies in
    them): what is returned is everywhere the silhouettes went, grown by 1% of the image's
    larger side (96-100% of it)."""
    shown = [f for f in fractions if f > 0]
    if not shown:
        return None
    h, w = covered.shape
    held_px = np.count_nonzero(covered >= 0.5 * len(shown))
    if held_px < HELD_SHARE * float(np.median(shown)) * h * w:
        return None
    margin = max(3, round(0.01 * max(h, w)))
    return cv2.dilate((covered > 0).astype(np.uint8), np.ones((margin, margin), np.uint8)) > 0


def _with_held(result: _CameraResult) -> _CameraResult:
    """``result`` with the pixels where its median holds the subject (`held_by_median`)
    added to its unknown background."""
    covered = result.masks.covered
    held = None if covered is None else held_by_median(covered, result.masks.fractions)
    if held is None:
        return result
    known = result.background.unknown
    background = dataclasses.replace(result.background,
                                     unknown=held if known is None else known | held)
    return dataclasses.replace(result, background=background, held=float(held.mean()))


def _spread(count: int, samples: int, *, odd: bool) -> list[int]:
    """Up to ``samples`` frame indexes spread evenly over 0..count-1; with ``odd`` an odd
    number of them (``samples`` rounded up, ``count`` down), as the median needs."""
    k = min(samples, count)
    if odd:
        k = min(samples + (samples % 2 == 0), count - (count % 2 == 0))
    # floor(x + 0.5), not round(): banker's rounding could merge neighbours 1 apart.
    return sorted({int(np.floor(x + 0.5)) for x in np.linspace(0, count - 1, max(k, 1))})


def _ranges(frames: list[int], step: int) -> str:
    """'0-4, 9, 12-20' for processed frames (consecutive when ``step`` apart)."""
    parts: list[str] = []
    start = prev = None
    for f in frames:
        if start is None:
            start = prev = f
        elif f == prev + step:
            prev = f
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = f
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    return ", ".join(parts)


def _touches_border(mask: np.ndarray, box: tuple[int, int, int, int]) -> bool:
    x0, y0, x1, y1 = box
    inner = mask[y0:y1, x0:x1]
    return bool(inner[0].any() or inner[-1].any() or inner[:, 0].any() or inner[:, -1].any())


def _upstream_fingerprint(ws: Workspace, cameras: list[Camera]) -> str:
    record = ws.step(INIT_STEP)
    if record is not None:
        return record.fingerprint
    # A workspace not made by init-video: its cameras and the videos' identities.
    videos = {}
    for camera in cameras:
        stat = video_path(ws, camera.name).stat()
        videos[camera.name] = [stat.st_size, stat.st_mtime_ns]
    return fingerprint(ws.cameras_path.read_text(), videos)


def make_silhouettes(ws: Workspace, config: SilhouettesConfig, *, overwrite: bool = False
                     ) -> StepRecord:  # fmt: skip
    """Silhouettes of every camera's processed frames in ``WS/silhouettes`` (module docstring);
    reused when the config and the videos are unchanged, unless ``overwrite``."""
    from recon import recording

    ws = Workspace.open_video(ws.root)
    cameras = workspace_cameras(ws)
    counts = {c.name: video_info(video_path(ws, c.name)) for c in cameras}
    n_frames = min(info[0] for info in counts.values())
    if any(info[0] != n_frames for info in counts.values()):
        listed = ", ".join(f"{name} {info[0]}" for name, info in counts.items())
        raise UserError(f"the workspace's videos have different frame counts ({listed})")
    last = n_frames - 1 if config.last is None else config.last
    if config.first > n_frames - 1 or last > n_frames - 1:
        bad = "--first" if config.first > n_frames - 1 else "--last"
        raise UserError(f"{bad} {config.first if bad == '--first' else last} is past the last "
                        f"frame {n_frames - 1} of the videos")
    frames = list(range(config.first, last + 1, config.frame_step))
    span = config.background_frames
    background_frames = background_sample(n_frames, config)
    plates = background_plates(config, cameras)
    if config.plates_are_model:
        kind = "photos" if config.background_images is not None else "clips"
        background_text = (f"clean plates ({kind} of the empty scene) in {config.plate_folder}:"
                           " each camera's own, every frame's exposure matched to them")
        if len(plates) < len(cameras):
            background_text += (f"; temporal median of {len(background_frames)} frames for "
                                "the cameras without")
    elif span is not None:
        background_text = (f"mean and spread of {len(background_frames)} empty-scene frames "
                           f"in {span[0]}-{span[1]}")
    else:
        background_text = (f"temporal median of {len(background_frames)} frames spread over "
                           f"0-{n_frames - 1}")
    settings = {**dataclasses.asdict(config), "last": last}
    fp = fingerprint(STEP, settings, _upstream_fingerprint(ws, cameras),
                     {name: [file_digest(path) for path in paths]
                      for name, paths in plates.items()})
    outputs = [*(ws.silhouettes_dir / c.name for c in cameras),
               ws.silhouettes_dir / CAMERAS_NAME]
    if done := ws.reusable(STEP, fp, *outputs, overwrite=overwrite):
        return dataclasses.replace(done, summary={**done.summary, "up_to_date": True})

    fps = {name: info[3] for name, info in counts.items()}
    logged = ({frames[i] for i in _spread(len(frames), config.logged_frames, odd=False)}
              if config.logged_frames else set())
    check = config.hull.multi_view_check and len(cameras) >= 2
    per_camera: dict[str, dict[str, Any]] = {}
    warnings: list[str] = []
    map_cameras = _camera_map.get()
    units = len(frames) * (len(cameras) + check)
    with (Timer() as timer, bar(units, "silhouettes", "frame") as progress,
          atomic_output(ws.silhouettes_dir) as tmp,
          recording.step_recording(ws.log_path(STEP), STEP) as rec):
        tmp.mkdir()
        recording.log_silhouette_context(rec, "world/cameras")
        jobs = [_CameraJob(root=ws.root.resolve(), camera=camera, frames=frames,
                           background_frames=background_frames, config=config,
                           out=tmp.resolve() / camera.name,
                           plates=tuple(plates.get(camera.name, ())))
                for camera in cameras]
        if map_cameras is not None:
            done = _silhouettes_as_tasks(map_cameras, jobs)
            progress.update(len(frames) * len(cameras))
        else:  # one camera after the other in this process
            done = [camera_silhouettes(job, progress) for job in jobs]
        done = [_with_held(result) for result in done]
        refined = None
        if config.coherence.refine_cameras and len(cameras) >= 2 and len(frames) >= 2:
            progress.set_postfix_str("camera correction")
            refined = _refined_rig(ws, cameras, [job.out for job in jobs], frames, done,
                                   config.coherence)  # fmt: skip
            used = refined.cameras
        else:
            used = cameras
        write_cameras_json(tmp / CAMERAS_NAME, used)
        if check:
            progress.set_postfix_str("multi-view check")
            done = _checked_by_hull(map_cameras, _HullJob(
                root=ws.root.resolve(), cameras=used, outs=[job.out for job in jobs],
                frames=frames, config=config.hull), done, progress)
        for camera, result in zip(used, done, strict=True):  # the recording shows the cameras used
            if result.background.unknown is not None:
                _write_mask(tmp / camera.name / UNKNOWN_NAME, result.background.unknown)
            _log_camera(rec, ws, camera, result, tmp / camera.name, sorted(logged), frames,
                        fps[camera.name])
            fractions, empty, border = (result.masks.fractions, result.masks.empty,
                                        result.masks.border)
            per_camera[camera.name] = {
                "frames": len(fractions),
                "foreground_fraction": {"min": min(fractions), "median":
                                        float(np.median(fractions)), "max": max(fractions)},
                "empty_frames": empty, "border_frames": border}
            if result.held:
                per_camera[camera.name]["median_holds_subject"] = result.held
                warnings.append(
                    f"{camera.name}: the subject stood on the same pixels in most frames "
                    "(walking towards or away from the camera, or keeping to one spot), so the "
                    "temporal median shows it and the silhouettes miss it; where it went "
                    f"({result.held:.1%} of the image) is marked unknown ({UNKNOWN_NAME}: the "
                    "multi-view check and the tracker leave it out); give plates of the "
                    "empty scene (--background-images or --background-video) or its frames "
                    "(--background frames:A-B)")
            if result.removed is not None:
                per_camera[camera.name]["hull_removed"] = {
                    "median": float(np.median(result.removed)), "max": max(result.removed)}
            photo = result.background.photo
            if result.background.plate is not None:
                per_camera[camera.name]["plate"] = result.background.plate
            if result.masks.gains:
                per_camera[camera.name]["exposure_gain"] = {
                    "min": min(result.masks.gains), "max": max(result.masks.gains)}
            if photo is not None:
                per_camera[camera.name]["background_image"] = photo
                if photo["gain"] is None:
                    warnings.append(
                        f"{camera.name}: background image {photo['image']} agrees with the "
                        f"video on only {photo['agreement']:.0%} of the pixels away from the "
                        "subject (another camera's, or the camera moved?): not used")
            elif plates and camera.name not in plates:
                warnings.append(f"{camera.name}: no plate in {config.plate_folder}: the "
                                "temporal median of its video (--median-fallback)")
            warnings.extend(_warnings(camera.name, empty, border, len(fractions),
                                      config.frame_step,
                                      span is None and not result.background.plate,
                                      plate=result.background.plate is not None))
        recording.log_table(rec, "silhouettes/summary", "Foreground fraction per camera", [
            {"camera": name, "min": s["foreground_fraction"]["min"],
             "median": s["foreground_fraction"]["median"], "max": s["foreground_fraction"]["max"],
             "empty": len(s["empty_frames"]), "at border": len(s["border_frames"])}
            for name, s in per_camera.items()])
    if plates and not config.plates_are_model:
        background_text += (f", with the photos of {config.background_images} where the "
                            "subject moved (--plates cluttered)")
    summary = {"cameras": per_camera, "frames": [config.first, last, config.frame_step],
               "processed": len(frames), "background": background_text,
               "background_frames": background_frames, "multi_view_check": check,
               "warnings": warnings,
               **({"camera_correction": refined.summary()} if refined is not None else {})}
    return ws.record_step(STEP, fp, outputs=outputs, config=settings, seconds=timer.seconds,
                          summary=summary)


def tracked_cameras(ws: Workspace) -> list[Camera]:
    """The cameras that go with the workspace's silhouettes: ``silhouettes/cameras.json``, as
    `mocap silhouettes` corrected them (or kept them), else the calibrated ``cameras.json``
    (silhouettes `mocap synth` drew with exact cameras); `UserError` when unreadable."""
    from tracking.rig.cameras import read_cameras

    path = ws.silhouettes_dir / CAMERAS_NAME
    path = path if path.is_file() else ws.cameras_path
    try:
        return read_cameras(path)
    except ValueError as exc:
        raise UserError(f"{path}: {exc}") from None


def _refined_rig(ws: Workspace, cameras: list[Camera], outs: list[Path], frames: list[int],
                 done: list[_CameraResult], config: CoherenceConfig,
                 ) -> CoherenceResult:  # fmt: skip
    """`tracking.silhouettes.coherence.refine_rig` on ``config.coherence_frames`` of the
    processed frames spread over them, their masks read from ``outs``, before the multi-view
    check, which then runs with the corrected cameras. Checked first with the calibrated
    cameras, the masks are trimmed to fit them wherever the error exceeds the check's
    tolerance: on the ball rig (tolerance 3 px) a camera 5 px off was found 2 px off; on the
    Pose2Sim demo (tolerance 19 px) both orders give the same correction within 3 px and the
    same coherence (1 cm hull: median IoU 0.903 and 0.902)."""
    picked = sorted({frames[i] for i in np.linspace(0, len(frames) - 1,
                                                    config.coherence_frames).round().astype(int)})
    masks = [[cv2.imread(str(out / f"{frame:06d}.png"), cv2.IMREAD_GRAYSCALE) > 127
              for out in outs] for frame in picked]  # fmt: skip
    return refine_rig(cameras, masks, [r.background.unknown for r in done], config,
                      [content_box(ws, camera) for camera in cameras])


def _log_camera(rec: Any, ws: Workspace, camera: Camera, result: _CameraResult, masks: Path,
                logged: list[int], frames: list[int], fps: float) -> None:  # fmt: skip
    """One camera's part of the recording: the camera, its background (and its pixels of
    unknown background), the logged frames with their final masks, and the foreground
    fraction over frames."""
    from recon import recording

    entity = f"world/cameras/{recording.entity_name(camera.name)}"
    recording.log_camera_image(rec, image_name=camera.name, image_path=None, K=camera.K,
                               width=camera.width, height=camera.height,
                               cam_from_world=camera.cam_from_world)
    recording.log_frame_image(rec, f"backgrounds/{recording.entity_name(camera.name)}",
                              np.clip(result.background.model.mean, 0, 255).astype(np.uint8))
    if result.background.unknown is not None:
        recording.log_frame_image(rec, f"backgrounds/{recording.entity_name(camera.name)}"
                                  "/unknown", result.background.unknown.astype(np.uint8) * 255)
    for index, frame in read_frames(ws, camera.name, logged):
        time_s = index / fps if fps else None
        mask = cv2.imread(str(masks / f"{index:06d}.png"), cv2.IMREAD_GRAYSCALE) > 127
        recording.log_frame_image(rec, f"{entity}/image", frame, index, time_s)
        recording.log_silhouette(rec, f"{entity}/image/silhouette", mask, index, time_s or 0.0)
    rate = fps or 1.0
    recording.log_frame_series(rec, f"silhouettes/{recording.entity_name(camera.name)}"
                               "/foreground_fraction", np.asarray(frames),
                               np.asarray(frames) / rate, np.asarray(result.masks.fractions))


CameraMap = Callable[..., list[Any]]
"""``map_fn(fn, items, *shared)`` returning ``[fn(item, *shared) for item in items]`` in input
order, however it runs them (:func:`recon.batch.map_ordered` runs them as Dask tasks, ``shared``
sent once rather than with every task)."""

# Unset (None) in a plain run: the cameras are processed one after another in this process.
_camera_map: contextvars.ContextVar[CameraMap | None] = contextvars.ContextVar(
    "silhouette_camera_map", default=None)

FRAME_CHUNK = 12
"""Processed frames of one camera per classification task under `mocap batch`, at most unless a
long sequence needs longer runs (:func:`frame_chunks`): 1088x1920 frames take ~75 ms each to
classify, so a task is about a second."""
_REDECODED_PER_FRAME = 4
"""Budget of :func:`frame_chunks`: video frames decoded again, over all of a camera's tasks, per
processed frame. A task reads its frames with :func:`tracking.rig.video.read_frames`, which decodes
(without converting) every frame before its first one: exact whatever the video's timestamps,
where seeking trusts them. Such a frame costs ~3 ms against ~80 ms to decode, convert and
classify a processed one (H.264 1088x1920, the Pose2Sim demo, one thread), so the budget bounds
the extra work at about 15% however long the sequence."""


@contextlib.contextmanager
def cameras_mapped_by(map_fn: CameraMap) -> Iterator[None]:
    """Within this block, :func:`make_silhouettes` hands its work to ``map_fn`` in two fan-outs:
    the background model of each camera (:func:`camera_background`, a task per camera), then the
    classification of each camera's frames in consecutive runs (:func:`frame_silhouettes`, a
    task per run of :func:`frame_chunks`, every camera's runs in one fan-out), each writing its
    masks into the partial folder, with the cameras' models as ``map_fn``'s shared argument.

    Like :func:`recon.dense.backends.stereo_pairs_mapped_by`: how the work is scheduled changes no
    output; the results are merged in camera and frame order, as a plain run makes them, and
    the masks still replace ``silhouettes/`` only when every task is done.
    """
    token = _camera_map.set(map_fn)
    try:
        yield
    finally:
        _camera_map.reset(token)


def frame_chunks(frames: list[int]) -> list[list[int]]:
    """``frames`` (one camera's processed frame indexes, increasing) split into consecutive runs
    of at most :data:`FRAME_CHUNK`, as even as can be; fewer, longer runs when so many would
    decode the video's early frames again too often (:data:`_REDECODED_PER_FRAME`): a run
    starting at frame s decodes the s frames before it, so n runs decode about (n - 1) / 2 times
    the video up to the last processed frame more than a single run does."""
    if not frames:
        return []
    count = -(-len(frames) // FRAME_CHUNK)
    affordable = 1 + 2 * _REDECODED_PER_FRAME * len(frames) // (frames[-1] + 1)
    count = max(1, min(count, affordable))
    bounds = [len(frames) * k // count for k in range(count + 1)]
    return [frames[a:b] for a, b in itertools.pairwise(bounds)]


@dataclass(frozen=True)
class _CameraJob:
    """One camera's share of :func:`make_silhouettes`; small and picklable."""

    root: Path
    camera: Camera
    frames: list[int]
    background_frames: list[int]
    config: SilhouettesConfig
    out: Path
    plates: tuple[Path, ...] = ()
    """The camera's background plates (`background_plates`), none without."""

    def frames_job(self, frames: list[int], model: int = 0) -> _FramesJob:
        """The classification of ``frames`` (some of ``self.frames``) against the ``model``-th
        of the background models given with it."""
        return _FramesJob(root=self.root, camera=self.camera, frames=frames,
                          thresholds=self.thresholds, out=self.out, model=model,
                          exposure=self.uses_plates, coverage=self.uses_median)

    @property
    def uses_plates(self) -> bool:
        """Whether this camera's background is its clean plates."""
        return bool(self.plates) and self.config.plates_are_model

    @property
    def uses_median(self) -> bool:
        """Whether this camera's background is the temporal median of its video alone."""
        return not self.plates and self.config.background_frames is None

    @property
    def thresholds(self) -> SilhouetteConfig:
        """The classification settings of this camera's frames: the config's, with the
        outline refined against clean plates unless ``edge_band_px`` says otherwise."""
        thresholds = self.config.thresholds
        if thresholds.edge_band_px is None:
            thresholds = dataclasses.replace(thresholds, edge_band_px=int(self.uses_plates))
        return thresholds


@dataclass(frozen=True)
class _FramesJob:
    """Some of one camera's processed frames to classify (all of them in a plain run, one run
    of :func:`frame_chunks` under `mocap batch`); small and picklable."""

    root: Path
    camera: Camera
    frames: list[int]
    thresholds: SilhouetteConfig
    out: Path
    model: int
    """Which of the background models given with the job is this camera's."""
    exposure: bool = False
    """Match each frame's exposure to the background (a plate) before classifying it."""
    coverage: bool = False
    """Count, per pixel, the frames whose silhouette spans it (`_FramesResult.covered`)."""


@dataclass(frozen=True)
class _HullJob:
    """Some processed frames whose silhouettes, all cameras' at once, go through the
    multi-view check (:func:`frames_consistency`); small and picklable."""

    root: Path
    cameras: list[Camera]
    outs: list[Path]
    frames: list[int]
    config: HullCheckConfig


@dataclass(frozen=True)
class _Background:
    model: BackgroundModel
    photo: dict[str, Any] | None
    """:func:`with_background_photo`'s account, with the image's name; None without a photo."""
    unknown: np.ndarray | None = None
    """(H, W) bool: pixels whose background is unknown (:func:`with_background_photo`)."""
    plate: dict[str, Any] | None = None
    """How the clean plates made the model (:func:`plate_model`, with the files' names)."""


@dataclass(frozen=True)
class _FramesResult:
    """Per processed frame of one camera, in order: the silhouette's fraction of the image;
    the frames whose silhouette is empty, and those where it touches the image border."""

    fractions: list[float]
    empty: list[int]
    border: list[int]
    gains: list[float] = field(default_factory=list)
    """Per frame, the exposure gain matched to the plate (channel mean; empty: none)."""
    covered: np.ndarray | None = None
    """(H, W) int32: per pixel, the frames whose silhouette spans it (`component_hulls`);
    None when not counted (`_FramesJob.coverage`)."""

    @classmethod
    def joined(cls, parts: Sequence[_FramesResult]) -> _FramesResult:
        """The results of consecutive runs of frames as one."""
        covered = [p.covered for p in parts if p.covered is not None]
        return cls([f for p in parts for f in p.fractions], [i for p in parts for i in p.empty],
                   [i for p in parts for i in p.border], [g for p in parts for g in p.gains],
                   np.sum(covered, axis=0) if covered else None)


@dataclass(frozen=True)
class _CameraResult:
    background: _Background
    masks: _FramesResult
    """Statistics of the final masks."""
    removed: list[float] | None = None
    """Per frame, the fraction of the silhouette the multi-view check removed (None: no check)."""
    held: float = 0.0
    """Fraction of the image whose median background is unknown because the subject stood
    there in most frames (:func:`held_by_median`); 0 when not looked for or under the bar."""


def _stats(index: int, mask: np.ndarray, box: tuple[int, int, int, int], into: _FramesResult
           ) -> None:  # fmt: skip
    fraction = float(mask.mean())
    into.fractions.append(fraction)
    if fraction == 0.0:
        into.empty.append(index)
    elif _touches_border(mask, box):
        into.border.append(index)


def camera_silhouettes(job: _CameraJob, progress: Any = None) -> _CameraResult:
    """The masks of one camera's frames written to ``job.out``, all in this process: its
    background model, then its frames in order (what a plain `mocap silhouettes` runs)."""
    if progress is not None:
        progress.set_postfix_str(f"{job.camera.name}: background")
    background = camera_background(job)
    if progress is not None:
        progress.set_postfix_str(job.camera.name)
    job.out.mkdir()
    return _CameraResult(background, frame_silhouettes(job.frames_job(job.frames),
                                                       [background.model], progress))


def camera_background(job: _CameraJob) -> _Background:
    """The background model of one camera: one independent task."""
    ws = Workspace(job.root)
    if job.uses_plates:
        model, account = plate_model(job.plates, job.camera, job.config,
                                     video=job.config.background_video is not None)
        _check_plate(ws, job, model)
        return _Background(model, None, plate={"files": [p.name for p in job.plates], **account})
    frames = [_checked_size(ws, job.camera, frame)
              for _, frame in read_frames(ws, job.camera.name, job.background_frames)]
    model = background_model(frames, job.config)
    if not job.plates:
        return _Background(model, None)
    # --plates cluttered: a photo, the mean of the camera's photos, completes the median.
    photo = np.mean([read_background_image(p, job.camera) for p in job.plates], axis=0)
    model, unknown, account = with_background_photo(model, frames, photo.astype(np.uint8),
                                                    job.config.thresholds)
    return _Background(model, {"image": ", ".join(p.name for p in job.plates), **account},
                       unknown if unknown.any() else None)


def _checked_size(ws: Workspace, camera: Camera, frame: np.ndarray) -> np.ndarray:
    if frame.shape[:2] != (camera.height, camera.width):
        raise UserError(f"video {video_path(ws, camera.name).name} is "
                        f"{frame.shape[1]}x{frame.shape[0]} but cameras.json says "
                        f"{camera.width}x{camera.height} for camera {camera.name}")
    return frame


def _check_plate(ws: Workspace, job: _CameraJob, model: BackgroundModel) -> None:
    """A one-line error when the plates leave most of the image foreground in every one of a
    few processed frames spread over the sequence (`_PLATE_MAX_FOREGROUND`)."""
    x0, y0, x1, y1 = content_box(ws, job.camera)
    sample = [job.frames[i] for i in _spread(len(job.frames), _PLATE_CHECK_FRAMES, odd=False)]
    fractions = [float(_silhouette(_checked_size(ws, job.camera, frame), model,
                                   job.thresholds, exposure=True)[0][y0:y1, x0:x1].mean())
                 for _, frame in read_frames(ws, job.camera.name, sample)]  # fmt: skip
    if fractions and min(fractions) > _PLATE_MAX_FOREGROUND:
        names = ", ".join(p.name for p in job.plates[:3])
        raise UserError(f"camera {job.camera.name}: its plate ({names}) differs from its video "
                        f"on {min(fractions):.0%} of the image or more in each of "
                        f"{len(fractions)} frames spread over it (another camera's plate, a "
                        "camera that moved, or the subject in the plate?)")


def _silhouette(frame: np.ndarray, model: BackgroundModel, thresholds: SilhouetteConfig, *,
                exposure: bool) -> tuple[np.ndarray, float | None]:  # fmt: skip
    """A frame's silhouette, with its exposure first matched to the model's when ``exposure``
    (a plate); and that gain (channel mean), None without."""
    if not exposure:
        return silhouette_from_frame(frame, model, thresholds), None
    gain = exposure_gain(frame, model, thresholds)
    return (silhouette_from_frame(matched_exposure(frame, gain), model, thresholds),
            float(np.mean(gain)))


def frame_silhouettes(job: _FramesJob, models: Sequence[BackgroundModel], progress: Any = None
                      ) -> _FramesResult:  # fmt: skip
    """The masks of ``job.frames`` written to ``job.out`` (which exists), classified against
    ``models[job.model]``: one independent task."""
    ws = Workspace(job.root)
    model = models[job.model]
    box = content_box(ws, job.camera)
    result = _FramesResult([], [], [], covered=np.zeros(model.shape[:2], np.int32)
                           if job.coverage else None)  # fmt: skip
    group_px = _odd(HELD_GROUP * max(model.shape[:2]))
    for index, frame in read_frames(ws, job.camera.name, job.frames):
        mask, gain = _silhouette(frame, model, job.thresholds, exposure=job.exposure)
        if gain is not None:
            result.gains.append(gain)
        if result.covered is not None:
            np.add(result.covered, component_hulls(mask, group_px), out=result.covered)
        _write_mask(job.out / f"{index:06d}.png", mask)
        _stats(index, mask, box, result)
        if progress is not None:
            progress.update()
    return result


def frames_consistency(job: _HullJob, unknowns: Sequence[np.ndarray | None],
                       progress: Any = None) -> tuple[list[_FramesResult], list[list[float]]]:
    """The multi-view check (`tracking.silhouettes.hull`) of ``job.frames``: every camera's mask
    read from
    its folder and rewritten when the check changed it (`unknowns`: each camera's pixels of
    unknown background, which do not carve): one independent task. Per camera, the
    statistics of the final masks and the fraction of the silhouette removed per frame."""
    ws = Workspace(job.root)
    boxes = [content_box(ws, camera) for camera in job.cameras]
    results = [_FramesResult([], [], []) for _ in job.cameras]
    removed: list[list[float]] = [[] for _ in job.cameras]
    for index in job.frames:
        paths = [out / f"{index:06d}.png" for out in job.outs]
        masks = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) > 127 for p in paths]
        kept = consistent_silhouettes(job.cameras, masks, job.config, boxes, unknowns)
        for k, (path, mask, final) in enumerate(zip(paths, masks, kept, strict=True)):
            before = int(mask.sum())
            if not np.array_equal(final, mask):
                _write_mask(path, final)
            removed[k].append(float((mask & ~final).sum() / before) if before else 0.0)
            _stats(index, final, boxes[k], results[k])
        if progress is not None:
            progress.update()
    return results, removed


def _write_mask(path: Path, mask: np.ndarray) -> None:
    if not cv2.imwrite(str(path), mask.astype(np.uint8) * 255):
        raise UserError(f"could not write {path}")


def _silhouettes_as_tasks(map_fn: CameraMap, jobs: list[_CameraJob]) -> list[_CameraResult]:
    """:func:`camera_silhouettes` of every job, as the fan-outs of :func:`cameras_mapped_by`."""
    backgrounds = map_fn(camera_background, jobs)
    for job in jobs:
        job.out.mkdir()
    runs = [frame_chunks(job.frames) for job in jobs]
    results = iter(map_fn(frame_silhouettes, [
        job.frames_job(frames, model=k) for k, job in enumerate(jobs) for frames in runs[k]],
        tuple(b.model for b in backgrounds)))
    return [_CameraResult(b, _FramesResult.joined([next(results) for _ in camera_runs]))
            for b, camera_runs in zip(backgrounds, runs, strict=True)]


def _checked_by_hull(map_fn: CameraMap | None, job: _HullJob, done: list[_CameraResult],
                     progress: Any) -> list[_CameraResult]:  # fmt: skip
    """``done`` after the multi-view check of every processed frame: in this process, or as a
    task per run of frames (:func:`frame_chunks`) under `mocap batch`."""
    unknowns = tuple(result.background.unknown for result in done)
    if map_fn is None:
        parts = [frames_consistency(job, unknowns, progress)]
    else:
        parts = map_fn(frames_consistency, [dataclasses.replace(job, frames=run)
                                            for run in frame_chunks(job.frames)], unknowns)
        progress.update(len(job.frames))
    return [dataclasses.replace(
        result, masks=dataclasses.replace(_FramesResult.joined([p[0][k] for p in parts]),
                                          gains=result.masks.gains),
        removed=[r for p in parts for r in p[1][k]]) for k, result in enumerate(done)]


def _warnings(name: str, empty: list[int], border: list[int], processed: int, step: int,
              median: bool, *, plate: bool = False) -> list[str]:  # fmt: skip
    out = []
    if empty and len(empty) == processed:
        hint = (" with a median background a subject who hardly moves is background: give "
                "plates of the empty scene (--background-images or --background-video) or "
                "its frames (--background frames:A-B)" if median else "")
        out.append(f"{name}: every silhouette is empty (is the subject in view?{hint})")
    elif empty:
        out.append(f"{name}: empty silhouette in frame(s) {_ranges(empty, step)} (subject out "
                   "of view?)")
    if border and plate and len(border) == processed:
        # Clean plates that show what the video does not (the Pose2Sim demo's calibration
        # shots: people, a moved chair) leave it foreground in every frame, often at the edge.
        out.append(f"{name}: silhouette touches the image border in every frame (does the plate "
                   "show people or objects the video does not? then --plates cluttered)")
    elif border:
        out.append(f"{name}: silhouette touches the image border in frame(s) "
                   f"{_ranges(border, step)} (subject leaving the view?)")
    return out


def camera_correction_text(ws: Workspace, summary: dict[str, Any]) -> str | None:
    """What the step's summary says of the cameras' correction, in one line (None when the
    step did not try one)."""
    correction = summary.get("camera_correction")
    if correction is None:
        return None
    shifts = ", ".join(f"{name} ({dx:+.0f}, {dy:+.0f})"
                       for name, (dx, dy) in correction["shifts_px"].items())
    before, after = correction["coherence_checked"]
    return (f"{'corrected' if correction['accepted'] else 'kept as calibrated'} by silhouette "
            f"coherence: image shifts {shifts} px; coherence of the checking frames "
            f"{before:.3f} -> {after:.3f}"
            + ("" if correction["accepted"] else " (too little to apply)")
            + f"; {ws.silhouettes_dir / CAMERAS_NAME}")


def summary_lines(ws: Workspace, record: StepRecord) -> list[str]:
    """What `mocap silhouettes` prints: counts, per-camera fractions, warnings, paths."""
    s = record.summary
    first, last, step = s["frames"]
    every = f", every {step}th" if step > 1 else ""
    took = "up to date" if s.get("up_to_date") else f"{record.seconds:.1f} s"
    lines = [f"silhouettes  {len(s['cameras'])} cameras x {s['processed']} frames ({first}-{last}"
             f"{every}) in {ws.silhouettes_dir} ({took})",
             f"background   {s['background']}"]
    for name, cam in s["cameras"].items():
        f = cam["foreground_fraction"]
        line = (f"{name:<12} foreground {f['median']:.1%} of the image (median; min "
                f"{f['min']:.1%}, max {f['max']:.1%})")
        if "hull_removed" in cam:
            line += f"; the multi-view check removed {cam['hull_removed']['median']:.1%}"
        plate = cam.get("plate")
        if plate is not None:
            line += f"; plate: {plate['model']}"
            if "noise_sigma" in plate:
                line += f" ({'/'.join(f'{v:.1f}' for v in plate['noise_sigma'])} grey levels)"
        if "exposure_gain" in cam:
            gain = cam["exposure_gain"]
            line += f", exposure x{gain['min']:.2f}-{gain['max']:.2f} of it"
        if "median_holds_subject" in cam:
            line += (f"; the median holds the subject: {cam['median_holds_subject']:.1%} of "
                     "the image unknown")
        photo = cam.get("background_image")
        if photo is not None and photo["gain"] is not None:
            line += (f"; photo on {photo['area']:.1%} of the image, background unknown on "
                     f"{photo['unknown']:.1%}")
        lines.append(line)
    if (correction := camera_correction_text(ws, s)) is not None:
        lines.append(f"cameras      {correction}")
    lines += [f"warning      {w}" for w in s["warnings"]]
    lines.append(f"recording    {ws.logs_dir / f'{STEP}.rrd'}")
    return lines
