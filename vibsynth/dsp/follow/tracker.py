"""The one tracker: a signal block by block -> intensity, balance and transients per frame.

Causal, bounded memory, identical offline and live (the offline :func:`~vibsynth.dsp.follow.offline.follow`
feeds the same object). The input is decimated by a whole factor to the mode's internal rate
(vibration: >= 4 kHz, audio: >= 16 kHz), framed every ``hop`` samples, analysed by the mode's
analyser, and mapped to knobs here:

* vibration: ``intensity = level_db_to_knob(level_db + gain_db)`` under the engine's mapping
  (``ceiling_db``, ``range_db``), so at gain 0 the output's 80-200 Hz level equals the input's
  wherever the knob range reaches; levels above the ceiling play at knob 1 and levels below
  the range at the knob's floor (both counted in :attr:`Tracker.clamped_frames`).
* audio: ``intensity = 1 + (drive_db + gain_db - top_db) / range_db``: ``range_db`` of input
  loudness spans the knob range (docs/follow.md gives the reasons and numbers).

Bad input at the edge: NaN and infinite samples are replaced by 0 and counted
(:attr:`Tracker.nonfinite_samples`): a live stream keeps its clock and goes on. Flat-topped
(clipped) runs are counted in :attr:`Tracker.clipped_samples`. DC makes no intensity: every
path is band-pass or high-pass, and the first block's mean is subtracted from everything, so an
offset (an accelerometer's gravity) does not start as a step that the narrow low bands would
ring with for seconds; later offsets the filters reject.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.dsp.follow.audio import AUDIO_RATE_HZ, MIN_AUDIO_RATE_HZ, AudioAnalyzer
from vibsynth.dsp.follow.frames import TrackFrames
from vibsynth.dsp.follow.onsets import ONSET_SCALE_FLOOR
from vibsynth.dsp.follow.params import TrackerParams
from vibsynth.dsp.follow.stream import Resampler, rate_factors
from vibsynth.dsp.follow.vibration import VIBRATION_RATE_HZ, LevelMeter, VibrationAnalyzer
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, level_db_to_knob
from vibsynth.errors import ParameterError

__all__ = ["Tracker", "MAX_RATE_HZ", "KNOB_FLOOR", "GATE_HYSTERESIS_DB", "BALANCE_LIMITS", "count_clipped"]

MAX_RATE_HZ = 768000.0
#: Smallest intensity knob an open gate gives (plays at the bottom of the knob range).
KNOB_FLOOR = 1e-3
GATE_HYSTERESIS_DB = 2.0
#: The engine's default live balance range (knobs.balance_min/max).
BALANCE_LIMITS = (-3.5, 3.5)


def count_clipped(x: NDArray[np.float64]) -> int:
    """Samples in flat-topped runs (>= 3 equal samples at the block's peak magnitude) of a block
    that swings (a constant, DC, is not clipping)."""
    if x.size < 3:
        return 0
    mag = np.abs(x)
    peak = float(mag.max())
    if peak <= 0 or float(np.ptp(x)) < 0.5 * peak:
        return 0
    at_peak = (mag >= peak * (1 - 1e-7)).astype(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], at_peak, [0]))))
    runs = edges[1::2] - edges[::2]
    return int(runs[runs >= 3].sum())


class Tracker:
    """Follow a signal: knob trajectories per frame.

    Parameters
    ----------
    fs : float
        Input rate (Hz): 2.4 kHz .. 768 kHz (audio mode: >= 8 kHz).
    params : TrackerParams
    basis : Basis
        Gives V1 and the balance units.
    ceiling_db, range_db : float
        The engine's intensity mapping (``knobs.ceiling_db``, ``knobs.range_db``).
    balance_limits : tuple of float
        The live balance range (``knobs.balance_min``, ``knobs.balance_max``).
    uniform_windows : bool
        Vibration mode: every band over ``balance_ms`` and the bank run every hop, no bias
        correction (the codec's windows; :func:`~vibsynth.dsp.follow.offline.window_analysis`).

    Attributes
    ----------
    hop : int
        Input samples per frame.
    latency : int
        Input samples from a change of the input to the end of the frame that shows half of it
        (level path); offline results are shifted back by this.
    up, factor : int
        Interpolation and decimation factors to the internal rate ``rate = fs * up / factor``.
    """

    def __init__(
        self,
        *,
        fs: float,
        params: TrackerParams,
        basis: Basis,
        ceiling_db: float = DEFAULT_CEILING_DB,
        range_db: float = DEFAULT_RANGE_DB,
        balance_limits: tuple[float, float] = BALANCE_LIMITS,
        uniform_windows: bool = False,
    ) -> None:
        if not isinstance(params, TrackerParams):
            raise ParameterError(f"params must be TrackerParams, got {type(params).__name__}")
        minimum = MIN_AUDIO_RATE_HZ if params.mode == "audio" else MIN_RATE_HZ
        if not (isinstance(fs, (int, float)) and math.isfinite(fs) and minimum <= fs <= MAX_RATE_HZ):
            raise ParameterError(
                f"follow ({params.mode} mode) needs an input rate in [{minimum:g}, {MAX_RATE_HZ:g}] Hz, got {fs!r}"
            )
        level_db_to_knob(0.0, ceiling_db=ceiling_db, range_db=range_db)  # validates the mapping
        lo, hi = balance_limits
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ParameterError(f"balance limits must be finite with lo < hi, got {balance_limits}")
        self.fs = float(fs)
        self.basis = basis
        self.ceiling_db = float(ceiling_db)
        self.range_db = float(range_db)
        self.balance_limits = (float(lo), float(hi))
        self._uniform = uniform_windows
        self.last_band_power = np.zeros((0, basis.n_bands))
        self.params = params
        self._build()
        self.nonfinite_samples = 0
        self.clipped_samples = 0
        self.clamped_frames = 0
        self.frames_done = 0

    # ------------------------------------------------------------------ set-up
    def _build(self) -> None:
        p = self.params
        if p.mode == "vibration":
            self.up, self.factor = rate_factors(self.fs, VIBRATION_RATE_HZ)
            passband = min(1200.0, 0.43 * self.fs)
        else:
            self.up, self.factor = rate_factors(self.fs, AUDIO_RATE_HZ)
            passband = 0.4 * self.fs / self.factor
        self.decimator = Resampler(self.fs, self.up, self.factor, passband)
        self.rate = self.fs * self.up / self.factor
        self.hop_internal = self.up * max(1, int(round(p.hop_ms * 1e-3 * self.fs / self.factor)))
        self.hop = self.hop_internal * self.factor // self.up
        self.analyzer: VibrationAnalyzer | AudioAnalyzer
        if p.mode == "vibration":
            self.analyzer = VibrationAnalyzer(
                fs=self.rate,
                hop=self.hop_internal,
                basis=self.basis,
                level_ms=p.level_ms,
                balance_ms=p.balance_ms,
                balance_limits=self.balance_limits,
                uniform_windows=self._uniform,
            )
        else:
            self.analyzer = AudioAnalyzer(
                fs=self.rate, hop=self.hop_internal, params=p, balance_limits=self.balance_limits
            )
        # Vibration mode measures the 80-200 Hz level at the input rate when it decimates: the
        # Butterworth's upper skirt then counts content up to the input's Nyquist, as the analog
        # definition (dsp/intensity.py) does; at the internal rate a bright accelerometer signal's
        # 2-5 kHz content would be lost from its level (2 dB on HaTT scans).
        self._meter: LevelMeter | None = None
        if p.mode == "vibration" and self.factor > 1:
            self._meter = LevelMeter(self.fs, p.level_ms)
            assert isinstance(self.analyzer, VibrationAnalyzer)
            self.analyzer.measure_level = False
            self.filter_delay_s = self._meter.delay_s
            window_s = self._meter.window / self.fs
        else:
            #: seconds of filter delay in front of the level's window (resampler + band filter)
            self.filter_delay_s = self.decimator.delay_s(140.0) + self.analyzer.filter_delay_s
            window_s = self.analyzer.level_window / self.rate
        #: input samples of the level's window
        self.level_window = int(round(window_s * self.fs))
        self.latency = int(round((self.filter_delay_s + 0.5 * window_s) * self.fs))
        self._input = 0
        self._internal = 0  # internal samples consumed
        self._gate = False
        self._offset: float | None = None

    def reset(self) -> None:
        """Forget the signal (filters, windows, gate, sample clock); keep the parameters."""
        self.decimator.reset()
        self.analyzer.reset()
        self._internal = 0
        self._input = 0
        if self._meter is not None:
            self._meter.reset()
        self._gate = False
        self._offset = None
        self.frames_done = 0

    def set_params(self, params: TrackerParams) -> None:
        """Change parameters live. Gain, gate, range, focus and transients apply from the next frame
        with no reset; a new mode, hop or window rebuilds the analysis (a reset)."""
        if not isinstance(params, TrackerParams):
            raise ParameterError(f"params must be TrackerParams, got {type(params).__name__}")
        old = self.params
        self.params = params
        structural = ("mode", "hop_ms", "level_ms", "balance_ms")
        if any(getattr(old, k) != getattr(params, k) for k in structural):
            frames = self.frames_done
            self._build()
            self.frames_done = frames
        elif isinstance(self.analyzer, AudioAnalyzer):
            self.analyzer.set_params(params)

    # ------------------------------------------------------------------ processing
    def process(self, block: ArrayLike) -> TrackFrames:
        """Track one block of input.

        Parameters
        ----------
        block : array_like, shape (n,) or (n, channels)
            Samples at ``fs``; several channels are mixed to their mean.

        Returns
        -------
        frames : TrackFrames
            The frames completed by this block (often 0 or 1 for a live block).
        """
        x = np.asarray(block, dtype=np.float64)
        if x.ndim == 2:
            x = x.mean(axis=1) if x.shape[1] else np.zeros(x.shape[0])
        if x.ndim != 1:
            raise ParameterError(f"a follow block must have shape (n,) or (n, channels), got {x.shape}")
        bad = ~np.isfinite(x)
        if bad.any():
            self.nonfinite_samples += int(np.count_nonzero(bad))
            x = np.where(bad, 0.0, x)
        self.clipped_samples += count_clipped(x)
        if self._offset is None and x.size:
            self._offset = float(x.mean())
        x = x - (self._offset or 0.0)
        y = self.decimator(x)
        start = self._internal
        self._internal += y.size
        first = (start // self.hop_internal + 1) * self.hop_internal
        ends_abs = np.arange(first, self._internal + 1, self.hop_internal, dtype=np.int64)
        ends = (ends_abs - start).astype(np.intp)
        level, balance, strength, drive = self._analyse(y, ends)
        if self._meter is not None:  # the 80-200 Hz level at the input rate (see _build)
            in_ends = ((ends_abs - 1) * self.factor + 1 - self._input).astype(np.intp)
            level = drive = self._meter(x, in_ends)
        self._input += x.size
        intensity, gate = self._map(level, drive)
        onset = np.where(gate, strength * np.maximum(intensity, ONSET_SCALE_FLOOR), 0.0)
        if not self.params.transients:
            onset = np.zeros(level.size)
        self.frames_done += ends.size
        return TrackFrames(
            end_sample=ends_abs * self.factor // self.up,
            level_db=level,
            intensity=intensity,
            balance=balance,
            gate_open=gate,
            onset_strength=np.where(onset > 0, np.clip(onset, 0.0, 1.0), 0.0),
        )

    def _analyse(
        self, y: NDArray[np.float64], ends: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        if isinstance(self.analyzer, VibrationAnalyzer):
            level, balance, _, strength, self.last_band_power = self.analyzer.process(y, ends)
            return level, balance, strength, level
        return self.analyzer.process(y, ends)

    def _map(
        self, level: NDArray[np.float64], drive: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        p = self.params
        gate = np.zeros(level.size, dtype=bool)
        state = self._gate
        for i, v in enumerate(level):
            if state and not v >= p.gate_db - GATE_HYSTERESIS_DB:
                state = False
            elif not state and v >= p.gate_db and math.isfinite(v):
                state = True
            gate[i] = state
        self._gate = state
        with np.errstate(invalid="ignore"):
            if p.mode == "vibration":
                knob = 1.0 + (drive + p.gain_db - self.ceiling_db) / self.range_db
            else:
                knob = 1.0 + (drive + p.gain_db - p.top_db) / p.range_db
        clamped = gate & ((knob > 1.0) | (knob < KNOB_FLOOR))
        self.clamped_frames += int(np.count_nonzero(clamped))
        intensity = np.where(gate & np.isfinite(knob), np.clip(knob, KNOB_FLOOR, 1.0), 0.0)
        return intensity, gate
