"""Visual hulls and the multi-view consistency check (`tracking.silhouettes.hull`) against exact
balls."""

from __future__ import annotations

import numpy as np
import pytest

from recon.errors import UserError
from tests.tracking.rig.test_video import ball_masks
from tracking.rig.cameras import ring_cameras
from tracking.silhouettes.hull import (
    HullCheckConfig,
    consistent_silhouettes,
    floor_only,
    hull_diameter,
    hull_silhouettes,
    hull_surface_points,
    lowest_band_pixels,
    rays_meeting_point,
    surface_voxels,
    visual_hull,
)

CAMERAS = ring_cameras(4, 3.0, 1.5, width=320, height=240, focal_px=300.0)
CENTRE = np.array([0.1, 0.2, -0.15])


def test_the_visual_hull_of_a_ball_holds_the_ball():
    masks = ball_masks(CAMERAS, CENTRE, 0.3)
    np.testing.assert_allclose(rays_meeting_point(CAMERAS, masks), CENTRE, atol=0.02)
    points, n, occupied = visual_hull(CAMERAS, masks, size_m=1.2, voxel_m=0.03)
    distance = np.linalg.norm(points - CENTRE, axis=1)
    assert occupied[distance < 0.28].all()  # the ball is inside its hull
    # Four views carve a hull a little larger than the ball, never much larger.
    assert occupied.sum() * 0.03**3 < 1.6 * (4 / 3) * np.pi * 0.3**3
    surface = surface_voxels(occupied, n)
    assert surface.sum() < occupied.sum() and not surface[distance < 0.2].any()
    # What the tracker takes: the surface voxels' centres, made without the cube's.
    assert np.array_equal(hull_surface_points(CAMERAS, masks, size_m=1.2, voxel_m=0.03),
                          points[surface])


def disc_masks(cameras: list, centre: np.ndarray, half_x: float, half_z: float) -> list[np.ndarray]:
    """(H, W) bool truth per camera: the pixels whose ray meets a horizontal elliptic disc
    (world centre, half axes along x and z, metres): a shadow on the floor."""
    out = []
    for cam in cameras:
        rays = cam.pixel_rays_in_camera @ cam.R  # world directions
        origin = cam.center_in_world
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (centre[1] - origin[1]) / rays[..., 1]
        x = origin[0] + t * rays[..., 0] - centre[0]
        z = origin[2] + t * rays[..., 2] - centre[2]
        out.append((t > 0) & ((x / half_x) ** 2 + (z / half_z) ** 2 < 1))
    return out


SUITE_CAMERAS = ring_cameras(4, 4.0, 1.5, (0.0, 0.9, 0.0), 320, 240, 343.0)
"""The motion suite's ring (`mocap synth`'s: 4 m, 1.5 m up) at half its image size."""


@pytest.mark.parametrize("lift_m", [0.35, 0.1])
def test_the_lowest_band_holds_a_floor_shadow_and_not_the_body_above(lift_m):
    up = np.array([0.0, 1.0, 0.0])
    # A ball (the body) `lift_m` above a shadow on the floor (y = 0), which every view keeps.
    body = ball_masks(SUITE_CAMERAS, np.array([0.0, 0.2 + lift_m, 0.0]), 0.2)
    shadow = disc_masks(SUITE_CAMERAS, np.array([0.1, 0.0, 0.05]), 0.2, 0.1)
    masks = [b | s for b, s in zip(body, shadow, strict=True)]
    points = hull_surface_points(SUITE_CAMERAS, masks, size_m=2.0, voxel_m=0.03)
    band = lowest_band_pixels(SUITE_CAMERAS, masks, points, up, band_m=0.1, voxel_m=0.03)
    for b, ball, disc in zip(band, body, shadow, strict=True):
        assert not (b & ball).any() and not (b & ~disc).any()
        # Nearly all of the shadow's own pixels (measured 0.74-0.96; the rest under the
        # slab's upper voxels).
        assert (b & disc & ~ball).sum() > 0.65 * (disc & ~ball).sum()
    # The slab is under a gap: the start's fit leaves it out (`floor_only`), all of it.
    below = floor_only(points, up, band_m=0.1, voxel_m=0.03)
    assert below.any() and points[below, 1].max() < 0.05 < points[~below, 1].min()


def test_the_lowest_band_of_a_body_on_the_floor_is_a_sliver_of_it():
    up = np.array([0.0, 1.0, 0.0])
    # A ball on the floor, no shadow: only a sliver of its bottom's pixels (measured 5.9%
    # of its 870).
    resting = ball_masks(SUITE_CAMERAS, np.array([0.0, 0.2, 0.0]), 0.2)
    points = hull_surface_points(SUITE_CAMERAS, resting, size_m=2.0, voxel_m=0.03)
    band = lowest_band_pixels(SUITE_CAMERAS, resting, points, up, band_m=0.1, voxel_m=0.03)
    assert all(0 < b.sum() < 0.1 * m.sum() for b, m in zip(band, resting, strict=True))
    assert not floor_only(points, up, band_m=0.1, voxel_m=0.03).any()  # no gap
    # Standing on its shadow: the band holds the shadow and the ball's bottom, no gap.
    shadow = disc_masks(SUITE_CAMERAS, np.array([0.1, 0.0, 0.05]), 0.2, 0.1)
    masks = [b | d for b, d in zip(resting, shadow, strict=True)]
    points = hull_surface_points(SUITE_CAMERAS, masks, size_m=2.0, voxel_m=0.03)
    assert not floor_only(points, up, band_m=0.1, voxel_m=0.03).any()
    band = lowest_band_pixels(SUITE_CAMERAS, masks, points, up, band_m=0.1, voxel_m=0.03)
    assert all((b & s & ~m).sum() > 0.65 * (s & ~m).sum()
               for b, s, m in zip(band, shadow, resting, strict=True))  # fmt: skip
    # No band, no hull: no pixels.
    assert not any(b.any() for b in lowest_band_pixels(SUITE_CAMERAS, masks, points, up,
                                                       band_m=0.0, voxel_m=0.03))
    assert not any(b.any() for b in lowest_band_pixels(SUITE_CAMERAS, masks, np.empty((0, 3)),
                                                       up, band_m=0.1, voxel_m=0.03))


def test_the_hull_silhouettes_bound_what_a_model_can_reach():
    from tracking.track.energy import iou

    truth = ball_masks(CAMERAS, CENTRE, 0.3)
    exact = hull_silhouettes(CAMERAS, truth, size_m=1.2, voxel_m=0.01)
    # Consistent views: the hull's silhouettes are the ball's, up to the voxels (measured 0.94).
    assert min(iou(h, m) for h, m in zip(exact, truth, strict=True)) > 0.9
    # One view whose calibration is 20 px off (two fifths of the ball's width): the hull shrinks
    # to what all views agree on, and that view's bound drops (and the opposite view's, which
    # shares its horizontal axis; measured 0.62 and 0.65), the side views' far less (0.90,
    # 0.88).
    shifted = [m.copy() for m in truth]
    shifted[0] = np.roll(truth[0], 20, axis=1)
    bound = [iou(h, m) for h, m in zip(hull_silhouettes(CAMERAS, shifted, size_m=1.2,
                                                         voxel_m=0.01), shifted, strict=True)]
    assert bound[0] < 0.7 and bound[2] < 0.7 and min(bound[1], bound[3]) > 0.85
    # Unknown pixels do not carve: a view whose pixels are all unknown bounds nothing.
    unknown = [np.ones_like(shifted[0]), None, None, None]
    freed = hull_silhouettes(CAMERAS, shifted, size_m=1.2, voxel_m=0.01, unknown=unknown)
    assert min(iou(h, m) for h, m in zip(freed[1:], truth[1:], strict=True)) > 0.9


def test_the_check_removes_what_one_camera_alone_sees():
    truth = ball_masks(CAMERAS, CENTRE, 0.3)
    masks = [m.copy() for m in truth]
    masks[0][200:230, 20:80] = True  # a reflection on the floor, in one view only
    rows, cols = np.nonzero(truth[1])
    masks[1][rows.min():rows.max(), cols.max() + 1:cols.max() + 30] = True  # attached to it
    kept = consistent_silhouettes(CAMERAS, masks)
    for k, (got, want) in enumerate(zip(kept, truth, strict=True)):
        assert (got & want).sum() >= 0.99 * want.sum(), k  # the ball stays
    assert not kept[0][200:230, 20:80].any()
    # Of the attached blob, a sliver next to the ball is left: the rays there pass within the
    # four-view hull of a ball, larger than the ball (plus the dilation of 3 px here and the
    # voxels' size).
    extra = kept[1] & ~truth[1]
    assert extra.sum() < 0.25 * (masks[1] & ~truth[1]).sum()
    assert not extra[:, cols.max() + 15:].any()
    # Off, the masks come back as they are.
    off = consistent_silhouettes(CAMERAS, masks, HullCheckConfig(multi_view_check=False))
    assert all((a == b).all() for a, b in zip(off, masks, strict=True))


def test_with_one_miss_allowed_what_one_view_loses_stays_in_the_others():
    # cam00 loses the ball's lower half (the subject in its median background): with no miss
    # allowed, the check carries the loss into every other view; with one, they keep it, and
    # what one camera alone sees (a reflection) still goes.
    truth = ball_masks(CAMERAS, CENTRE, 0.3)
    masks = [m.copy() for m in truth]
    rows = np.nonzero(truth[0])[0]
    masks[0][(rows.min() + rows.max()) // 2:] = False
    masks[2][200:230, 20:80] = True
    strict = consistent_silhouettes(CAMERAS, masks)
    tolerant = consistent_silhouettes(CAMERAS, masks, HullCheckConfig(check_misses=1))
    lost = [1 - (strict[k] & truth[k]).sum() / truth[k].sum() for k in (1, 2, 3)]
    assert max(lost) > 0.1, lost
    for k in (1, 2, 3):
        assert (tolerant[k] & truth[k]).sum() >= 0.99 * truth[k].sum(), k
    assert not tolerant[2][200:230, 20:80].any()
    assert (tolerant[0] == masks[0] & tolerant[0]).all()  # a check only removes


def test_a_subject_outside_one_view_or_empty_in_one_is_kept_in_the_others():
    # Out of the fields of view of cam00 and cam01: the two others still confirm each other.
    truth = ball_masks(CAMERAS, np.array([1.5, 0.0, 1.5]), 0.3)
    assert not truth[0].any() and not truth[1].any() and truth[2].any() and truth[3].any()
    kept = consistent_silhouettes(CAMERAS, truth)
    for got, want in zip(kept[2:], truth[2:], strict=True):
        assert (got & want).sum() >= 0.99 * want.sum()
    # One view's segmentation failed (empty): it takes no part, the others stay.
    masks = ball_masks(CAMERAS, CENTRE, 0.3)
    masks[2] = np.zeros_like(masks[2])
    kept = consistent_silhouettes(CAMERAS, masks)
    assert not kept[2].any()
    for k in (0, 1, 3):
        assert (kept[k] & masks[k]).sum() >= 0.99 * masks[k].sum()


def test_bad_check_settings_are_one_line_errors():
    for kwargs, match in (({"check_tolerance": 0.6}, "check-tolerance"),
                          ({"check_voxel_m": 0.0}, "check-voxel-m"),
                          ({"check_size_m": 0.05}, "exceed two voxels"),
                          ({"check_size_m": 100.0, "check_voxel_m": 0.01}, "million voxels")):
        with pytest.raises(UserError, match=match):
            HullCheckConfig(**kwargs)


def test_pixels_of_unknown_background_do_not_carve():
    # cam01 cannot tell its left half (say its background photo shows a person there): its
    # silhouette misses the ball's part there. Told so, the check keeps the ball whole in the
    # other views; not told, that half of cam01 carves away what the others see behind it.
    truth = ball_masks(CAMERAS, CENTRE, 0.3)
    masks = [m.copy() for m in truth]
    rows, cols = np.nonzero(truth[1])
    middle = int(np.median(cols))
    masks[1][:, :middle] = False  # the ball's left half lost
    unknown: list[np.ndarray | None] = [None] * len(CAMERAS)
    unknown[1] = np.zeros_like(truth[1])
    unknown[1][:, :middle] = True
    told = consistent_silhouettes(CAMERAS, masks, unknown=unknown)
    blind = consistent_silhouettes(CAMERAS, masks)
    for k in (0, 2, 3):
        assert (told[k] & truth[k]).sum() >= 0.99 * truth[k].sum()
    assert min((blind[k] & truth[k]).sum() / truth[k].sum() for k in (0, 2, 3)) < 0.9
    assert (told[1] == masks[1]).all()  # cam01's known half is confirmed by the others


@pytest.mark.parametrize("seed", range(6))
def test_the_coarse_to_fine_candidates_carve_the_very_hull_of_the_whole_cube(seed: int):
    """hull_candidates skips blocks of voxels; carving what is left must equal carving every
    voxel of the cube, on scenes with distortion (barrel and pincushion), a content box, stray
    blobs, an empty view and unknown pixels."""
    import dataclasses

    import cv2

    from tracking.silhouettes.hull import carve, hull_candidates, voxel_centres

    rng = np.random.default_rng(seed)
    cameras = [dataclasses.replace(c, dist=np.array([k1, 0.02, 0.0, 0.0, 0.0]))
               for c, k1 in zip(ring_cameras(4, 2.5, 1.2, width=320, height=240,
                                             focal_px=220.0 + 60 * seed),
                                rng.uniform(-0.25, 0.25, 4), strict=True)]
    masks = ball_masks(cameras, CENTRE + rng.normal(0, 0.2, 3), 0.35)
    for mask in masks:  # stray blobs one view alone sees
        for _ in range(3):
            x, y = rng.integers(0, 320), rng.integers(0, 240)
            cv2.circle(mask.view(np.uint8), (int(x), int(y)), int(rng.integers(3, 20)), 1, -1)
    unknown = [None, (rng.random((240, 320)) < 0.002), None, None]
    if seed % 3 == 0:
        masks[3][:] = False  # an empty view takes no part
    boxes = [None, (10, 5, 300, 230), None, (0, 0, 320, 200)]
    centre = CENTRE + rng.normal(0, 0.1, 3)
    for settings in ({}, {"dilate_px": 7, "boxes": boxes, "min_views": 2, "unknown": unknown},
                     {"dilate_px": 3, "boxes": boxes, "min_views": 3, "misses": 1}):
        points, _ = voxel_centres(centre, 2.0, 0.04)
        full, _ = carve(cameras, masks, points, **settings)
        candidates, index = hull_candidates(cameras, masks, centre, 2.0, 0.04, **settings)
        np.testing.assert_array_equal(candidates, points[index])
        kept, _ = carve(cameras, masks, candidates, **settings)
        assert full.any() and len(index) < 0.5 * len(points)
        np.testing.assert_array_equal(np.flatnonzero(full), index[kept])


def test_hull_diameter_is_the_largest_distance_between_two_points():
    """Against every pair (scipy's pdist), on a cloud, a flat set (no convex hull: all
    points) and a single point."""
    from scipy.spatial.distance import pdist

    cloud = np.random.default_rng(3).normal(size=(500, 3)) * [0.2, 0.8, 0.15]
    assert hull_diameter(cloud) == pytest.approx(pdist(cloud).max())
    flat = np.c_[np.random.default_rng(4).random((50, 2)), np.zeros(50)]
    assert hull_diameter(flat) == pytest.approx(pdist(flat).max())
    assert hull_diameter(np.zeros((1, 3))) == 0.0
