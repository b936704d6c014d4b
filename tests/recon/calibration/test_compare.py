"""`mocap compare` and the kruppa / view-graph initialisers against known focal lengths."""

from __future__ import annotations

import json

import pytest

from recon.calibration.compare import CompareConfig, compare_intrinsics
from recon.demo import DemoConfig, make_scene
from recon.sfm.pipeline import CameraMode, SfMConfig, run_sfm
from recon.workspace import Workspace
from tests.helpers import read_recording, recording_entities, run_cli, shared_dataset

TRUE_FOCAL = 600.0  # the synthetic scene's


@pytest.fixture(scope="module")
def demo_ws(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare") / "demo"
    images, truth, _ = make_scene(DemoConfig(out=out, num_views=10))
    ws, _ = Workspace.create(out, images)
    return ws, truth


def test_compare_on_the_synthetic_scene(demo_ws):
    ws, truth = demo_ws
    json_copy = ws.root / "elsewhere" / "c.json"
    result = compare_intrinsics(
        ws, SfMConfig(), CompareConfig(gt=truth, json=json_copy)
    )
    data = json.loads((ws.root / "compare" / "comparison.json").read_text())
    assert data == json.loads(json_copy.read_text())
    assert data["ground_truth_focal_px"] == pytest.approx(TRUE_FOCAL)
    assert set(data["methods"]) == {
        "kruppa", "kruppa-pp", "kruppa-pp-epipolar", "kruppa-per-image", "kruppa+ba",
        "colmap-default+ba",
        "view-graph", "view-graph+ba"
    }
    for name, method in data["methods"].items():
        assert method["registered"] == method["images"] == 10, name
        if name == "view-graph":
            # COLMAP's own fit, held fixed: usually within 0.2% here, but it was seen 15% off
            # on some runs' matches. Ours is what this test holds to 1%.
            assert abs(method["rel_error"]) < 0.5, name
        else:
            assert abs(method["rel_error"]) < 0.01, name  # within 1% on a generic scene
        assert method["seconds"] > 0 and method["mean_reproj_px"] < 1.0
    # The variants say which mode ran and where their principal point is against the truth.
    truth_pp = data["ground_truth_principal_point_px"]
    assert truth_pp is not None
    methods = data["methods"]
    assert methods["kruppa"]["mode"] == "shared focal, principal point at centre"
    assert methods["kruppa-per-image"]["mode"].startswith("per-image focal")
    assert methods["kruppa-pp"]["mode"].startswith("shared focal, free principal point")
    # Accepted or rejected, the principal point used stays near the truth (the demo's is the
    # image centre) and a rejection is said in the notes.
    for name in ("kruppa-pp", "kruppa-pp-epipolar"):
        assert methods[name]["principal_point_error_px"] < 10.0, name
        fit = methods[name]["principal_point_fit"]
        assert fit["status"] == "ok" or any("rejected" in n for n in methods[name]["notes"])
    assert methods["kruppa-pp-epipolar"]["mode"].startswith(
        "shared focal, free principal point from the inliers")
    assert methods["kruppa"]["principal_point_error_px"] < 1.0
    assert "principal point" in result.outputs["report"].read_text()
    assert result.outputs["principal_points_png"].stat().st_size > 1000
    # Kruppa alone: the focal is the closed-form estimate, held fixed in mapping.
    kruppa = data["methods"]["kruppa"]
    assert kruppa["focal_px"] == pytest.approx(kruppa["initial_focal_px"])
    assert not kruppa["fallback"]
    # Per-pair table (thesis Table 4.1): every pair has a status; ok pairs have a focal.
    assert data["pairs"] and all(p["status"] for p in data["pairs"])
    ok = [p for p in data["pairs"] if p["status"] == "ok"]
    assert len(ok) >= 10 and all(p["focal_px"] > 0 for p in ok)
    assert data["kruppa_fused"]["status"] == "ok"
    for key in ("pairs_png", "errors_png", "report"):
        assert result.outputs[key].stat().st_size > 1000
    assert "Table 4.1" in result.outputs["report"].read_text()
    entities = recording_entities(ws.root / "logs" / "compare.rrd")
    assert "/kruppa/pair_focal_px@Scalars:scalars" in entities
    assert "/tables/methods@TextDocument:text" in entities
    # Opens on the `pair` timeline of its curves, every view with data (issue 21).
    read = read_recording(ws.root / "logs" / "compare.rrd")
    assert read.timeline == "pair" and read.layout_problems() == []


def test_kruppa_through_sfm_sets_the_prior(demo_ws):
    ws, _ = demo_ws
    summary = run_sfm(ws, SfMConfig(intrinsics="kruppa", intrinsics_options=("refine=false",)))
    camera = summary.steps["intrinsics"].summary["cameras"][0]
    assert camera["prior"] and camera["focal_px"] == pytest.approx(TRUE_FOCAL, rel=0.01)
    assert camera["source"].startswith("kruppa")
    assert summary.mapping["cameras"][0]["focal_px"] == pytest.approx(camera["focal_px"])


def test_compare_rejects_bad_ground_truth_and_methods(demo_ws, tmp_path):
    ws, _ = demo_ws
    bogus = tmp_path / "gt.csv"
    bogus.write_text("1,2,3")
    result = run_cli("compare", ws.root, "--gt", bogus)
    assert result.returncode == 2 and "not a ground truth" in result.stderr
    result = run_cli("compare", ws.root, "--methods", "kruppa,magic")
    assert result.returncode == 2 and "unknown method(s) magic" in result.stderr


@pytest.mark.slow  # session 24: make test took 17:23 on these machines, over its 10 minutes
@pytest.mark.shared_data
def test_temple_ring_is_flagged_and_falls_back(tmp_path):
    """The Middlebury ring is Kruppa's singular case: every pair must be flagged, and mapping
    falls back to COLMAP's default rather than using a meaningless focal."""
    temple = shared_dataset("temple_sparse_ring")
    ws = tmp_path / "temple"
    assert run_cli("init", ws, "--images", temple).returncode == 0
    result = run_cli(
        "compare", ws, "--gt", temple / "templeSR_par.txt", "--methods", "kruppa,view-graph"
    )
    assert result.returncode == 0, result.stderr
    data = json.loads((ws / "compare" / "comparison.json").read_text())
    assert data["ground_truth_focal_px"] == pytest.approx(1523.15)
    # Nearly every pair is flagged; matching is multi-threaded, and now and then one noisy pair
    # escapes the flag (seen: 1 of 33), which fusion must not trust on its own.
    ok = [p for p in data["pairs"] if p["status"] == "ok"]
    assert len(ok) <= 0.1 * len(data["pairs"])
    assert data["kruppa_fused"]["status"] != "ok"
    assert data["methods"]["kruppa"]["fallback"]
    assert "fell back" in result.stdout
    # The fallback is COLMAP's default with BA: within 2% of the truth.
    assert abs(data["methods"]["kruppa"]["rel_error"]) < 0.02
    # COLMAP's view-graph calibration is far off on this ring (measured 54%).
    assert abs(data["methods"]["view-graph"]["rel_error"]) > 0.2


@pytest.mark.slow
@pytest.mark.shared_data
def test_fountain_kruppa_within_half_a_percent(tmp_path):
    fountain = shared_dataset("fountain_p11")
    ws = tmp_path / "fountain"
    assert run_cli("init", ws, "--images", fountain / "images").returncode == 0
    result = run_cli(
        "compare", ws, "--gt", fountain / "gt_dense_cameras", "--methods", "kruppa,kruppa+ba"
    )
    assert result.returncode == 0, result.stderr
    methods = json.loads((ws / "compare" / "comparison.json").read_text())["methods"]
    assert abs(methods["kruppa"]["rel_error"]) < 0.005
    assert abs(methods["kruppa+ba"]["rel_error"]) < 0.001
    assert methods["kruppa+ba"]["registered"] == 11


def test_kruppa_falls_back_when_every_pair_is_singular(tmp_path):
    """pycolmap's synthetic cameras all aim at the scene centre: no pair determines f. The
    initialiser must say so and fall back to COLMAP's default (refined), and mapping still
    recovers the focal."""
    from recon.sfm.pipeline import initialise_intrinsics, map_sparse
    from tests.recon.sfm.test_pipeline import TRUE_FOCAL as SYNTHETIC_FOCAL
    from tests.recon.sfm.test_pipeline import _synthetic_workspace

    ws, _ = _synthetic_workspace(tmp_path)
    config = SfMConfig(intrinsics="kruppa", intrinsics_options=("refine=false",), num_threads=1)
    record = initialise_intrinsics(ws, config)
    assert record.summary["details"]["fallback"] is True
    assert record.summary["refine_focal"] is True  # a default guess is never frozen
    assert any("falling back to colmap-default" in n for n in record.summary["notes"])
    assert record.summary["cameras"][0]["prior"] is False
    statuses = {p["status"] for p in record.summary["details"]["pairs"]}
    assert "ok" not in statuses and "near-singular" in statuses
    mapping = map_sparse(ws, config)
    assert mapping.summary["cameras"][0]["focal_px"] == pytest.approx(SYNTHETIC_FOCAL, rel=1e-3)


def test_kruppa_per_image_gives_each_camera_its_focal(tmp_path):
    """Features extracted with one camera per image: per-image mode gives every camera its
    own focal prior (the demo's are all 600 px) and says so in the run record."""
    out = tmp_path / "demo"
    images, _, _ = make_scene(DemoConfig(out=out, num_views=10))
    ws, _ = Workspace.create(out, images)
    config = SfMConfig(
        intrinsics="kruppa", intrinsics_options=("refine=false", "camera_mode=per-image"),
        camera_mode=CameraMode.PER_IMAGE,
    )
    summary = run_sfm(ws, config)
    record = summary.steps["intrinsics"].summary
    cameras = record["cameras"]
    assert len(cameras) == 10
    assert record["details"]["camera_mode"] == "per-image"
    priors = [c["focal_px"] for c in cameras if c["prior"]]
    assert len(priors) >= 8, record["notes"]  # a camera with only singular pairs falls back
    # Measured within 0.6% (two runs); the cameras on an arc constrain their common scale weakly,
    # and a refit closer to least squares was 2-3% short here.
    assert all(abs(f / TRUE_FOCAL - 1) < 0.015 for f in priors), priors
    assert all(c["source"].startswith("kruppa per-image") for c in cameras if c["prior"])
