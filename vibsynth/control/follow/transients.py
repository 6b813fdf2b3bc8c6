"""Onsets played live the way the clip player plays a clip's transients (docs/clips.md).

At an onset of strength ``s`` the intensity jumps (no glide) to ``peak = intensity + s *
TRANSIENT_BOOST`` (at most 1: :func:`~vibsynth.dsp.follow.onsets.transient_peak`, the lift offline
conversion uses too), where live ``intensity`` is the level the onset announces (the
level path lags the onset path by a few ms: see the follower), then glides linearly back to
the tracked curve over the decay
(``clips.transient_decay_ms``); the intensity knob is linear in dB, so this is an exponential
amplitude decay, as for a clip transient. A new onset during a decay takes over from there.
"""

from __future__ import annotations

from vibsynth.dsp.follow.onsets import transient_peak

__all__ = ["TransientEnvelope"]


class TransientEnvelope:
    """The transient riding on one route's intensity, on the input's sample clock.

    Parameters
    ----------
    fs : float
        Input rate (Hz): times are input sample indices.
    decay_s : float
        From the peak back to the curve.
    """

    def __init__(self, fs: float, decay_s: float) -> None:
        self.decay = max(1.0, float(decay_s) * float(fs))
        self._peak: float | None = None
        self._at = 0

    def trigger(self, intensity: float, strength: float, at_sample: int, now: float | None = None) -> float:
        """An onset of ``strength`` (0..1] on a curve at ``intensity``; returns the peak it jumps to.

        ``now``: what the envelope plays at the onset (a running decay), so the peak is never below it.
        """
        peak = float(transient_peak(intensity, strength))
        if now is not None:
            peak = max(peak, float(now))
        self._peak, self._at = peak, int(at_sample)
        return peak

    def value(self, curve: float, at_sample: int) -> float:
        """The intensity to play at ``at_sample``: the curve, or the decaying transient above it."""
        if self._peak is None:
            return curve
        elapsed = int(at_sample) - self._at
        if elapsed >= self.decay:
            self._peak = None
            return curve
        return max(curve, self._peak + (curve - self._peak) * max(0, elapsed) / self.decay)

    @property
    def active(self) -> bool:
        """A transient is decaying."""
        return self._peak is not None

    def reset(self) -> None:
        self._peak = None
