"""logs/track.rrd read back with Rerun's own reader: the XOR overlay's classes, the body mesh
that shades without hiding the skeleton, and the default blueprint (issue 21)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from recon.recording import XOR_CLASSES
from recon.workspace import Workspace
from tests.helpers import ReadRecording, read_recording
from tracking.body.bvh import write_bvh
from tracking.body.model import BodyShape
from tracking.body.motion import motion_from_poses
from tracking.body.synthetic import walking_poses
from tracking.rig.synth import SynthConfig, synthesize
from tracking.track.step import HeldMasks, TrackStepConfig, track_workspace
from tracking.track.tracker import TrackConfig

FRAMES = 3
CAMERAS = ("cam00", "cam01", "cam02")
SIZE = (160, 120)  # below MAX_LOGGED_IMAGE_SIZE: the overlays are logged at the masks' size


@pytest.fixture(scope="module")
def tracked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ReadRecording]:
    """A 3-frame synthetic walk seen by 3 cameras at 160x120, tracked from its true start (about
    10 s): the workspace and its track.rrd."""
    root = tmp_path_factory.mktemp("walk")
    shape = BodyShape.default(1.68)
    bvh = root / "walk.bvh"
    write_bvh(motion_from_poses(walking_poses(FRAMES, 30.0, shape), shape, 1 / 30), bvh)
    ws = root / "ws"
    synthesize(ws, SynthConfig(bvh=bvh, size=f"{SIZE[0]}x{SIZE[1]}", cameras=len(CAMERAS),
                               clean=True))  # fmt: skip
    summary = track_workspace(Workspace(ws), TrackStepConfig(init_pose=ws / "gt" / "pose.json"),
                              TrackConfig(), progress=False)  # fmt: skip
    assert summary["tracked"] == FRAMES
    return ws, read_recording(ws / "logs" / "track.rrd")


def _classes(row: list) -> dict[int, tuple[str, int]]:
    """{class id: (label, 0xRRGGBBAA colour)} of one logged AnnotationContext (a row of its
    column: one context, a list of classes)."""
    (context,) = row
    return {c["class_id"]: (c["class_description"]["info"]["label"],
                            c["class_description"]["info"]["color"]) for c in context}


def test_the_xor_classes_are_logged_once_before_the_overlays(tracked):
    """Re-logged between the frames, the viewer fell back to its own palette ("Label 0")."""
    _, rec = tracked
    overlays = sorted(rec.entities("SegmentationImage:buffer"))
    assert overlays == [f"/world/cameras/{c}/image/xor" for c in CAMERAS]
    contexts = [(chunk.entity_path, row) for chunk in rec.chunks
                for row in (chunk.to_record_batch().column("AnnotationContext:context").to_pylist()
                            if "AnnotationContext:context" in chunk.to_record_batch().schema.names
                            else [])]  # fmt: skip
    xor = [(path, row) for path, row in contexts
           if any(o == path or o.startswith(path + "/") for o in overlays)]
    assert len(xor) == 1, [path for path, _ in xor]  # one context, for every camera's overlay
    path, context = xor[0]
    expected = {i: (label, (r << 24) | (g << 16) | (b << 8) | 255)
                for i, label, (r, g, b) in XOR_CLASSES}
    assert _classes(context) == expected
    assert [label for label, _ in expected.values()] == ["neither", "model only", "image only",
                                                         "both"]
    # Before the first overlay, in the file and in the time the rows were made (row ids are
    # time-ordered).
    first_overlay = next(i for i, c in enumerate(rec.chunks) if c.entity_path in overlays)
    first_context = next(i for i, c in enumerate(rec.chunks) if c.entity_path == path
                         and "AnnotationContext:context" in c.to_record_batch().schema.names)
    assert first_context < first_overlay


def test_the_xor_overlay_holds_the_image_silhouette_in_its_classes(tracked):
    """Classes 2 and 3 (image only, both) are exactly the silhouette the tracker read; 1 and 3
    (model only, both) the model's, which covers most of it (tracked from the truth)."""
    ws, rec = tracked
    for camera in CAMERAS:
        frames = rec.rows(f"world/cameras/{camera}/image/xor", "frame")
        buffers = rec.rows(f"world/cameras/{camera}/image/xor", "SegmentationImage:buffer")
        formats = rec.rows(f"world/cameras/{camera}/image/xor", "SegmentationImage:format")
        assert frames == list(range(FRAMES))
        for frame, buffer, (fmt,) in zip(frames, buffers, formats, strict=True):
            assert (fmt["width"], fmt["height"]) == SIZE
            ids = np.asarray(buffer[0], np.uint8).reshape(SIZE[1], SIZE[0])
            assert set(np.unique(ids)) <= {0, 1, 2, 3}
            silhouette = cv2.imread(str(ws / "silhouettes" / camera / f"{frame:06d}.png"),
                                    cv2.IMREAD_GRAYSCALE) > 127
            np.testing.assert_array_equal(ids >= 2, silhouette)
            model = (ids == 1) | (ids == 3)
            assert (model & silhouette).sum() > 0.8 * silhouette.sum()


def test_the_body_mesh_shades_and_shows_the_skeleton(tracked):
    _, rec = tracked
    positions = rec.rows("world/body/mesh", "Mesh3D:vertex_positions")
    normals = rec.rows("world/body/mesh", "Mesh3D:vertex_normals")
    albedo = rec.rows("world/body/mesh", "Mesh3D:albedo_factor")
    assert len(positions) == len(normals) == len(albedo) == FRAMES
    for vertices, vertex_normals, (colour,) in zip(positions, normals, albedo, strict=True):
        vertex_normals = np.asarray(vertex_normals)
        assert vertex_normals.shape == np.asarray(vertices).shape
        np.testing.assert_allclose(np.linalg.norm(vertex_normals, axis=1), 1.0, atol=1e-3)
        # See-through (alpha below a half), so that the skeleton inside shows.
        assert (colour & 0xFF) < 128
    radii = rec.rows("world/body/skeleton", "Points3D:radii", static=False)
    assert len(radii) == FRAMES and all(min(r) >= 0.02 for r in radii)  # metres
    # Its 16 joint names on hover, not drawn over the body.
    assert rec.rows("world/body/skeleton", "Points3D:show_labels") == [[False]] * FRAMES
    ((context,),) = rec.rows("world/body/skeleton", "AnnotationContext:context", static=True)
    (body,) = context
    assert body["class_description"]["info"]["color"] is not None  # not the automatic palette
    assert len(body["class_description"]["keypoint_connections"]) >= 15  # the bones


def test_the_blueprint_shows_body_cameras_and_energy_on_the_frame_timeline(tracked):
    _, rec = tracked
    assert rec.application_id == "mocap-track"
    assert rec.timeline == "frame"
    kinds = {(v["kind"], v["origin"]) for v in rec.views}
    assert ("3D", "world") in kinds
    assert {("2D", f"world/cameras/{c}/image") for c in CAMERAS} <= kinds
    assert ("TimeSeries", "track/energy_px") in kinds
    assert rec.layout_problems() == []
    # What the views show is on the frame timeline, one row per tracked frame.
    assert rec.rows("track/energy_px", "frame") == list(range(FRAMES))
    assert rec.rows("world/body/mesh", "frame") == list(range(FRAMES))


def test_each_frame_status_is_logged_and_written_to_pose_json(tracked):
    """Issue 20: a text log per frame (lost and diverged frames as warnings), its index in
    STATUSES as a scalar, and the same status in pose.json with the lists of lost, diverged
    and recovered frames."""
    import json

    ws, rec = tracked
    assert ("TextLog", "track/status") in {(v["kind"], v["origin"]) for v in rec.views}
    assert rec.rows("track/status", "frame") == list(range(FRAMES))
    texts = [row[0] for row in rec.rows("track/status", "TextLog:text")]
    assert texts[0].startswith("init: init from the given pose") and texts[1:] == ["tracked"] * 2
    assert [row[0] for row in rec.rows("track/status", "TextLog:level")] == ["INFO"] * FRAMES
    assert rec.rows("track/status_index", "frame") == list(range(FRAMES))
    pose = json.loads((ws / "tracks" / "pose.json").read_text())
    assert [f["status"] for f in pose["frames"]] == ["init", "tracked", "tracked"]
    assert (pose["lost"], pose["diverged"], pose["recovered"]) == ([], [], [])



def test_held_silhouettes_come_back_bit_for_bit():
    """The frames a track back may replace are held bit-packed (`HeldMasks`), and what the
    track back and the recording read is what was added: sizes that are no multiple of 8."""
    rng = np.random.default_rng(0)
    masks = [rng.random((121, 163)) > 0.5, rng.random((7, 5)) > 0.3]
    held = HeldMasks()
    held.add(4, masks)
    held.add(5, [~m for m in masks])
    for frame, expected in ((4, masks), (5, [~m for m in masks])):
        back = held.masks(frame)
        assert [m.dtype for m in back] == [np.dtype(bool)] * 2
        assert all(np.array_equal(b, m) for b, m in zip(back, expected, strict=True))
    popped = held.pop(5)
    assert all(np.array_equal(b, ~m) for b, m in zip(popped, masks, strict=True))
    with pytest.raises(KeyError):
        held.masks(5)
    assert all(np.array_equal(b, m) for b, m in zip(held.masks(4), masks, strict=True))
