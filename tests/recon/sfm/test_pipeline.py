"""SfM through our steps on pycolmap's synthetic dataset (truth known), and on real photos."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from recon.evaluation.truth import pose_errors
from recon.sfm.pipeline import SfMConfig, cams_from_world, initialise_intrinsics, map_sparse
from recon.workspace import Workspace
from tests.helpers import read_recording, recording_entities, run_cli, shared_dataset

TRUE_FOCAL = 1280.0


def _synthetic_workspace(tmp_path, *, noise_px: float = 0.0):
    """A workspace whose database pycolmap synthesised (keypoints, matches, geometries).

    Seeded, one camera, 8 images. Features and matching are pycolmap's synthetic ones, so the
    workspace records them as done and our intrinsics and mapping steps run on top.
    """
    ws = Workspace(tmp_path / "ws")
    ws.images_dir.mkdir(parents=True)
    pycolmap.set_random_seed(0)
    options = pycolmap.SyntheticDatasetOptions(
        num_rigs=1,
        num_cameras_per_rig=1,
        num_frames_per_rig=8,
        num_points3D=300,
        camera_params=[TRUE_FOCAL, 512.0, 384.0, 0.0],
    )
    with pycolmap.Database.open(ws.database_path) as db:
        truth = pycolmap.synthesize_dataset(options, db)
        if noise_px:
            # Perturbs the keypoints in the database (and in the model passed, hence the copy).
            noisy = pycolmap.Reconstruction(truth)
            pycolmap.synthesize_noise(
                pycolmap.SyntheticNoiseOptions(point2D_stddev=noise_px), noisy, db
            )
    ws.record_step("matches", "synthetic", outputs=[ws.database_path], config={}, seconds=0.0)
    return ws, truth


def _run_single_threaded(ws, **kwargs):
    config = SfMConfig(num_threads=1, seed=0, **kwargs)
    initialise_intrinsics(ws, config)
    return map_sparse(ws, config)


@pytest.mark.parametrize(
    ("intrinsics", "options"),
    [("colmap-default", ()), ("fixed", (f"focal_px={TRUE_FOCAL}",))],
)
def test_synthetic_dataset_recovers_truth(tmp_path, intrinsics, options):
    ws, truth = _synthetic_workspace(tmp_path)
    record = _run_single_threaded(ws, intrinsics=intrinsics, intrinsics_options=options)
    assert record.summary["registered"] == 8
    model = pycolmap.Reconstruction(ws.model_dir)
    errors = pose_errors(cams_from_world(model), cams_from_world(truth))
    # Noise-free correspondences: poses exact up to solver tolerance.
    assert max(errors.rotation_deg.values()) < 1e-2  # degrees
    extent = np.ptp([im.projection_center() for im in truth.images.values()], axis=0).max()
    assert max(errors.center.values()) < 1e-4 * extent  # scene units
    focal = model.cameras[1].params[0]
    assert focal == pytest.approx(TRUE_FOCAL, rel=1e-4)
    with pycolmap.Database.open(ws.database_path) as db:
        assert db.read_camera(1).has_prior_focal_length == (intrinsics == "fixed")


def test_synthetic_dataset_with_keypoint_noise(tmp_path):
    """Noisy variant: 1 px keypoint noise, so the bounds are loosened on purpose."""
    ws, truth = _synthetic_workspace(tmp_path, noise_px=1.0)
    assert _run_single_threaded(ws).summary["registered"] == 8
    model = pycolmap.Reconstruction(ws.model_dir)
    errors = pose_errors(cams_from_world(model), cams_from_world(truth))
    assert max(errors.rotation_deg.values()) < 0.5  # degrees
    extent = np.ptp([im.projection_center() for im in truth.images.values()], axis=0).max()
    assert max(errors.center.values()) < 0.02 * extent
    assert model.cameras[1].params[0] == pytest.approx(TRUE_FOCAL, rel=0.02)
    assert 0.5 < model.compute_mean_reprojection_error() < 2.0  # px: noise is really there


def test_wrong_fixed_focal_is_held_when_not_refined(tmp_path):
    ws, _ = _synthetic_workspace(tmp_path)
    _run_single_threaded(ws, intrinsics="fixed", intrinsics_options=("focal_px=1400",))
    assert pycolmap.Reconstruction(ws.model_dir).cameras[1].params[0] == pytest.approx(1400)
    # Refining from the same wrong start recovers the truth, and reruns the mapping step.
    before = ws.step("mapping").fingerprint
    _run_single_threaded(
        ws, intrinsics="fixed", intrinsics_options=("focal_px=1400",), refine_focal=True
    )
    assert ws.step("mapping").fingerprint != before
    assert pycolmap.Reconstruction(ws.model_dir).cameras[1].params[0] == pytest.approx(
        TRUE_FOCAL, rel=1e-3
    )


def test_mapping_recording_has_cameras_points_and_errors(tmp_path):
    ws, truth = _synthetic_workspace(tmp_path)
    _run_single_threaded(ws)
    entities = recording_entities(ws.log_path("mapping"))
    name = next(iter(truth.images.values())).name.replace(".", "_")
    assert "/world/points@Points3D:positions" in entities
    assert f"/world/cameras/{name}@Transform3D:mat3x3" in entities
    assert f"/world/cameras/{name}/image@Pinhole:image_from_camera" in entities
    assert f"/world/cameras/{name}/image/keypoints@Points2D:positions" in entities
    assert "/stats/reprojection_error_px@BarChart:values" in entities
    assert "/stats/registered_images@Scalars:scalars" in entities


def test_mapping_recording_opens_on_the_timeline_of_its_curve(tmp_path):
    """Issue 21: `stats/registered_images` sat on a timeline the viewer did not show, so its
    plot was empty until the user switched timelines. Read back with Rerun's reader: the
    blueprint's time panel shows `registration`, which carries the curve (one point per
    registration), and every view of the layout shows data."""
    ws, truth = _synthetic_workspace(tmp_path)
    _run_single_threaded(ws)
    rec = read_recording(ws.log_path("mapping"))
    assert rec.application_id == "mocap-mapping"
    assert rec.timeline == "registration"
    registrations = rec.rows("stats/registered_images", "registration")
    counts = rec.rows("stats/registered_images", "Scalars:scalars")
    assert len(counts) >= 2 and registrations == list(range(len(counts)))
    assert [c for (c,) in counts] == list(range(1, len(counts) + 1))  # one more each time
    assert {(v["kind"], v["origin"]) for v in rec.views} >= {
        ("3D", "world"), ("TimeSeries", "stats/registered_images"),
        ("BarChart", "stats/reprojection_error_px")}
    assert rec.layout_problems() == []
    # The reprojection error per image: a bar per registered image, whichever the timeline.
    ((bars,),) = rec.rows("stats/reprojection_error_px", "BarChart:values", static=True)
    assert bars["shape"] == [len(truth.images)] and max(bars["buffer"]) < 1.0  # px
    assert read_recording(ws.log_path("intrinsics")).layout_problems() == []


@pytest.mark.shared_data
def test_temple_through_the_cli(tmp_path):
    temple = shared_dataset("temple_sparse_ring")
    ws = tmp_path / "temple"
    result = run_cli("sfm", ws, "--images", temple)
    assert result.returncode == 0, result.stderr
    model = pycolmap.Reconstruction(ws / "sparse" / "0")
    assert model.num_reg_images() >= 13
    assert model.cameras[1].params[0] == pytest.approx(1523.0, rel=0.02)
    assert "registered" in result.stdout and "focal" in result.stdout
    # A second run reuses every step.
    again = run_cli("sfm", ws)
    assert again.returncode == 0 and again.stdout.count("(reused)") == 4
    entities = recording_entities(ws / "logs" / "features.rrd")
    assert "/world/cameras/templeSR0001_png/image@EncodedImage:blob" in entities
    for step in ("features", "matches", "intrinsics", "mapping"):
        assert read_recording(ws / "logs" / f"{step}.rrd").layout_problems() == [], step
