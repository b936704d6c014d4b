"""The XOR silhouette energy: zero at the true pose, growing with a limb's error, consistent
across pyramid levels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tracking.body.model import BodyModel, BodyShape, Pose
from tracking.rig.cameras import ring_cameras
from tracking.track.energy import SilhouetteEnergy, XorCount, downsample_mask, iou
from tracking.track.render import CpuRasterRenderer

TRUE_POSE = {"l_shoulder_rz": 0.3, "r_knee_flex": 0.5, "r_hip_rx": -0.4, "root_ry": 0.3}


@pytest.fixture(scope="module")
def setup():
    model = BodyModel(BodyShape.default())
    cameras = ring_cameras(4, 3.0, 0.0, (0.0, 0.0, 0.0), 640, 480, 600.0)
    renderer = CpuRasterRenderer(CpuRasterRenderer.Options())
    truth = Pose.from_dict(TRUE_POSE)
    vertices = model.posed_vertices(truth)
    masks = [renderer.render(vertices, model.faces, c) for c in cameras]
    return model, cameras, masks, renderer, truth


def _arm_raised_by(deg: float) -> Pose:
    return Pose.from_dict({**TRUE_POSE, "l_shoulder_rz": TRUE_POSE["l_shoulder_rz"]
                           + math.radians(deg)})


def test_iou_and_downsampling_rules():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    assert iou(a, b) == 1.0
    a[:2, :2] = True
    b[:2, :] = True
    assert iou(a, b) == pytest.approx(4 / 8)
    with pytest.raises(ValueError, match="shape"):
        iou(a, np.zeros((2, 2), bool))
    # A coarse pixel is foreground when at least half of its block was: 2 of 4 yes, 1 of 4 no.
    fine = np.zeros((4, 4), bool)
    fine[0, 0:2] = True  # block (0, 0): 2 of 4
    fine[2, 2] = True  # block (1, 1): 1 of 4
    np.testing.assert_array_equal(downsample_mask(fine, 2, 2), [[True, False], [False, False]])


def test_energy_is_zero_at_the_pose_that_made_the_masks(setup):
    model, cameras, masks, renderer, truth = setup
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=3)
    assert energy(truth) == 0.0
    assert all(not x.any() for x in energy.xor_masks(truth))
    # Masks from another renderer (the ray caster) give 0 too: they agree pixel for pixel.
    raycast_energy = SilhouetteEnergy(model, cameras, masks, "open3d-raycast", levels=1)
    assert raycast_energy(truth) == 0.0


def test_energy_grows_with_the_error_of_a_limb_at_every_level(setup):
    model, cameras, masks, renderer, truth = setup
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=3)
    silhouette_px = sum(int(m.sum()) for m in masks)
    for level in range(3):
        floor = energy(truth, level)
        values = [energy(_arm_raised_by(deg), level) for deg in (3, 10, 25, 50)]
        assert floor < values[0], level
        assert all(b > a for a, b in zip(values, values[1:], strict=False)), (level, values)
        # A 50 degree error of one arm is a few percent of the four silhouettes, not noise.
        assert values[-1] - floor > 0.05 * silhouette_px, (level, values)


def test_pyramid_levels_agree_in_full_resolution_pixels(setup):
    """Levels are comparable: E_l ~ E_0 up to the level's own floor (its value at the true
    pose, from thresholding half-covered coarse pixels), and the floors are small."""
    model, cameras, masks, renderer, truth = setup
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=3)
    silhouette_px = sum(int(m.sum()) for m in masks)
    for level in (1, 2):
        floor = energy(truth, level)
        # Level 1 is the worst: a 2x2 block half covered (half of all blocks along an edge
        # parallel to the pixel grid) cannot say on which side its centre lies.
        assert floor < (0.05 if level == 1 else 0.03) * silhouette_px
        for deg in (10, 25, 50):
            pose = _arm_raised_by(deg)
            e0, el = energy(pose, 0), energy(pose, level)
            assert abs(el - e0) <= floor + 0.1 * e0, (level, deg, e0, el)


def test_counters_shapes_and_units(setup):
    model, cameras, masks, renderer, truth = setup
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=3)
    pose = _arm_raised_by(20)
    xors = energy.xor_masks(pose, level=2)
    assert [x.shape for x in xors] == [(120, 160)] * 4
    assert energy.evaluations == 0  # display helpers do not count
    total = energy(pose, level=2)
    assert energy.evaluations == 1
    assert total == pytest.approx(16 * sum(int(x.sum()) for x in xors))
    assert total == pytest.approx(energy.per_view(pose, 2).sum())
    assert [m.shape for m in energy.masks[1]] == [(240, 320)] * 4
    with pytest.raises(ValueError, match="level"):
        energy(pose, level=3)


def test_odd_image_sizes_use_the_exact_area_ratio(setup):
    model, _, _, renderer, truth = setup
    cameras = ring_cameras(2, 3.0, 0.0, (0.0, 0.0, 0.0), 641, 481, 600.0)
    vertices = model.posed_vertices(truth)
    masks = [renderer.render(vertices, model.faces, c) for c in cameras]
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=2)
    pose = _arm_raised_by(30)
    ratio = (641 * 481) / (320 * 240)
    assert energy(pose, 1) == pytest.approx(ratio * sum(int(x.sum())
                                                        for x in energy.xor_masks(pose, 1)))


def test_bad_inputs_are_refused(setup):
    model, cameras, masks, renderer, _ = setup
    with pytest.raises(ValueError, match="one mask per camera"):
        SilhouetteEnergy(model, cameras, masks[:2], renderer)
    with pytest.raises(ValueError, match="mask of camera cam00"):
        SilhouetteEnergy(model, cameras, [m[:, :10] for m in masks], renderer)
    with pytest.raises(ValueError, match="below 8 px"):
        SilhouetteEnergy(model, cameras, masks, renderer, levels=8)


def test_unknown_pixels_count_in_no_xor():
    cameras = ring_cameras(2, 3.0, 1.2, (0.0, 0.9, 0.0), 160, 120, 170.0)
    model = BodyModel(BodyShape.default(1.75))
    pose = Pose.from_dict({"root_ty": 0.95})
    masks = [np.zeros((120, 160), bool), np.zeros((120, 160), bool)]  # nothing seen
    known = [np.ones((120, 160), bool), None]
    known[0][:, 80:] = False  # the right half of view 0 cannot tell
    full = SilhouetteEnergy(model, cameras, masks, "cpu-raster", levels=2)
    part = SilhouetteEnergy(model, cameras, masks, "cpu-raster", levels=2, known=known)
    drawn = full.model_masks(pose, 0)
    # All XOR is the model itself; with view 0's right half unknown only its left half counts.
    assert full.per_view(pose, 0)[0] == drawn[0].sum()
    assert part.per_view(pose, 0)[0] == drawn[0][:, :80].sum() < drawn[0].sum()
    assert part.per_view(pose, 0)[1] == full.per_view(pose, 0)[1]
    assert part.known[1][0].shape == (60, 80) and part.known[1][1] is None
    assert part(pose, 1) < full(pose, 1)


@pytest.mark.parametrize("renderer_name", ["cpu-raster", "open3d-raycast"])
def test_the_xor_counted_without_drawing_equals_the_drawn_xor(setup, renderer_name):
    """`XorCount` (the mesh's covered pixels summed, not drawn: what the energy and the
    tracker's stages count) gives the integers of the drawn masks' XOR, with a static part
    and unknown pixels, pose after pose, two counters in turn, for the compiled renderer
    and for one that draws."""
    from plugins.registry import create

    model, cameras, masks, _, truth = setup
    renderer = create("renderer", renderer_name)
    rng = np.random.default_rng(3)
    known = [rng.random(m.shape) > 0.1 for m in masks]
    moving = model.faces_moved_by(np.isin(np.arange(16), [8, 9, 10]))  # some limb's nodes
    assert 0 < moving.sum() < len(model.faces)
    static = [renderer.render(model.posed_vertices(truth), model.faces[~moving], c)
              for c in cameras]  # fmt: skip
    count = XorCount(renderer, cameras, masks, known, static)
    whole = XorCount(renderer, cameras, masks, known)
    for k in range(4):
        pose = Pose(truth.params + rng.normal(0.0, 0.15, truth.params.shape) * (k > 0))
        vertices = model.posed_vertices(pose)
        drawn = [renderer.render(vertices, model.faces[moving], c) for c in cameras]
        expected = [np.count_nonzero(((s | d) ^ m) & kn)
                    for s, d, m, kn in zip(static, drawn, masks, known, strict=True)]  # fmt: skip
        assert count.counts(vertices, model.faces[moving]).tolist() == expected
        drawn = [renderer.render(vertices, model.faces, c) for c in cameras]
        assert whole.counts(vertices, model.faces).tolist() == [
            np.count_nonzero((d ^ m) & kn) for d, m, kn in zip(drawn, masks, known, strict=True)]
    # The energy's own count (no static part) is its drawn XOR masks' count.
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=2, known=known)
    for level in (0, 1):
        drawn = [np.count_nonzero(x) for x in energy.xor_masks(_arm_raised_by(20), level)]
        assert np.array_equal(energy.per_view(_arm_raised_by(20), level),
                              np.array(drawn) * energy._pixel_area[level])
        assert sum(drawn) > 0


def test_missed_pixels_count_whatever_the_pose(setup):
    """`SilhouetteEnergy`'s missed pixels (the tracker's floor band): out of every view's XOR,
    and counted as missed whatever the pose, at every level: the energy is the one with them
    unknown plus their count, so it ranks poses as that one does, with the scale of counting
    them. A stage's counter (`XorCount` with a static part) counts them too."""
    model, cameras, masks, renderer, truth = setup
    rng = np.random.default_rng(5)
    missed = [m & (rng.random(m.shape) > 0.7) for m in masks]
    missed[2] = None
    plain = SilhouetteEnergy(model, cameras, masks, renderer, levels=2)
    known = [None if d is None else ~d for d in missed]
    unknown = SilhouetteEnergy(model, cameras, masks, renderer, levels=2, known=known)
    energy = SilhouetteEnergy(model, cameras, masks, renderer, levels=2, missed=missed)
    assert energy.missed[0].tolist() == [0 if d is None else d.sum() for d in missed]
    for level in (0, 1):
        extra = energy.missed[level] * energy._pixel_area[level]
        assert extra[0] > 0 and extra[2] == 0
        for deg in (0, 30):
            pose = _arm_raised_by(deg)
            assert np.array_equal(energy.per_view(pose, level),
                                  unknown.per_view(pose, level) + extra)
    # At the pose that made the masks: the missed pixels alone, where plain counts 0.
    assert plain(truth) == 0 and energy(truth) == sum(d.sum() for d in missed if d is not None)
    moving = model.faces_moved_by(np.isin(np.arange(16), [8, 9, 10]))
    static = [renderer.render(model.posed_vertices(truth), model.faces[~moving], c)
              for c in cameras]  # fmt: skip
    stage = XorCount(renderer, cameras, masks, energy.known[0], static, energy.missed[0])
    vertices = model.posed_vertices(truth)
    assert stage.counts(vertices, model.faces[moving]).sum() == energy(truth)


def test_the_xor_count_of_views_of_different_sizes(setup):
    """Views of several sizes share one padded array in the compiled count (`ViewGains`): each
    view's count is still its own drawn XOR, a mesh partly outside the smaller views
    included."""
    from recon.cameras import Camera

    model, cameras, _, renderer, truth = setup
    small = [Camera(f"small{i}", 320, 200, c.K * [[0.5], [0.5], [1]], c.cam_from_world)
             for i, c in enumerate(cameras[:2])]  # fmt: skip
    tall = Camera("tall", 300, 520, cameras[2].K + [[0, 0, -170], [0, 0, 20], [0, 0, 0]],
                  cameras[2].cam_from_world)  # fmt: skip
    views = [*small, tall, cameras[3]]
    vertices = model.posed_vertices(truth)
    masks = [renderer.render(vertices, model.faces, c) for c in views]
    count = XorCount(renderer, views, masks, [None] * len(views))
    assert count.views.stacked.shape == (4, 520, 640)
    for deg in (0, 25, 60):
        vertices = model.posed_vertices(_arm_raised_by(deg))
        drawn = [renderer.render(vertices, model.faces, c) for c in views]
        expected = [np.count_nonzero(d ^ m) for d, m in zip(drawn, masks, strict=True)]
        assert count.counts(vertices, model.faces).tolist() == expected
        assert (sum(expected) == 0) == (deg == 0)
    # The subject is cut by the edges of the smaller views: the padding counts nothing.
    assert any(m[:, -1].any() or m[-1].any() for m in masks[:2])
