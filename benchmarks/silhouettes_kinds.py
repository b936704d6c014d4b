"""`mocap silhouettes` on synthetic recordings of the kinds users record, against the truth masks.

    .venv/bin/python benchmarks/silhouettes_kinds.py [--cameras 4] [--frames 50]
                                                     [--size 640x480] [--keep DIR]

Each kind is a `mocap synth --videos --clean` sequence (4 cameras on a ring, 640x480, MJPG
quality 95), made into a video workspace with `mocap init-video` and segmented by the step as a
user runs it (`mocap silhouettes CAP --overwrite` plus the background flags of the row, in its
own process; the time is that process' wall time, start-up and the multi-view check
included):

* still: a subject standing on the spot, frame 0 of cmu_131_01_start_walk_stop.bvh held for
  ``--frames`` frames at 30 Hz, swaying 1 cm side to side (root X, 4 s period). A seated
  subject would be the harder case, but cmu_sit_stand.bvh uses Daz joint names, which
  `mocap synth` does not read. With the photo of the empty scene (``--background-images``,
  the plate), and with the temporal median alone, to show why a plate is needed: a subject
  who keeps still is part of the median.
* walk: cmu_02_01_walk.bvh, every 6th clip frame (20 Hz), ``--frames`` frames, turned 45
  degrees about the vertical (`turned_bvh`): the subject walks diagonally across the ring,
  so every camera sees it cross part of its image. No plate: the default temporal median,
  and the same without the multi-view check; with the plate as a reference.
* walk along: the same clip as it is, walking along the axis of two cameras, towards one and
  away from the other (cam00, cam02), across the other two. In those two it stays on the same
  pixels in most frames: no median can show the empty scene there, and the step is to say so
  (`tracking.silhouettes.step.held_by_median`: a warning, and those pixels marked unknown, so
  that the multi-view check does not carry the loss into the cameras it crosses). The median,
  and the plate as a reference.
* drift: the still and the walk videos decoded and written again, frame by frame, with a
  global per-channel gain that falls linearly from 1 to 0.78 (blue), 0.80 (green) and 0.82
  (red) over the clip (the light dims, or the camera's auto-exposure drifts), losslessly
  (FFV1); the plate is the synth's, taken at gain 1.
* still (FFV1), a reference: the still scene composited again from the truth masks, the plate
  and the cloth (`tracking.rig.synth_video`) and written losslessly, with the plate: what is
  left of the error without MJPG's blur of the cloth's edges.

The truth is synth's exact renders (``silhouettes/<camera>/<frame>.png`` of the ``--clean``
synth workspace; video frame k is synth frame k). Per camera: the median IoU of the step's
masks with the truth over the frames, the worst frame's IoU, and the frames where the truth
has the subject but the step's mask is empty. Target (issue 18): median IoU >= 0.92 in every
camera and no empty silhouette where the subject is in view. For each row that misses it, the
error pixels: missed (truth not found) and extra (found, not truth), as a share of the truth's
area, with the part of each within 2 px of the truth's outline (edges: MJPG blurs cloth and
scene together there), the share the multi-view check removed and, with a plate, the exposure
gain the step measured (from its summary).

The subject is rendered by our own superquadric body model (`tracking.body.model`, driven by
the BVH), not a scanned human: fine for silhouettes, since the silhouettes step is model-free
(it sees only pixels). The scene (blurred colour noise over a ramp) and the red cloth are
synthetic too (`tracking.rig.synth_video`); the synth videos have no cast shadows.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from _cli import SHARED_DATA, mocap  # benchmarks/ is on sys.path when a script here runs
from scipy.spatial.transform import Rotation

from tracking.rig.synth_video import cloth_texture, composite, scene_background

BVH = SHARED_DATA / "mocap_bvh"
STAND, WALK = BVH / "cmu_131_01_start_walk_stop.bvh", BVH / "cmu_02_01_walk.bvh"
TARGET = 0.92
WALK_YAW_DEG = 45.0
SWAY_M, SWAY_PERIOD_S, HOLD_FPS = 0.01, 4.0, 30.0
CMU_METRES_PER_UNIT = 0.0254 / 0.45  # `mocap synth`'s default --metres-per-unit
DRIFT_END_BGR = (0.78, 0.80, 0.82)
EDGE_PX = 2
PLATE = "plate (--background-images)"


def held_bvh(source: Path, frame: int, count: int, out: Path) -> Path:
    """``out``: a BVH of ``count`` frames at `HOLD_FPS`, each the ``frame``-th of ``source`` with
    its root moved `SWAY_M` side to side along X (a sinusoid of `SWAY_PERIOD_S`)."""
    lines = source.read_text().splitlines()
    motion = next(i for i, line in enumerate(lines) if line.strip() == "MOTION")
    root_channels = next(line.split() for line in lines[:motion] if "CHANNELS" in line)
    x = root_channels[2:].index("Xposition")
    values = lines[motion + 3 + frame].split()
    body = []
    for k in range(count):
        swayed = list(values)
        offset = SWAY_M / CMU_METRES_PER_UNIT * math.sin(2 * math.pi * k / HOLD_FPS / SWAY_PERIOD_S)
        swayed[x] = f"{float(values[x]) + offset:.5f}"
        body.append(" ".join(swayed))
    out.write_text("\n".join([*lines[: motion + 1], f"Frames: {count}",
                              f"Frame Time: {1 / HOLD_FPS:.7f}", *body]) + "\n")  # fmt: skip
    return out


def turned_bvh(source: Path, yaw_deg: float, out: Path) -> Path:
    """``out``: ``source`` turned by ``yaw_deg`` about the vertical (BVH Y) through the mean
    position of its root: the root's positions rotated, and its rotation pre-multiplied."""
    lines = source.read_text().splitlines()
    motion = next(i for i, line in enumerate(lines) if line.strip() == "MOTION")
    channels = next(line.split() for line in lines[:motion] if "CHANNELS" in line)[2:]
    x, z = channels.index("Xposition"), channels.index("Zposition")
    rotations = [k for k, c in enumerate(channels) if c.endswith("rotation")]
    order = "".join(channels[k][0] for k in rotations)  # intrinsic, as BVH applies them
    values = np.array([line.split() for line in lines[motion + 3:] if line.strip()], float)
    a = math.radians(yaw_deg)
    dx, dz = values[:, x] - values[:, x].mean(), values[:, z] - values[:, z].mean()
    values[:, x] += math.cos(a) * dx + math.sin(a) * dz - dx
    values[:, z] += -math.sin(a) * dx + math.cos(a) * dz - dz
    turned = (Rotation.from_euler("Y", yaw_deg, degrees=True)
              * Rotation.from_euler(order, values[:, rotations], degrees=True))
    values[:, rotations] = turned.as_euler(order, degrees=True)
    out.write_text("\n".join([*lines[: motion + 3],
                              *(" ".join(f"{v:.5f}" for v in row) for row in values)]) + "\n")
    return out


def drifted_videos(videos: Path, out: Path) -> Path:
    """``out/<camera>.avi`` (FFV1): each video of ``videos`` with frame k of n multiplied per
    channel by ``1 - (1 - end) * k / (n - 1)``, ``end`` = `DRIFT_END_BGR`."""
    out.mkdir(parents=True)
    for video in sorted(videos.glob("*.avi")):
        capture = cv2.VideoCapture(str(video))
        n = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
                int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))  # fmt: skip
        writer = cv2.VideoWriter(str(out / video.name), cv2.VideoWriter_fourcc(*"FFV1"),
                                 capture.get(cv2.CAP_PROP_FPS), size)  # fmt: skip
        if not writer.isOpened():
            sys.exit("OpenCV cannot write FFV1 videos here")
        end = np.asarray(DRIFT_END_BGR, np.float32)
        for k in range(n):
            ok, frame = capture.read()
            if not ok:
                sys.exit(f"{video}: frame {k} of {n} does not decode")
            gain = 1 - (1 - end) * k / max(n - 1, 1)
            writer.write(np.clip(frame * gain + 0.5, 0, 255).astype(np.uint8))
        capture.release()
        writer.release()
    return out


def lossless_videos(synth: Path, out: Path) -> Path:
    """``out/<camera>.avi`` (FFV1): the frames of ``synth``'s videos composited again from its
    clean silhouettes, scenes and cloths (`tracking.rig.synth_video`, synth's seed 0)."""
    out.mkdir(parents=True)
    for k, folder in enumerate(sorted(p for p in (synth / "silhouettes").iterdir()
                                      if p.is_dir())):  # fmt: skip
        masks = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) > 127
                 for p in sorted(folder.glob("[0-9]*.png"))]  # fmt: skip
        height, width = masks[0].shape
        scene, cloth = scene_background(width, height, 17 * k), cloth_texture(width, height, 17 * k)
        plate = cv2.imread(str(synth / "render" / "backgrounds" / f"{folder.name}.png"))
        if not np.array_equal(scene, plate):
            sys.exit(f"{folder.name}: the scene is not synth's (its seeds changed?)")
        writer = cv2.VideoWriter(str(out / f"{folder.name}.avi"), cv2.VideoWriter_fourcc(*"FFV1"),
                                 HOLD_FPS, (width, height))  # fmt: skip
        for mask in masks:
            writer.write(composite(scene, cloth, mask))
        writer.release()
    return out


@dataclass
class CameraScore:
    median: float
    worst: float
    worst_frame: int
    empty: list[int]
    truth_px: int
    missed_px: int
    missed_edge_px: int
    extra_px: int
    extra_edge_px: int
    unknown_px: int
    """Truth pixels inside the step's ``unknown.png`` of the camera (0 without one)."""


def score_camera(ours: Path, truth: Path) -> CameraScore:
    """The masks of the folder ``ours`` against those of the same name in ``truth``."""
    ring = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * EDGE_PX + 1, 2 * EDGE_PX + 1))
    ious, empty = [], []
    counts = np.zeros(5, np.int64)
    frames = sorted(truth.glob("[0-9]*.png"))
    unknown_path = ours / "unknown.png"
    unknown = (cv2.imread(str(unknown_path), cv2.IMREAD_GRAYSCALE) > 127
               if unknown_path.exists() else None)  # fmt: skip
    unknown_px = 0
    for path in frames:
        exact = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127
        found = cv2.imread(str(ours / path.name), cv2.IMREAD_GRAYSCALE)
        if found is None:
            sys.exit(f"{ours / path.name} is missing")
        found = found > 127
        union = np.count_nonzero(exact | found)
        ious.append(np.count_nonzero(exact & found) / union if union else 1.0)
        if exact.any() and not found.any():
            empty.append(int(path.stem))
        t = exact.astype(np.uint8)
        edge = (cv2.dilate(t, ring) > 0) & ~(cv2.erode(t, ring) > 0)
        missed, extra = exact & ~found, found & ~exact
        if unknown is not None:
            unknown_px += int(np.count_nonzero(exact & unknown))
        counts += [exact.sum(), missed.sum(), (missed & edge).sum(), extra.sum(),
                   (extra & edge).sum()]  # fmt: skip
    worst = int(np.argmin(ious))
    return CameraScore(float(np.median(ious)), float(ious[worst]), int(frames[worst].stem),
                       empty, *(int(c) for c in counts), unknown_px)  # fmt: skip


@dataclass
class Row:
    kind: str
    flags: str
    cameras: dict[str, CameraScore]
    seconds: float
    summary: dict

    @property
    def passed(self) -> bool:
        return all(c.median >= TARGET and not c.empty for c in self.cameras.values())

    @property
    def verdict(self) -> str:
        """PASS; FLAGGED when every camera that misses the target is one whose median the
        step reports as holding the subject (a warning and unknown pixels); else FAIL."""
        if self.passed:
            return "PASS"
        missing = [n for n, c in self.cameras.items() if c.median < TARGET or c.empty]
        flagged = [n for n in missing
                   if "median_holds_subject" in self.summary["cameras"].get(n, {})]
        return "FLAGGED" if flagged == missing else "FAIL"


def run_row(kind: str, flags: list[str], label: str, videos: Path, synth: Path,
            cap: Path) -> Row:  # fmt: skip
    """`mocap init-video` of ``videos`` (once per ``cap``), `mocap silhouettes` with
    ``flags``, scored against ``synth``'s clean silhouettes."""
    if not (cap / "cameras.json").exists():
        mocap("init-video", str(cap), "--videos", str(videos), "--calibration",
              str(synth / "cameras.json"), echo=False)  # fmt: skip
    seconds = mocap("silhouettes", str(cap), "--overwrite", *flags, echo=False)
    truth = synth / "silhouettes"
    cameras = {c.name: score_camera(cap / "silhouettes" / c.name, c)
               for c in sorted(truth.iterdir()) if c.is_dir()}  # fmt: skip
    summary = json.loads((cap / "run.json").read_text())["steps"]["silhouettes"]["summary"]
    return Row(kind, label, cameras, seconds, summary)


def print_table(rows: list[Row]) -> None:
    names = list(rows[0].cameras)
    print(f"{'kind':<13}{'background':<29}" + "".join(f"{n:>7}" for n in names)
          + f"{'worst (camera frame)':>26}{'empty':>7}{'seconds':>9}  target")  # fmt: skip
    for row in rows:
        worst_name = min(row.cameras, key=lambda n: row.cameras[n].worst)
        worst = row.cameras[worst_name]
        empty = sum(len(c.empty) for c in row.cameras.values())
        print(f"{row.kind:<13}{row.flags:<29}"
              + "".join(f"{row.cameras[n].median:>7.3f}" for n in names)
              + f"{worst.worst:>12.3f} ({worst_name} {worst.worst_frame:>3})"
              + f"{empty:>7}{row.seconds:>9.1f}  {row.verdict}")  # fmt: skip


def ranges(frames: list[int]) -> str:
    """``[1, 2, 3, 7]`` -> ``"1-3, 7"``."""
    runs: list[list[int]] = []
    for f in frames:
        if runs and f == runs[-1][1] + 1:
            runs[-1][1] = f
        else:
            runs.append([f, f])
    return ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in runs)


def print_errors(row: Row) -> None:
    """Where the error pixels of ``row`` fall, per camera that misses the target."""
    print(f"{row.kind}, {row.flags}: {row.summary.get('background', '')}")
    for name, c in row.cameras.items():
        if c.median >= TARGET and not c.empty:
            continue
        camera = row.summary["cameras"].get(name, {})
        removed = camera.get("hull_removed", {}).get("median")
        gain = camera.get("exposure_gain") or {}
        empty = f", empty in {len(c.empty)} frames ({ranges(c.empty)})" if c.empty else ""
        held = camera.get("median_holds_subject")
        print(f"  {name}: missed {c.missed_px / c.truth_px:6.1%} of the truth "
              f"({c.missed_edge_px / max(c.missed_px, 1):4.0%} within {EDGE_PX} px of its "
              f"outline), extra {c.extra_px / c.truth_px:6.1%} "
              f"({c.extra_edge_px / max(c.extra_px, 1):4.0%} within {EDGE_PX} px)"
              + (f"; multi-view check removed {removed:.1%} (median)"
                 if removed is not None else "")
              + (f"; exposure gain {gain['min']:.3f}-{gain['max']:.3f}" if gain else "")
              + (f"; flagged: the median holds the subject on {held:.1%} of the image, "
                 f"marked unknown ({c.unknown_px / c.truth_px:.0%} of the truth)"
                 if held else "")
              + empty)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", type=int, default=4)
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--size", default="640x480")
    parser.add_argument("--keep", type=Path, help="keep the workspaces in this folder")
    args = parser.parse_args()
    for clip in (STAND, WALK):
        if not clip.is_file():
            sys.exit(f"{clip} is absent")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        common = ["--videos", "--clean", "--cameras", str(args.cameras), "--size", args.size,
                  "--frames", str(args.frames)]  # fmt: skip
        held = held_bvh(STAND, 0, args.frames, root / "still.bvh")
        turned = turned_bvh(WALK, WALK_YAW_DEG, root / "walk.bvh")
        synth_s = {}
        for kind, clip, step in (("still", held, 1), ("walk", turned, 6),
                                 ("walk_along", WALK, 6)):
            synth_s[kind] = mocap("synth", str(root / f"synth_{kind}"), "--bvh", str(clip),
                                  "--step", str(step), *common, echo=False)  # fmt: skip
        rows = []
        for kind in ("still", "walk", "walk_along"):
            synth = root / f"synth_{kind}"
            plate = ["--background-images", str(synth / "render" / "backgrounds")]
            videos = synth / "render" / "videos"
            cap = root / f"cap_{kind}"
            label = kind.replace("_", " ")
            plate_row = run_row(label, plate, PLATE, videos, synth, cap)
            median_row = run_row(label, [], "median (no plate)", videos, synth, cap)
            if kind == "walk":
                alone = run_row(label, ["--no-multi-view-check"], "median, no multi-view check",
                                videos, synth, cap)  # fmt: skip
                rows += [median_row, alone, plate_row]
            else:
                rows += [plate_row, median_row] if kind == "still" else [median_row, plate_row]
        for kind in ("still", "walk"):
            synth = root / f"synth_{kind}"
            videos = root / f"drift_{kind}"
            if not videos.is_dir():
                drifted_videos(synth / "render" / "videos", videos)
            plate = ["--background-images", str(synth / "render" / "backgrounds")]
            rows.append(run_row(f"{kind}+drift", plate, PLATE, videos, synth,
                                root / f"cap_drift_{kind}"))  # fmt: skip
        synth = root / "synth_still"
        videos = root / "lossless_still"
        if not videos.is_dir():
            lossless_videos(synth, videos)
        plate = ["--background-images", str(synth / "render" / "backgrounds")]
        rows.append(run_row("still (FFV1)", plate, PLATE, videos, synth, root / "cap_lossless"))
    print(f"{args.cameras} cameras x {args.frames} frames at {args.size}; synth "
          + ", ".join(f"{t:.1f} s ({k})" for k, t in synth_s.items()))  # fmt: skip
    print(f"IoU with the rendered truth: median over the frames per camera; target median >= "
          f"{TARGET} in every camera, no empty silhouette with the subject in view (FLAGGED: "
          "missed only where the step warns that the median holds the subject)")  # fmt: skip
    print_table(rows)
    failing = [row for row in rows if not row.passed]
    if failing:
        print("\nerror pixels of the cameras that miss the target:")
        for row in failing:
            print_errors(row)


if __name__ == "__main__":
    main()
