"""Two-view dense stereo against the synthetic room's exact depth.

Views 0-5 of the room stand on an arc about 20 degrees apart with jittered heights and rolls,
so consecutive pairs have oblique baselines; two extra cameras rendered beside view 2 give the
pure vertical (source above) and the mirrored (source on the left) rectifications.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from recon.dense import stereo
from recon.dense.backends import stereo_pair_depths
from recon.dense.stereo import (
    DepthMap,
    StereoConfig,
    View,
    backproject_pixels,
    depths_from_pair,
    select_pairs,
)
from recon.evaluation.synthetic_room import (
    SyntheticScene,
    SyntheticSceneConfig,
    render_scene,
    render_view,
    scene_quads,
    scene_textures,
)

SCENE_CONFIG = SyntheticSceneConfig(num_views=6)
# The extra cameras: view 2 moved this far up (world z) or to its left (its own -x).
EXTRA_OFFSET_M = 0.35


@dataclasses.dataclass(frozen=True)
class Truth:
    """A view with its exact depth: (H, W) float32 z in metres, inf where nothing is seen."""

    view: View
    depth: np.ndarray


def points_from_depth(
    K: np.ndarray,
    cam_from_world: np.ndarray,
    depth: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
) -> np.ndarray:
    """(N, 3) points_in_world seen at pixel centres (rows, cols) with finite ``depth``."""
    z = depth[rows, cols]
    seen = np.isfinite(z)
    pixels = np.stack([cols[seen] + 0.5, rows[seen] + 0.5, np.ones(int(seen.sum()))])
    points_in_cam = (np.linalg.inv(K) @ pixels) * z[seen]
    R, t = cam_from_world[:, :3], cam_from_world[:, 3]
    return (R.T @ (points_in_cam - t[:, None])).T


def depth_seen(truth: Truth, points_in_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N,) depth of each point in the view, (N,) true depth at its pixel, NaN outside)."""
    R, t = truth.view.cam_from_world[:, :3], truth.view.cam_from_world[:, 3]
    points_in_cam = points_in_world @ R.T + t
    projected = points_in_cam @ truth.view.K.T
    z = points_in_cam[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        col = np.floor(projected[:, 0] / projected[:, 2])
        row = np.floor(projected[:, 1] / projected[:, 2])
    h, w = truth.depth.shape
    inside = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    seen = np.full(len(z), np.nan)
    seen[inside] = truth.depth[row[inside].astype(int), col[inside].astype(int)]
    return z, seen


def visible_in(truth: Truth, points_in_world: np.ndarray, tol: float = 0.005) -> np.ndarray:
    """(N,) whether each point is the surface the view sees (not occluded, inside the image)."""
    z, seen = depth_seen(truth, points_in_world)
    return np.abs(z - seen) <= tol * z


def overlap_mask(ref: Truth, src: Truth) -> np.ndarray:
    """(H, W) pixels of ``ref`` whose surface point ``src`` sees too."""
    h, w = ref.depth.shape
    rows, cols = (a.ravel() for a in np.mgrid[0:h, 0:w])
    finite = np.isfinite(ref.depth[rows, cols])
    points = points_from_depth(ref.view.K, ref.view.cam_from_world, ref.depth, rows, cols)
    mask = np.zeros(h * w, dtype=bool)
    mask[np.flatnonzero(finite)] = visible_in(src, points)
    return mask.reshape(h, w)


def relative_errors(depth: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(M,) signed (estimate - truth) / truth over pixels where both are finite."""
    both = np.isfinite(depth) & np.isfinite(truth)
    return (depth[both] - truth[both]) / truth[both]


def distance_to_scene(points_in_world: np.ndarray) -> np.ndarray:
    """(N,) distance of each point to the nearest face of the synthetic scene, metres."""
    best = np.full(len(points_in_world), np.inf)
    for quad in scene_quads():
        offset = points_in_world - quad.origin
        u = np.clip(offset @ quad.edge_u / (quad.edge_u @ quad.edge_u), 0, 1)
        v = np.clip(offset @ quad.edge_v / (quad.edge_v @ quad.edge_v), 0, 1)
        nearest = u[:, None] * quad.edge_u + v[:, None] * quad.edge_v
        best = np.minimum(best, np.linalg.norm(offset - nearest, axis=1))
    return best


def scene_truths(scene: SyntheticScene, seed: int = 0) -> list[Truth]:
    """Views with sparse points, as COLMAP would give them: a common set of surface points
    (random pixels of every view) of which each view lists those it sees, rows shared exactly.
    """
    rng = np.random.default_rng(seed)
    h, w = scene.config.height, scene.config.width
    points = np.concatenate(
        [
            points_from_depth(
                scene.K,
                v.cam_from_world,
                v.depth,
                rng.integers(0, h, 1500),
                rng.integers(0, w, 1500),
            )
            for v in scene.views
        ]
    )
    truths = []
    for v in scene.views:
        bare = Truth(
            View(v.name, scene.K, v.cam_from_world, v.image_rgb[:, :, ::-1].copy()), v.depth
        )
        seen = points[visible_in(bare, points)]
        truths.append(Truth(dataclasses.replace(bare.view, points_in_world=seen), v.depth))
    return truths


@pytest.fixture(scope="module")
def scene() -> SyntheticScene:
    return render_scene(SCENE_CONFIG)


@pytest.fixture(scope="module")
def truths(scene: SyntheticScene) -> list[Truth]:
    return scene_truths(scene)


@pytest.fixture(scope="module")
def extra(scene: SyntheticScene) -> dict[str, Truth]:
    """View 2's camera moved up (vertical baseline) and to its left (source left of the ref)."""
    quads = scene_quads()
    textures = scene_textures(SCENE_CONFIG, quads)
    base = scene.views[2].cam_from_world
    R, t = base[:, :3], base[:, 3]
    centre = -R.T @ t
    out = {}
    for name, moved in (
        ("above", centre + [0.0, 0.0, EXTRA_OFFSET_M]),
        ("left", centre - EXTRA_OFFSET_M * R[0]),
    ):
        cam = np.column_stack([R, -R @ moved])
        image, depth = render_view(
            quads,
            textures,
            scene.K,
            cam,
            SCENE_CONFIG.width,
            SCENE_CONFIG.height,
            SCENE_CONFIG.supersample,
        )
        out[name] = Truth(View(name, scene.K, cam, image[:, :, ::-1].copy()), depth)
    return out


# (ref, src) by name: consecutive arc views in both orders (the reverse puts the source on the
# other side and turns the rectified images by 180 degrees), then the constructed cases.
CASES = ("arc-1-2", "arc-2-1", "src-above", "src-left")


def case_pair(name: str, truths: list[Truth], extra: dict[str, Truth]) -> tuple[Truth, Truth]:
    return {
        "arc-1-2": (truths[1], truths[2]),
        "arc-2-1": (truths[2], truths[1]),
        "src-above": (truths[2], extra["above"]),
        "src-left": (truths[2], extra["left"]),
    }[name]


def test_constructed_cases_are_what_they_claim(truths: list[Truth], extra: dict[str, Truth]):
    R = truths[2].view.cam_from_world[:, :3]
    for name, (dominant, sign) in {"above": (1, -1), "left": (0, -1)}.items():
        # The source's centre in the reference camera's frame (x right, y down).
        offset = R @ (extra[name].view.center_in_world - truths[2].view.center_in_world)
        assert np.argmax(np.abs(offset)) == dominant
        assert np.sign(offset[dominant]) == sign


@pytest.mark.parametrize("case", CASES)
def test_rectification_aligns_rows_and_round_trips_depth(
    case: str, truths: list[Truth], extra: dict[str, Truth]
):
    ref, src = case_pair(case, truths, extra)
    config = StereoConfig()
    rect = stereo._rectify(ref.view, src.view, config)
    assert rect is not None
    rng = np.random.default_rng(1)
    h, w = ref.depth.shape
    rows, cols = rng.integers(0, h, 4000), rng.integers(0, w, 4000)
    finite = np.isfinite(ref.depth[rows, cols])
    rows, cols = rows[finite], cols[finite]
    points = points_from_depth(ref.view.K, ref.view.cam_from_world, ref.depth, rows, cols)
    both = visible_in(src, points)
    rows, cols, points = rows[both], cols[both], points[both]
    # Where the source sees each point, in OpenCV pixel coordinates (COLMAP's minus 0.5).
    R, t = src.view.cam_from_world[:, :3], src.view.cam_from_world[:, 3]
    projected = (points @ R.T + t) @ src.view.K.T
    src_px = np.stack(
        [
            projected[:, 0] / projected[:, 2] - 0.5,
            projected[:, 1] / projected[:, 2] - 0.5,
            np.ones(len(points)),
        ]
    )
    ref_px = np.stack([cols, rows, np.ones(len(rows))]).astype(float)
    on_ref = rect.ref_to_canvas @ ref_px
    on_src = rect.src_to_canvas @ src_px
    on_ref, on_src = on_ref[:2] / on_ref[2], on_src[:2] / on_src[2]
    # Epipolar lines are rows, and the source is to the right: positive disparity.
    np.testing.assert_allclose(on_ref[1], on_src[1], atol=1e-6)
    canvas_disparity = on_ref[0] - on_src[0]
    assert canvas_disparity.min() > 0
    # Disparity -> depth is the exact inverse, on the unrectified reference grid.
    q_z = (rect.ref_to_canvas @ ref_px)[2]
    depth = rect.focal * rect.baseline / (canvas_disparity + rect.offset) / q_z
    np.testing.assert_allclose(depth, ref.depth[rows, cols], rtol=1e-9)
    # The search covers the scene: from the sparse points where known, else 0..256.
    inside = (canvas_disparity >= 0) & (canvas_disparity < rect.num_disparities)
    assert inside.mean() > 0.99


def test_sparse_points_narrow_the_search(truths: list[Truth]):
    config = StereoConfig()
    bare = [dataclasses.replace(t.view, points_in_world=None) for t in truths[1:3]]
    narrow = stereo._rectify(truths[1].view, truths[2].view, config)
    wide = stereo._rectify(bare[0], bare[1], config)
    assert narrow is not None and wide is not None
    assert narrow.offset > 0 and wide.offset == 0
    assert narrow.num_disparities % 16 == 0
    assert narrow.num_disparities < wide.num_disparities


@pytest.fixture(scope="module")
def case_depths(
    truths: list[Truth], extra: dict[str, Truth]
) -> dict[str, tuple[DepthMap, DepthMap]]:
    config = StereoConfig()
    out = {}
    for case in CASES:
        ref, src = case_pair(case, truths, extra)
        out[case] = depths_from_pair(ref.view, src.view, config, ref_index=0, src_index=1)
    return out


@pytest.mark.parametrize("case", CASES)
def test_depths_from_pair_match_truth(
    case: str,
    truths: list[Truth],
    extra: dict[str, Truth],
    case_depths: dict[str, tuple[DepthMap, DepthMap]],
):
    ref, src = case_pair(case, truths, extra)
    for estimate, view, other in zip(case_depths[case], (ref, src), (src, ref), strict=True):
        assert estimate.depth.shape == view.depth.shape and estimate.depth.dtype == np.float32
        errors = relative_errors(estimate.depth, view.depth)
        assert np.median(np.abs(errors)) < 0.005
        assert abs(np.median(errors)) < 0.002  # no bias (a half-pixel slip would show)
        assert np.mean(np.abs(errors) > 0.05) < 0.02
        overlap = overlap_mask(view, other)
        assert np.isfinite(estimate.depth[overlap]).mean() > 0.6
        # Pixels the other camera cannot see at all get no depth.
        assert np.isfinite(estimate.depth[~overlap]).mean() < 0.1
    assert (case_depths[case][0].view, case_depths[case][0].source) == (0, 1)
    assert (case_depths[case][1].view, case_depths[case][1].source) == (1, 0)


def test_the_backends_pair_task_gives_both_maps_of_its_pair(truths: list[Truth]):
    # `cpu-stereo` runs each pair as this task (in process or on Dask): its maps are the pair's
    # own, labelled with the views' indices in the list.
    config = StereoConfig()
    views = [t.view for t in truths]
    ref_map, src_map = stereo_pair_depths((1, 2), views, config)
    both = depths_from_pair(views[1], views[2], config, ref_index=1, src_index=2)
    assert (ref_map.view, ref_map.source, src_map.view, src_map.source) == (1, 2, 2, 1)
    np.testing.assert_array_equal(ref_map.depth, both[0].depth)
    np.testing.assert_array_equal(src_map.depth, both[1].depth)


def test_left_right_check_removes_occlusion_errors(truths: list[Truth]):
    def gross_error_fraction(config: StereoConfig) -> float:
        errors = []
        views = [t.view for t in truths]
        for i in (2, 3):
            estimate, _ = stereo_pair_depths((i, i + 1), views, config)
            errors.append(relative_errors(estimate.depth, truths[i].depth))
        return float(np.mean(np.abs(np.concatenate(errors)) > 0.05))

    checked = gross_error_fraction(StereoConfig())
    unchecked = gross_error_fraction(StereoConfig(lr_max_diff_px=None))
    assert checked < 0.015
    # The gross errors are occlusions and mismatches that only the check removes.
    assert unchecked > 1.5 * checked


def test_backproject_true_depth_lies_on_the_scene(truths: list[Truth]):
    # How fusion turns depth maps into points (fused colours: tests/recon/dense/test_fusion.py).
    truth = truths[3]
    rows, cols = np.nonzero(np.isfinite(truth.depth))
    points = backproject_pixels(truth.view, rows, cols, truth.depth[rows, cols])
    assert points.shape == (len(rows), 3)
    # Exact at pixel centres: a +-0.5 px slip would put points centimetres off the faces.
    assert np.quantile(distance_to_scene(points), 0.999) < 1e-3


def test_backproject_estimate_lies_on_the_scene(
    truths: list[Truth], case_depths: dict[str, tuple[DepthMap, DepthMap]]
):
    estimate = case_depths["arc-1-2"][0]
    rows, cols = np.nonzero(np.isfinite(estimate.depth))
    depth = estimate.depth[rows, cols]
    points = backproject_pixels(truths[1].view, rows, cols, depth)
    assert np.mean(distance_to_scene(points) < 0.01 * depth) > 0.95


def true_triangulation_deg(a: Truth, b: Truth) -> float:
    """Median angle at a's visible surface points (that b sees too) between the two rays."""
    h, w = a.depth.shape
    rows, cols = (x.ravel() for x in np.mgrid[0:h:8, 0:w:8])
    points = points_from_depth(a.view.K, a.view.cam_from_world, a.depth, rows, cols)
    points = points[visible_in(b, points)]
    ray_a = a.view.center_in_world - points
    ray_b = b.view.center_in_world - points
    cos = np.sum(ray_a * ray_b, 1) / np.linalg.norm(ray_a, axis=1) / np.linalg.norm(ray_b, axis=1)
    return float(np.degrees(np.median(np.arccos(np.clip(cos, -1, 1)))))


@pytest.mark.parametrize("with_points", [True, False])
def test_select_pairs_picks_neighbours_within_angle_limits(truths: list[Truth], with_points: bool):
    views = [
        t.view if with_points else dataclasses.replace(t.view, points_in_world=None) for t in truths
    ]
    config = StereoConfig()
    pairs = select_pairs(views, config)
    assert pairs == sorted(set(pairs)) and all(i < j for i, j in pairs)
    # Every view is paired, with arc neighbours only (views 20 degrees apart; 2 apart is 40).
    assert {i for pair in pairs for i in pair} == set(range(len(views)))
    assert all(j - i <= 2 for i, j in pairs)
    for i, j in pairs:
        angle = true_triangulation_deg(truths[i], truths[j])
        assert (
            config.min_triangulation_angle_deg - 2
            <= angle
            <= config.max_triangulation_angle_deg + 2
        )
    # Each view picked at most max_pairs_per_view partners; the union may give it one more.
    degree = np.bincount(np.ravel(pairs), minlength=len(views))
    assert degree.max() <= 2 * config.max_pairs_per_view
    # Deterministic, and independent of the order of the views.
    assert select_pairs(views, config) == pairs
    n = len(views)
    reversed_pairs = select_pairs(views[::-1], config)
    assert sorted((n - 1 - j, n - 1 - i) for i, j in reversed_pairs) == pairs
    # The angle limits are honoured: 20 degrees apart is outside [3, 10] and [30, 40].
    assert select_pairs(views, StereoConfig(max_triangulation_angle_deg=10.0)) == []
    assert all(
        j - i >= 2 for i, j in select_pairs(views, StereoConfig(min_triangulation_angle_deg=30.0))
    )


def test_select_pairs_never_pairs_an_opposite_view(truths: list[Truth]):
    views = [dataclasses.replace(t.view, points_in_world=None) for t in truths]
    # View 0 turned round about the vertical axis through the room centre: it faces the other
    # cameras across the room.
    half_turn = np.diag([-1.0, -1.0, 1.0])
    cam = views[0].cam_from_world
    opposite = View(
        "opposite",
        views[0].K,
        np.column_stack([cam[:, :3] @ half_turn, cam[:, 3]]),
        views[0].image_bgr,
    )
    assert np.dot(opposite.axis_in_world, views[0].axis_in_world) < 0
    pairs = select_pairs([*views, opposite], StereoConfig())
    assert all(len(views) not in pair for pair in pairs)
    assert pairs == select_pairs(views, StereoConfig())


def test_pairs_without_stereo_give_empty_maps(truths: list[Truth]):
    ref = truths[1].view
    # A camera beside view 1 turned 90 degrees about the vertical: no common rectification.
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    R = ref.cam_from_world[:, :3] @ quarter
    centre = ref.center_in_world + [0.3, 0.0, 0.0]
    turned = View("turned", ref.K, np.column_stack([R, -R @ centre]), ref.image_bgr)
    # The same camera twice: no baseline.
    same = View("same", ref.K, ref.cam_from_world, ref.image_bgr)
    for src in (turned, same):
        assert stereo._rectify(ref, src, StereoConfig()) is None
        ref_map, src_map = depths_from_pair(ref, src, StereoConfig(), ref_index=1, src_index=9)
        assert ref_map.depth.shape == ref.image_bgr.shape[:2]
        assert np.isnan(ref_map.depth).all() and np.isnan(src_map.depth).all()


def test_config_and_view_validation(truths: list[Truth]):
    with pytest.raises(ValueError, match="block_size"):
        StereoConfig(block_size=4)
    with pytest.raises(ValueError, match="min_depth"):
        StereoConfig(min_depth=5.0, max_depth=2.0)
    with pytest.raises(ValueError, match="depth_percentiles"):
        StereoConfig(depth_percentiles=(90.0, 10.0))
    with pytest.raises(ValueError, match="image_bgr"):
        View("grey", truths[0].view.K, truths[0].view.cam_from_world, truths[0].depth)
    for f in dataclasses.fields(StereoConfig):
        assert f.metadata.get("help"), f.name


def test_explicit_depth_range_limits_the_search(truths: list[Truth]):
    bare = [dataclasses.replace(t.view, points_in_world=None) for t in truths[1:3]]
    config = StereoConfig(min_depth=1.0, max_depth=8.0)
    rect = stereo._rectify(bare[0], bare[1], config)
    assert rect is not None
    focal_baseline = rect.focal * rect.baseline
    # The searched disparities cover depths 1..8 m at every pixel (rectified depth differs from
    # the view's by the rectifying rotation, at most a few tens of percent here).
    assert rect.offset <= focal_baseline / 8.0
    assert rect.offset + rect.num_disparities >= focal_baseline / 1.0
    assert math.isfinite(rect.baseline) and rect.num_disparities <= config.max_num_disparities


def test_disparity_to_view_grid_interpolates_but_not_across_depth_edges():
    # A canvas shifted by half a pixel from the view: every view pixel samples between two
    # canvas pixels. Left half at disparity 10, right half at 20.
    canvas = np.full((6, 12), 10.0, dtype=np.float32)
    canvas[:, 6:] = 20.0
    canvas[:, 9] = 21.0  # a 1-px bump: interpolated, not an edge
    rect = stereo._Rectification(
        ref_to_canvas=np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        src_to_canvas=np.eye(3),
        canvas_size=(12, 6),
        focal=100.0,
        baseline=2.0,
        offset=4,
        num_disparities=16,
    )
    depth = stereo._to_view_grid(canvas, rect.ref_to_canvas, (12, 6), rect)
    # View pixel x samples canvas x + 0.5: pixels 0-4 are inside the left half, 5 straddles
    # the jump (15 would be a point floating between the two surfaces), 8 and 9 straddle the
    # bump (disparity 20.5, plus the offset 4), 11 reaches beyond the canvas.
    expected_disparity = np.array([10, 10, 10, 10, 10, np.nan, 20, 20, 20.5, 20.5, 20, np.nan])
    expected_disparity += 4
    expected = (100.0 * 2.0 / expected_disparity).astype(np.float32)
    np.testing.assert_allclose(depth[2], expected, rtol=1e-6)
