"""Background plates as the model (`tracking.silhouettes.subtraction`): the noise model of a
single photo, the streamed mean and spread of a clip, and the exposure matched frame by frame,
against scenes with known noise, gain and subject."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.silhouettes.subtraction import (
    BackgroundModel,
    SilhouetteConfig,
    exposure_gain,
    matched_exposure,
    noise_sigma,
    silhouette_from_frame,
)


def scene(seed: int = 0, width: int = 320, height: int = 240) -> np.ndarray:
    """A textured, noiseless empty scene (smooth colour noise over a ramp) with a sharp
    vertical edge in the middle (a door frame)."""
    rng = np.random.default_rng(seed)
    texture = cv2.GaussianBlur(rng.normal(0, 1, (height, width, 3)).astype(np.float32),
                               (0, 0), 3.0)
    image = 110 + 120 * texture + np.linspace(0, 30, width, dtype=np.float32)[None, :, None]
    image[:, width // 2:] -= 50
    return np.clip(image, 0, 255).astype(np.uint8)


def noisy(image: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(image + rng.normal(0, sigma, image.shape)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("sigma", [1.0, 3.0, 6.0])
def test_noise_sigma_measures_the_noise_not_the_texture(sigma: float):
    measured = noise_sigma(noisy(scene(), sigma, seed=1))
    assert measured == pytest.approx([sigma] * 3, rel=0.12, abs=0.3)


def test_one_photo_spreads_by_its_noise_and_more_at_edges():
    photo = noisy(scene(), 2.0, seed=2)
    model = BackgroundModel.from_photo(photo)
    assert np.array_equal(model.mean, photo.astype(np.float32))
    flat = model.std[100:140, 40:80]
    edge = model.std[100:140, 159:161]
    assert np.median(flat) == pytest.approx(2.0, rel=0.5)
    assert edge.min() > 3 * np.median(flat)  # half a pixel of a 50-level step: 12.5
    # Another exposure of the scene (new noise, shifted by a third of a pixel) is background.
    shifted = cv2.warpAffine(scene(), np.float32([[1, 0, 0.33], [0, 1, 0]]), (320, 240),
                             borderMode=cv2.BORDER_REFLECT)
    assert silhouette_from_frame(noisy(shifted, 2.0, seed=3), model).mean() < 0.002


def test_the_mean_and_spread_of_photos_take_any_iterable():
    frames = [noisy(scene(), 4.0, seed=s) for s in range(12)]
    listed = BackgroundModel.from_frames(frames)
    streamed = BackgroundModel.from_frames(f for f in frames)
    assert np.array_equal(listed.mean, streamed.mean) and np.array_equal(listed.std,
                                                                          streamed.std)
    assert np.median(streamed.std) == pytest.approx(4.0, rel=0.15)
    with pytest.raises(ValueError, match="no frames"):
        BackgroundModel.from_frames(iter(()))


@pytest.mark.parametrize("subject_fraction", [0.05, 0.4])
def test_the_exposure_is_matched_to_the_plate_whatever_the_subject(subject_fraction: float):
    plate = scene()
    model = BackgroundModel.from_photo(plate)
    truth = np.zeros(plate.shape[:2], bool)
    rows = round(240 * np.sqrt(subject_fraction))
    truth[240 - rows:, 40:40 + round(subject_fraction * 240 * 320 / rows)] = True
    frame = noisy(plate, 2.0, seed=4)
    frame[truth] = (40, 45, 235)
    gain = np.array([0.78, 0.86, 1.12])  # darker and warmer: the light changed
    dimmed = np.clip(np.rint(frame * gain), 0, 255).astype(np.uint8)
    assert silhouette_from_frame(dimmed, model).mean() > 0.5  # unmatched: all foreground
    found = exposure_gain(dimmed, model)
    assert found == pytest.approx(gain, rel=0.01)
    mask = silhouette_from_frame(matched_exposure(dimmed, found), model)
    assert (mask & truth).sum() / (mask | truth).sum() > 0.97


def test_the_outline_is_split_at_half_the_contrast():
    """A bright disc blurred as a codec blurs it (sigma 1.2 px; IoU 0.946 as classified, 0.983
    with the band of 1 px, 1.000 with 2): the lower threshold calls
    every pixel the disc touches foreground, a rim outside the true outline; the band round
    the outline goes to the nearer colour, the rim with it."""
    plate = scene(5)
    model = BackgroundModel.from_photo(plate)
    yy, xx = np.mgrid[:240, :320]
    truth = (yy - 120.3) ** 2 + (xx - 150.6) ** 2 < 45**2
    sharp = np.where(truth[..., None], np.uint8([40, 45, 235]), plate)
    frame = cv2.GaussianBlur(sharp, (0, 0), 1.2)

    def iou(mask):
        return (mask & truth).sum() / (mask | truth).sum()

    plain = silhouette_from_frame(frame, model, SilhouetteConfig(edge_band_px=0))
    refined = silhouette_from_frame(frame, model, SilhouetteConfig(edge_band_px=1))
    assert iou(plain) < 0.96 and (plain & ~truth).sum() > 3 * (truth & ~plain).sum()
    assert iou(refined) > 0.98 and iou(refined) > iou(plain) + 0.02, (iou(plain), iou(refined))
    # Away from the outline nothing changes.
    far = cv2.dilate(truth.astype(np.uint8), np.ones((9, 9), np.uint8)) == 0
    assert not refined[far].any() and refined[100:140, 130:170].all()
