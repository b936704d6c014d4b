"""Knowing when the tracker is lost, relative to what the model reached on this subject
(issue 20): pure bookkeeping of the XOR fractions of tracked frames, no images.

The absolute bar of `tracking.track.tracker` (``max_xor_fraction`` of the silhouette area, or
1.5 times the best start's XOR) lets a wrong track through when the model fits this subject
well: a track that went from 10% to 30% XOR is lost, yet under 35%. `XorWatch` keeps the XOR
fractions of the recent frames it accepted and flags a frame

* far above their median (a spike: ``spike_factor`` times it), or
* above ``high_factor`` times it for ``high_frames`` frames in a row (a slower slide).

Frames above ``high_factor`` times the median do not enter it, so a slide cannot raise its own
reference. A bar is never closer than ``min_margin`` (a fraction of the silhouette area) above
the median: on clean renders the median is ~2% and a few pixels of difference would double it.

After a divergence the start search found nothing better for (`diverge`), the level the model
reaches is the reference, and the watch keeps the high bar of the reference before it: the
first frame back under that bar (`returned`; the tracker also asks that the visual hull be
explained) is the track found again, and the tracker calls the frames over it diverged still.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

MIN_REFERENCE_FRAMES = 3
"""Accepted frames whose median is the reference; until there are that many after a
`XorWatch.restart` with a value (a start, refined with every limb over its whole range), that
value alone is the reference."""


@dataclass(frozen=True, kw_only=True)
class WatchConfig:
    spike_factor: float
    high_factor: float
    high_frames: int
    window: int
    min_margin: float

    @property
    def enabled(self) -> bool:
        return self.spike_factor > 0 or self.high_frames > 0


class XorWatch:
    """The relative divergence test over a sequence of XOR fractions (see module docstring).

    Per frame: `verdict` (does this XOR make the frame a divergence?), then `accept` for a
    frame kept as tracked, or `restart` after a start or a recovery that found nothing better
    (its XOR becomes the new reference)."""

    def __init__(self, config: WatchConfig) -> None:
        self.config = config
        self.accepted: deque[float] = deque(maxlen=max(config.window, 1))
        self.streak = 0  # frames in a row above the high bar, not accepted
        self.start: float | None = None  # the XOR of the last restart's pose
        self.diverged: tuple[int, float] | None = None
        """The first divergence not yet behind the track (`diverge`): its frame, and the high
        bar of the reference before it (or the absolute bar a start was over); None after a
        start, a recovery or `returned`."""
        self._start_over_bar = False  # `diverged` is a start over the absolute bar

    def reference(self) -> float | None:
        """Median XOR fraction of the accepted frames; until there are `MIN_REFERENCE_FRAMES`,
        the start's (`restart`), or None after a restart without one.

        Why the start's: the first frames after a start set the median, and a track that left
        its start's pose at once made its own reference. On the motion suite (session 21),
        climb_steps, kick and sit_stand went from a start at 9.6-9.9% XOR to 18-28% in the
        next frame (both wrists 300 mm off, unflagged); the 12 other clips' first five frames
        stay within 0.8-1.3 times their start's."""
        if len(self.accepted) < MIN_REFERENCE_FRAMES:
            return self.start
        values = sorted(self.accepted)
        n = len(values)
        return values[n // 2] if n % 2 else 0.5 * (values[n // 2 - 1] + values[n // 2])

    def bar(self, factor: float) -> float | None:
        """The XOR fraction above which a frame is `factor` times the reference."""
        reference = self.reference()
        if reference is None or factor <= 0:
            return None
        return max(factor * reference, reference + self.config.min_margin)

    def verdict(self, xor_fraction: float) -> str:
        """Why a frame of this XOR fraction is a divergence, or "" when it is not."""
        cfg = self.config
        reference = self.reference()
        if reference is None:
            return ""
        spike = self.bar(cfg.spike_factor)
        if spike is not None and xor_fraction > spike:
            return (f"XOR {xor_fraction:.1%} of the silhouette, over {spike:.1%} "
                    f"({cfg.spike_factor:g} x this subject's recent median {reference:.1%})")
        high = self.bar(cfg.high_factor)
        if (cfg.high_frames > 0 and high is not None and xor_fraction > high
                and self.streak + 1 >= cfg.high_frames):  # fmt: skip
            return (f"XOR {xor_fraction:.1%} of the silhouette, over {high:.1%} "
                    f"({cfg.high_factor:g} x this subject's recent median {reference:.1%}) for "
                    f"{self.streak + 1} frames in a row")
        return ""

    def accept(self, xor_fraction: float) -> None:
        """A frame kept as tracked: its XOR enters the reference unless it is above the high
        bar (then it counts towards the streak)."""
        high = self.bar(self.config.high_factor)
        if high is not None and xor_fraction > high:
            self.streak += 1
        else:
            self.accepted.append(xor_fraction)
            self.streak = 0

    def restart(self, xor_fraction: float | None = None) -> None:
        """Forget the reference and any divergence (a new start, or a recovery)."""
        self.accepted.clear()
        self.streak = 0
        self.start = xor_fraction
        self.diverged, self._start_over_bar = None, False
        if xor_fraction is not None:
            self.accepted.append(xor_fraction)

    def diverge(self, frame: int, xor_fraction: float, absolute: float | None = None) -> None:
        """A divergence the start search found nothing better for: what the model reaches now
        is the reference from here (`restart`), and the high bar of the reference before it
        is kept for `returned` (the first divergence's, until the track is back under it).
        absolute: a start over this absolute bar (an XOR fraction), which is the bar to be
        back under (a start has no reference before it)."""
        kept, over = self.diverged, self._start_over_bar
        if kept is None:
            bar = self.bar(self.config.high_factor) if absolute is None else absolute
            kept, over = (None if bar is None else (frame, bar)), absolute is not None
        self.restart(xor_fraction)
        self.diverged, self._start_over_bar = kept, over

    def bar_words(self) -> str:
        """What the bar of `diverged` is, for an event's text."""
        assert self.diverged is not None
        if self._start_over_bar:
            return f"the absolute bar, which the start at frame {self.diverged[0]} was over"
        return f"this subject's usual XOR before the divergence at frame {self.diverged[0]}"

    def returned(self, xor_fraction: float) -> tuple[int, float] | None:
        """After a `diverge`, whether a tracked frame of this XOR fraction is back under the
        high bar of the reference before the divergence: that divergence's frame and the bar
        (then forgotten), or None."""
        if self.diverged is None or xor_fraction > self.diverged[1]:
            return None
        back, self.diverged = self.diverged, None
        self._start_over_bar = False
        return back
