"""The relative divergence test (`tracking.track.divergence.XorWatch`) on synthetic sequences
of XOR fractions (issue 20)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tracking.track.divergence import WatchConfig, XorWatch

WATCH = WatchConfig(spike_factor=1.6, high_factor=1.3, high_frames=3, window=15,
                    min_margin=0.03)
"""The relative tests with the tracker's defaults (`tracking.track.tracker.SPIKE_XOR_FACTOR` ...,
where they were measured)."""


def _verdicts(watch: XorWatch, sequence) -> list[str]:
    """Each frame's verdict, every frame then kept as tracked (no recovery, no restart)."""
    out = []
    for value in sequence:
        out.append(watch.verdict(value))
        watch.accept(value)
    return out


def test_steady_tracking_raises_no_divergence():
    """Measured on the mismatched mpfb subject: 9-12% XOR frame to frame over the CMU walk and
    wave at 30 fps (README). Noise of that size, for 300 frames, is never flagged."""
    rng = np.random.default_rng(0)
    sequence = np.clip(0.10 + 0.01 * rng.standard_normal(300), 0.08, 0.13)
    assert not any(_verdicts(XorWatch(WATCH), sequence))


def test_a_spike_is_flagged_at_once_and_a_slide_after_some_frames():
    watch = XorWatch(WATCH)
    assert _verdicts(watch, [0.10] * 5) == [""] * 5
    spike = 0.10 * WATCH.spike_factor + 0.01
    assert "this subject's recent median 10.0%" in watch.verdict(spike)
    assert watch.verdict(0.10 * WATCH.spike_factor - 0.01) == ""
    # A slide above the high bar but under the spike: flagged on its high_frames-th frame, and
    # its frames do not raise the reference.
    slide = 0.5 * (WATCH.high_factor + WATCH.spike_factor) * 0.10
    verdicts = _verdicts(watch, [slide] * WATCH.high_frames)
    assert verdicts[:-1] == [""] * (WATCH.high_frames - 1)
    assert f"for {WATCH.high_frames} frames in a row" in verdicts[-1]
    assert watch.reference() == pytest.approx(0.10)
    # Back under the bar: the streak ends.
    watch.accept(0.10)
    assert watch.streak == 0 and watch.verdict(slide) == ""


def test_the_bars_keep_a_margin_over_a_small_median_and_restart_at_a_new_level():
    """Clean renders of the tracker's own model reach ~2% XOR: 4% is not a divergence."""
    watch = XorWatch(WATCH)
    _verdicts(watch, [0.02, 0.018, 0.022, 0.02])
    assert watch.verdict(0.02 + WATCH.min_margin - 0.005) == ""
    assert watch.verdict(0.02 + WATCH.min_margin + 0.005) != ""
    # A recovery that found nothing better restarts the reference at what the model reaches.
    watch.restart(0.2)
    assert _verdicts(watch, [0.2, 0.21, 0.2, 0.22]) == [""] * 4
    # Off: nothing is flagged.
    off = XorWatch(dataclasses.replace(WATCH, spike_factor=0.0, high_frames=0))
    assert not any(_verdicts(off, [0.1] * 5 + [0.5] * 10))


def test_the_start_is_the_reference_until_enough_frames_follow_it():
    """A track that leaves its start at once must not set its own reference: climb_steps went
    from its start at 9.6% XOR to 17.9% in the next frame, both wrists 300 mm off, and the
    first three frames' median was that wrong level (session 21; there the truth's arms dropped
    70 degrees in one frame, the clip's blend out of its rest pose, which synth skips since
    session 31)."""
    watch = XorWatch(WATCH)
    watch.restart(0.096)
    assert watch.reference() == pytest.approx(0.096)
    assert "recent median 9.6%" in watch.verdict(0.179)
    # A frame near the start's level is not flagged, and enters the reference.
    assert watch.verdict(0.11) == ""
    # Without a start's value (the shape pass's restart) nothing speaks until 3 frames.
    watch.restart()
    assert watch.reference() is None and watch.verdict(0.5) == ""


def test_after_a_divergence_the_first_frame_back_under_the_former_bar_is_found_again():
    """The suite's turn_pirouette (60 frames, session 29): frame 41 diverged at 24.0% over a
    median of 14.9%, the start search found nothing better, and the frames after it went back
    to 15% by themselves. The watch keeps the bar of before the divergence (the high one,
    1.3 x 14.9%) through later divergences, until a frame is back under it; a start or a
    recovery by the start search forgets it."""
    watch = XorWatch(WATCH)
    _verdicts(watch, [0.15, 0.14, 0.16, 0.15])
    bar = WATCH.high_factor * 0.15
    watch.diverge(41, 0.24)
    assert watch.reference() == pytest.approx(0.24)  # the level reached is the reference
    assert watch.returned(bar + 0.01) is None
    watch.accept(bar + 0.01)
    watch.diverge(43, 0.30)  # a second divergence keeps the first's frame and bar
    assert watch.diverged == (41, pytest.approx(bar))
    back = watch.returned(bar - 0.01)
    assert back == (41, pytest.approx(bar)) and watch.diverged is None
    assert watch.returned(0.10) is None  # found once
    # A new start forgets the divergence; so does a diverge with no reference to keep.
    watch.diverge(50, 0.3)
    watch.restart(0.12)
    assert watch.diverged is None and watch.returned(0.05) is None
    fresh = XorWatch(WATCH)
    fresh.diverge(3, 0.3)
    assert fresh.diverged is None
