"""Silhouettes: a synthetic scene with known foreground and shadow, the temporal-median
background, CDnet scoring against hand counts, and bad input (CDnet highway itself:
test_cdnet.py, through the step)."""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np
import pytest

from tracking.silhouettes.subtraction import (
    BackgroundModel,
    Counts,
    Label,
    SilhouetteConfig,
    _free_median,
    classify,
    component_hulls,
    confusion_counts,
    f_measure,
    foreground_mask,
    silhouette_from_frame,
)

H, W = 120, 160
NOISE = 2.0  # grey levels per channel and frame, a decent camera's sensor noise
SHADOW_BRIGHTNESS = 0.75  # a soft indoor shadow keeps 75% of the light


def _background(rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) float32 textured background in [90, 230]: smooth blotches plus fine grain."""
    coarse = cv2.resize(rng.uniform(0, 1, (12, 16, 3)).astype(np.float32), (W, H),
                        interpolation=cv2.INTER_CUBIC)  # fmt: skip
    fine = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    return 90 + 140 * np.clip(0.7 * coarse + 0.3 * fine, 0, 1)


def _noisy(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.clip(np.rint(image + rng.normal(0, NOISE, image.shape)), 0, 255).astype(np.uint8)


def _ellipse(center: tuple[int, int], axes: tuple[int, int]) -> np.ndarray:
    mask = np.zeros((H, W), np.uint8)
    cv2.ellipse(mask, center, axes, 0, 0, 360, 1, -1)
    return mask.astype(bool)


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(background (H, W, 3) float32, frame (H, W, 3) uint8, person mask, shadow mask).

    The "person" is an upright ellipse in a saturated colour with its own texture; its shadow
    falls on the floor beside it, not overlapping it (a shadow under the person would be
    hidden by it anyway).
    """
    background = _background(rng)
    person = _ellipse((70, 60), (16, 40))
    shadow = _ellipse((115, 95), (30, 10)) & ~person
    image = background.copy()
    image[shadow] *= SHADOW_BRIGHTNESS
    clothes = np.array([40.0, 150.0, 230.0]) + rng.uniform(-15, 15, (int(person.sum()), 3))
    image[person] = clothes
    return background, _noisy(image, rng), person, shadow


def _background_model(background: np.ndarray, rng: np.random.Generator) -> BackgroundModel:
    return BackgroundModel.from_frames([_noisy(background, rng) for _ in range(20)])


# ----------------------------------------------------------------------------- synthetic scene


def test_background_model_recovers_mean_and_noise() -> None:
    rng = np.random.default_rng(0)
    background = _background(rng)
    model = _background_model(background, rng)
    assert model.shape == (H, W, 3)
    assert model.mean.dtype == np.float32 and model.std.dtype == np.float32
    # 20 frames: the mean is within ~NOISE / sqrt(20) ~ 0.45 levels (plus 0.29 of rounding).
    assert np.abs(model.mean - background).mean() < 0.6
    assert np.median(model.std) == pytest.approx(NOISE, rel=0.15)


def test_synthetic_person_found_and_shadow_labelled_shadow() -> None:
    rng = np.random.default_rng(1)
    background, frame, person, shadow = _scene(rng)
    model = _background_model(background, rng)
    config = SilhouetteConfig()

    labels = classify(frame, model, config)
    assert labels.shape == (H, W) and labels.dtype == np.uint8
    assert set(np.unique(labels)) <= {Label.BACKGROUND, Label.SHADOW, Label.FOREGROUND}
    # Per pixel, before clean-up: the shadow test must recognise the soft shadow.
    assert (labels[shadow] == Label.SHADOW).mean() >= 0.9
    assert (labels[person] == Label.FOREGROUND).mean() >= 0.95
    assert (labels[~person & ~shadow] == Label.BACKGROUND).mean() >= 0.99

    silhouette = silhouette_from_frame(frame, model, config)
    assert silhouette.dtype == bool
    np.testing.assert_array_equal(silhouette, foreground_mask(labels, config))
    gt = np.where(person, 255, 0).astype(np.uint8)
    assert f_measure(silhouette, gt) >= 0.97
    # Clean-up leaves almost none of the shadow in the silhouette.
    assert silhouette[shadow].mean() <= 0.02


def test_without_shadow_test_the_shadow_joins_the_silhouette() -> None:
    # The same scene with the shadow test off: the shadow (about half the person's area) is
    # foreground and F falls to about 2 x 1 / (2 x 1 + 0.47) = 0.81, so the bound above is
    # not met by the thresholds alone.
    rng = np.random.default_rng(1)
    background, frame, person, shadow = _scene(rng)
    model = _background_model(background, rng)
    silhouette = silhouette_from_frame(frame, model, SilhouetteConfig(detect_shadows=False))
    assert silhouette[shadow].mean() >= 0.9
    assert f_measure(silhouette, np.where(person, 255, 0)) < 0.85


def test_clean_up_removes_specks_and_fills_small_holes() -> None:
    labels = np.zeros((60, 60), np.uint8)
    labels[10:50, 10:40] = Label.FOREGROUND
    labels[25:28, 20:23] = Label.SHADOW  # a 3x3 hole inside the body
    labels[5, 55] = Label.FOREGROUND  # an isolated false pixel
    mask = foreground_mask(labels, SilhouetteConfig())
    assert mask[25:28, 20:23].all()
    assert not mask[5, 55]
    # Opening a 3-pixel disc shaves at most the rectangle's corners.
    assert abs(int(mask.sum()) - 40 * 30) <= 4


def test_grey_frames_work_as_one_channel() -> None:
    rng = np.random.default_rng(2)
    background = _background(rng)[:, :, 1]
    model = BackgroundModel.from_frames([_noisy(background, rng) for _ in range(10)])
    assert model.shape == (H, W, 1)
    frame = background.copy()
    person = _ellipse((80, 60), (15, 30))
    frame[person] = 20.0
    silhouette = silhouette_from_frame(_noisy(frame, rng), model)
    assert f_measure(silhouette, np.where(person, 255, 0)) >= 0.97


# ----------------------------------------------------------------------- temporal median model


def test_temporal_median_recovers_background_behind_moving_object() -> None:
    rng = np.random.default_rng(3)
    background = _background(rng)
    frames, covered = [], np.zeros((H, W), int)
    for t in range(40):
        # A blob crosses the image once; it covers any pixel in at most ~12 of the 40 frames.
        blob = _ellipse((10 + 4 * t, 60), (14, 35))
        image = background.copy()
        image[blob] = (30.0, 30.0, 200.0)
        frames.append(_noisy(image, rng))
        covered += blob
    assert covered.max() < 20 and (covered > 0).mean() > 0.5  # the test's premise
    model = BackgroundModel.from_sequence(frames)
    error = np.abs(model.mean - background)
    # Median of >= 32 background samples of noise 2: off by well under a grey level typically.
    # Samples are whole grey levels, so the median is too (or a half): the rare worst pixel,
    # darkened 8 times by the blob, is off by a few.
    assert np.median(error) < 0.6
    assert np.percentile(error, 99.9) < 2.5
    assert error.max() < 4.0
    # The robust spread is the noise where nothing passed, and the blob (100+ levels away in
    # up to 8 of 40 frames) inflates it by a third at most; it inflates a plain standard
    # deviation twentyfold. (The mean, not the median, of the MADs: the MAD of whole grey
    # levels comes in steps of 0.5 x 1.4826.)
    assert model.std[covered == 0].mean() == pytest.approx(NOISE, rel=0.15)
    assert model.std[covered > 0].mean() < 1.35 * NOISE
    plain = BackgroundModel.from_frames(frames)
    assert np.median(plain.std[covered > 5]) > 10 * NOISE
    assert np.abs(plain.mean - background)[covered > 5].mean() > 10
    # Every second frame is nearly as good.
    assert np.abs(BackgroundModel.from_sequence(frames[::2]).mean - background).max() < 5


def _median_and_mad(frames: list[np.ndarray], free: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """numpy's median and 1.4826 MAD over the frames (where `free` (N, H, W), if given)."""
    stack = np.stack(frames).astype(float)
    if free is not None:
        stack[~free] = np.nan
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        median = np.nanmedian(stack, axis=0)
        mad = np.nanmedian(np.abs(stack - median[None]), axis=0)
    return median, 1.4826 * mad


@pytest.mark.parametrize("count", [9, 8])
def test_one_pass_is_the_temporal_median_and_mad(count: int) -> None:
    # Odd counts take the 8-bit sorting network, even ones the mean of the two middle values.
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (17, 23, 3), dtype=np.uint8) for _ in range(count)]
    frames[4][:5] = 255  # something passing through
    model = BackgroundModel.from_sequence(frames, passes=1)
    median, spread = _median_and_mad(frames)
    np.testing.assert_array_equal(model.mean, median)
    np.testing.assert_allclose(model.std, spread, rtol=1e-6)
    grey = BackgroundModel.from_sequence([f[:, :, 1] for f in frames], passes=1)
    np.testing.assert_array_equal(grey.mean[:, :, 0], median[:, :, 1])


def test_second_background_pass_leaves_out_the_subject() -> None:
    # A subject of changing colour stands on the left half in 8 of 21 frames: its colours
    # inflate the first pass's spread there (so faint parts of it would pass as background);
    # the second pass takes the median and spread over the frames where it is absent.
    rng = np.random.default_rng(5)
    frames = []
    for k in range(21):
        frame = np.clip(rng.normal(100, 2, (40, 60, 3)), 0, 255).astype(np.uint8)
        if k % 5 in (0, 2):
            frame[5:35, 5:30] = rng.integers(140, 250, 3).astype(np.uint8)
        frames.append(frame)
    one = BackgroundModel.from_sequence(frames, passes=1)
    two = BackgroundModel.from_sequence(frames, passes=2)
    spot, clear = (slice(10, 30), slice(10, 25)), (slice(10, 30), slice(40, 55))
    assert np.median(one.std[spot]) > 1.5 * np.median(one.std[clear])
    assert np.median(two.std[spot]) < 1.25 * np.median(two.std[clear])
    np.testing.assert_allclose(np.median(two.mean[spot]), 100, atol=1.5)
    # Where nothing passed, the second pass changes nothing of note.
    np.testing.assert_allclose(two.std[clear], one.std[clear], rtol=0.35, atol=0.5)


def test_free_median_is_the_median_over_the_free_frames() -> None:
    rng = np.random.default_rng(8)
    frames = [rng.integers(0, 256, (7, 9, 3), dtype=np.uint8) for _ in range(9)]
    free = rng.random((9, 7, 9)) < 0.6
    previous = BackgroundModel.from_sequence(frames, passes=1)
    got = _free_median(frames, free, previous)
    median, spread = _median_and_mad(frames, free)
    enough = free.sum(axis=0) >= 9 // 4
    np.testing.assert_allclose(got.mean[enough], median[enough])
    np.testing.assert_allclose(got.std[enough], spread[enough], rtol=1e-5)
    np.testing.assert_array_equal(got.mean[~enough], previous.mean[~enough])


# ------------------------------------------------------------------------------------ scoring


def test_f_measure_matches_hand_counts_with_cdnet_labels_and_roi() -> None:
    gt = np.array([
        [255, 255, 255, 0],
        [255, 170, 50, 0],
        [0, 0, 85, 255],
        [255, 50, 0, 0],
    ], np.uint8)  # fmt: skip
    pred = np.array([
        [1, 1, 0, 1],
        [0, 1, 1, 0],
        [0, 1, 1, 1],
        [1, 0, 0, 0],
    ], bool)  # fmt: skip
    roi = np.full((4, 4), 255, np.uint8)
    roi[3, :] = 0  # the bottom row is outside the ROI
    # Counted: rows 0-2 minus (1,1) unknown and (2,2) outside-ROI = 10 pixels.
    # fg truth: (0,0) (0,1) (0,2) (1,0) (2,3); predicted fg among counted: (0,0) (0,1) (0,3)
    # (1,2) (2,1) (2,3).
    counts = confusion_counts(pred, gt, roi)
    assert counts == Counts(tp=3, fp=3, fn=2, tn=2)
    assert counts.precision == pytest.approx(3 / 6)
    assert counts.recall == pytest.approx(3 / 5)
    assert f_measure(pred, gt, roi) == pytest.approx(2 * 3 / (2 * 3 + 3 + 2))
    # Without an ROI the bottom row counts: (3,0) tp, (3,1) shadow tn, (3,2) (3,3) tn.
    assert confusion_counts(pred, gt) == Counts(tp=4, fp=3, fn=2, tn=5)
    # Counts pool over frames the CDnet way.
    assert (counts + counts).f_measure == pytest.approx(counts.f_measure)
    assert math.isnan(f_measure(np.zeros((2, 2), bool), np.zeros((2, 2), np.uint8)))


# ---------------------------------------------------------------------------------- bad input


def test_bad_input_raises_one_line_value_errors() -> None:
    a = np.zeros((10, 12, 3), np.uint8)
    cases = [
        (lambda: BackgroundModel.from_frames([]), "no frames"),
        (lambda: BackgroundModel.from_sequence([]), "no frames"),
        (lambda: BackgroundModel.from_sequence([a, np.zeros((10, 13, 3), np.uint8)]),
         "frame 1 is .* same size"),
        (lambda: BackgroundModel.from_frames([a.astype(np.float32), np.full(a.shape, np.nan)]),
         "frame 1 contains NaN"),
        (lambda: classify(np.zeros((11, 12, 3), np.uint8), BackgroundModel.from_frames([a])),
         "background model is"),
        (lambda: classify(np.full(a.shape, np.nan), BackgroundModel.from_frames([a])), "NaN"),
        (lambda: BackgroundModel.from_sequence([a], passes=0), "passes"),
        (lambda: BackgroundModel.from_sequence([a.astype(np.float32)]), "uint8"),
        (lambda: SilhouetteConfig(lower_sigma=5, upper_sigma=4), "lower_sigma"),
        (lambda: f_measure(np.zeros((3, 3), bool), np.zeros((3, 4), np.uint8)), "ground truth"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises(ValueError, match=message) as info:
            call()
        assert "\n" not in str(info.value)


def test_component_hulls_span_the_gaps_of_a_group_and_keep_groups_apart() -> None:
    """An arm beside a trunk, 6 px apart, spans the gap between them once grouped; a second
    figure 60 px away keeps its own hull, and the empty space between the two stays empty."""
    mask = np.zeros((H, W), np.uint8)
    mask[20:100, 20:40] = 1  # trunk
    mask[20:70, 46:52] = 1  # arm
    mask[20:100, 110:130] = 1  # another figure
    alone = component_hulls(mask)
    assert alone[50, 43] == 0  # ungrouped, the gap stays open
    grouped = component_hulls(mask, group_px=9)
    assert grouped[50, 43] == 1 and grouped[30, 50] == 1
    assert not grouped[:, 60:105].any()
    assert grouped[50, 120] == 1
    assert np.all(grouped >= mask)
