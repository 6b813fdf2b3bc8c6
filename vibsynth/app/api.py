"""Convenience functions of the public API (``vibsynth.analyze``, ``vibsynth.render``, ``vibsynth.follow``).

They wrap the science (:mod:`vibsynth.dsp`) and the engine (:mod:`vibsynth.engine`) with
the defaults a script wants: the shipped basis, files read by name, the engine's default
intensity mapping. :func:`render` goes through the one offline renderer
(:func:`vibsynth.app.render.render`, into an :class:`~vibsynth.app.render.ArrayCollector`),
like every other offline render. See docs/python.md.
"""

from __future__ import annotations

import math
import numbers
import os
import secrets
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.app.render import ArrayCollector
from vibsynth.app.render import render as render_offline
from vibsynth.dsp.analysis import Analysis
from vibsynth.dsp.analysis import analyze as _analyze
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.dsp.follow import FollowResult
from vibsynth.dsp.follow import follow as _follow
from vibsynth.dsp.follow.offline import FollowOptions
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.formats.basis_file import default_basis
from vibsynth.formats.recordings import read_recording

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack from Python 3.11

__all__ = ["analyze", "render", "follow", "RENDER_LOOP_SECONDS"]

#: Loop length of the bank :func:`render` builds (the live default, ``bank.loop_seconds``).
RENDER_LOOP_SECONDS = 4.0


def _finite(
    name: str, value: object, *, low: float = -math.inf, high: float = math.inf, open_low: bool = False
) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise ParameterError(f"{name} must be a finite number, got {value!r}")
    number = float(value)
    if number < low or number > high or (open_low and number == low):
        bracket = "(" if open_low else "["
        raise ParameterError(f"{name} {number:g} is outside the allowed range {bracket}{low:g}, {high:g}]")
    return number


def analyze(
    x: ArrayLike | str | os.PathLike[str],
    *,
    fs: float | None = None,
    basis: Basis | None = None,
    channel: int = 0,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
) -> Analysis:
    """Analyse a stationary vibration: intensity, balance, t1, 30-band spectrum, non-stationarity.

    Parameters
    ----------
    x : array_like or path-like
        Mono samples, or a recording file (WAV, or CSV/TXT with one column of samples).
    fs : float, optional
        Sample rate in Hz: required for samples and CSV/TXT files, ignored for WAV files.
    basis : Basis, optional
        Spectral basis (M, V1..V8); default: the shipped one.
    channel : int
        Channel of a multi-channel WAV file (0-based).
    ceiling_db, range_db : float
        Intensity knob mapping used for ``intensity_knob`` (the defaults of ``vibsynth serve``).

    Returns
    -------
    Analysis
        See :class:`vibsynth.dsp.analysis.Analysis` (``intensity_knob``, ``balance``, ``level_db``,
        ``t1``, ``band_db``, ...).

    Raises
    ------
    ParameterError
        Bad samples (NaN, too short, silent, rate too low) or a missing ``fs``.
    InputError
        A file that cannot be read.
    """
    if isinstance(x, (str, os.PathLike)):
        recording = read_recording(x, fs=fs, channel=channel)
        samples: ArrayLike = recording.samples
        rate = recording.fs
    else:
        if fs is None:
            raise ParameterError("fs (the sample rate in Hz) is required when analysing samples")
        samples, rate = x, _finite("fs", fs, low=0.0, open_low=True)
    return _analyze(
        samples,
        fs=rate,
        basis=basis if basis is not None else default_basis(),
        ceiling_db=ceiling_db,
        range_db=range_db,
    )


def render(
    intensity: float,
    balance: float,
    seconds: float,
    *,
    fs: float = 48000.0,
    basis: Basis | None = None,
    seed: int | None = None,
) -> NDArray[np.float32]:
    """A stationary texture rendered offline through the real-time engine.

    The engine (:class:`vibsynth.engine.engine.Engine`, with the intensity mapping, limiter
    and loop of ``vibsynth serve``'s defaults) plays a noise bank built for exactly this
    balance, so the spectrum is ``M + t1(balance) V1`` without interpolation between bank
    levels. The texture is a seamless loop of :data:`RENDER_LOOP_SECONDS`, repeated for
    longer renders, as live.

    Parameters
    ----------
    intensity : float
        Knob 0..1 (0 = silence; 1 = the ceiling band level, -40 dB re unit RMS).
    balance : float
        High/low balance in knob units (0 = mean spectrum, +1/-1 = 98th/2nd percentile).
    seconds : float
        Duration (> 0).
    fs : float
        Sample rate in Hz (>= 2.4 kHz).
    basis : Basis, optional
        Default: the shipped basis.
    seed : int, optional
        Random phases; the same seed gives the same samples. Default: fresh.

    Returns
    -------
    ndarray, shape (frames,), float32
        ``frames = round(seconds * fs)``.

    Raises
    ------
    ParameterError
        A value outside its range, or a render too long to hold in memory (over
        :data:`~vibsynth.app.render.MAX_COLLECT_BYTES`, 23 min at 48 kHz: stream it to a
        WAV file with :func:`vibsynth.app.render.render` and a
        :class:`~vibsynth.formats.wav_stream.WavStreamWriter` instead).
    """
    intensity = _finite("intensity", intensity, low=0.0, high=1.0)
    balance = _finite("balance", balance)
    seconds = _finite("seconds", seconds, low=0.0, open_low=True)
    fs = _finite("fs", fs, low=MIN_RATE_HZ)
    frames = int(round(seconds * fs))
    if frames < 1:
        raise ParameterError(f"{seconds:g} s at {fs:g} Hz is less than one sample")
    if seed is None:
        seed = secrets.randbits(31)
    elif isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
    # two levels with the wanted balance exactly on the first: the engine reads that level alone
    spec = BankSpec(
        fs=fs,
        loop_seconds=RENDER_LOOP_SECONDS,
        balance_min=balance,
        balance_max=balance + 1.0,
        levels=2,
        seed=int(seed),
    )
    collector = ArrayCollector(frames, 1)  # refuses an over-long render before the bank is built
    bank = build_bank(basis if basis is not None else default_basis(), spec)
    engine = Engine(
        bank,
        channels=1,
        ceiling_db=DEFAULT_CEILING_DB,
        range_db=DEFAULT_RANGE_DB,
        glide_s=0.0,
        initial_intensity=intensity,
        initial_balance=balance,
    )
    result = render_offline(engine, frames, collector)
    out: NDArray[np.float32] = result.output.reshape(frames)  # (frames, 1) -> (frames,), a view
    return out


def follow(x: ArrayLike, fs: float, **options: Unpack[FollowOptions]) -> FollowResult:
    """Knob trajectories (intensity, balance, transients) that follow a sound or a vibration.

    :func:`vibsynth.dsp.follow.follow` (the one tracker over the whole signal, latency
    compensated; docs/follow.md) with the shipped basis unless ``basis`` is given. ``x`` has
    shape (n,) or (n, channels) (mixed to their mean); the options are
    :class:`~vibsynth.dsp.follow.offline.FollowOptions` (``mode``, ``focus``, ``params`` overriding
    both, ``basis``, the engine's intensity mapping ``ceiling_db`` / ``range_db``, ``balance_limits``).

    Returns
    -------
    result : FollowResult
        ``times``, ``intensity``, ``balance``, ``level_db``, ``onsets`` and notes on bad input.
    """
    if options.get("basis") is None:
        options["basis"] = default_basis()
    return _follow(x, fs, **options)
