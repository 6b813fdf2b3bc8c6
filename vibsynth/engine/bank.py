"""The noise bank: one seamless loop per balance level, all sharing one phase spectrum.

For each balance ``b`` on a grid (default 49 levels over [-3.5, 3.5]), the DSP core's
exact synthesis (:meth:`~vibsynth.dsp.synthesis.SpectralShaper.solve_balance`) gives
per-bin powers whose *measured* band spectrum is ``M + t1(b) V1`` at an 80-200 Hz
band level of 0 dB (iso-intensity: every level has the same band level, so the
engine's gain alone sets the intensity). Every level is rendered with the **same**
random phasors, so level ``i`` and ``i+1`` are the same waveform "grain" with
different magnitudes: mixing them sample by sample, ``(1-f) x_i + f x_{i+1}``, has
the spectrum ``((1-f)|X_i| + f|X_{i+1}|) e^{i phi}`` -- a magnitude crossfade with
no power dip and no change of grain while the balance knob moves.

Each level is one period of a periodic signal (``loop_seconds`` at the output rate),
so reading it modulo its length loops without a seam.

Decorrelated channels
---------------------
Channels read the same bank at read offsets ``c * n_samples / channels`` apart
(:meth:`NoiseBank.channel_offsets`; 0.5 s for 8 channels of a 4 s loop). The
circular cross-correlation of a periodic random-phase signal with itself at lag
``L`` is the inverse DFT of ``|X|^2`` at ``L``, which does not depend on the
phases: for these smooth 10-1000 Hz spectra it decays within a few milliseconds,
so channels half a second apart are uncorrelated (measured |r| < 0.01), while
every channel keeps exactly the same spectrum and intensity. Independent phase
sets would multiply memory and build time by the channel count for no benefit.

Actuator compensation
---------------------
With an :class:`~vibsynth.engine.actuator.ActuatorResponse`, each level's
magnitudes are multiplied by the boost-limited inverse response, then rescaled so
that the *felt* spectrum (electrical x actuator) has the 0 dB intensity level under the
spec's :class:`~vibsynth.dsp.felt_intensity.IntensityWeighting` (the paper's 80-200 Hz band,
or a calibrated profile's own weighting). With the flat default and the paper's band both
coincide.

Disk cache
----------
:func:`load_or_build` keys a ``.npz`` file by the basis id, rate, loop length, grid,
actuator response, seed and a format version (hash in the file name, full key
inside). Writes are atomic (temporary file + rename). A file that is unreadable,
truncated or whose key or shapes do not match is rebuilt with a warning, never
fatal; a cache folder that cannot be written only costs a warning.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.errors import ParameterError

if TYPE_CHECKING:
    from vibsynth.settings.models_config import Bank

__all__ = ["BankSpec", "NoiseBank", "build_bank", "felt_spectra", "load_or_build", "default_cache_dir", "CACHE_FORMAT"]

log = logging.getLogger(__name__)

#: Bump when the bank's content for the same key would change.
CACHE_FORMAT = 1

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class BankSpec:
    """What defines a bank (and its cache key).

    Attributes
    ----------
    fs : float
        Output sample rate (Hz).
    loop_seconds : float
        Loop length; ``n_samples = round(loop_seconds * fs)``.
    balance_min, balance_max : float
        Grid ends (knob units), ``balance_min < balance_max``.
    levels : int
        Grid size (>= 2).
    seed : int
        Seed of the shared random phases.
    actuator : ActuatorResponse
    intensity : IntensityWeighting
        What the knob's level means: the felt level under this weighting.
    """

    fs: float = 48000.0
    loop_seconds: float = 4.0
    balance_min: float = -3.5
    balance_max: float = 3.5
    levels: int = 49
    seed: int = 1
    actuator: ActuatorResponse = ActuatorResponse()
    intensity: IntensityWeighting = PAPER_WEIGHTING

    def __post_init__(self) -> None:
        for name in ("fs", "loop_seconds", "balance_min", "balance_max"):
            if not math.isfinite(float(getattr(self, name))):
                raise ParameterError(f"bank {name} must be finite, got {getattr(self, name)!r}")
        if self.fs < MIN_RATE_HZ or self.loop_seconds <= 0:
            raise ParameterError(
                f"bank needs a rate of at least {MIN_RATE_HZ:g} Hz (its top band reaches 1000 Hz) and a positive "
                f"loop length, got {self.fs}, {self.loop_seconds}"
            )
        if self.n_samples < 1024:
            raise ParameterError(f"bank loop of {self.n_samples} samples is too short (need >= 1024)")
        if not self.balance_min < self.balance_max:
            raise ParameterError(
                f"bank balance_min ({self.balance_min}) must be below balance_max ({self.balance_max})"
            )
        if int(self.levels) != self.levels or self.levels < 2:
            raise ParameterError(f"bank levels must be an integer >= 2, got {self.levels!r}")

    @classmethod
    def from_settings(
        cls, bank: Bank, fs: float, actuator: ActuatorResponse, intensity: IntensityWeighting = PAPER_WEIGHTING
    ) -> BankSpec:
        """The spec of the typed ``bank:`` section at sample rate ``fs`` (``audio.rate``), for ``actuator``."""
        return cls(
            intensity=intensity,
            fs=float(fs),
            loop_seconds=bank.loop_seconds,
            balance_min=bank.balance_min,
            balance_max=bank.balance_max,
            levels=bank.levels,
            seed=bank.seed,
            actuator=actuator,
        )

    @property
    def n_samples(self) -> int:
        return int(round(self.loop_seconds * self.fs))

    def balances(self) -> NDArray[np.float64]:
        """The grid, shape (levels,)."""
        return np.linspace(self.balance_min, self.balance_max, int(self.levels))

    def key(self, basis: Basis) -> dict[str, object]:
        """JSON-able cache key (the paper's band adds nothing: older caches stay valid)."""
        key: dict[str, object] = {
            "format": CACHE_FORMAT,
            "basis": basis.id,
            "fs": float(self.fs),
            "n_samples": self.n_samples,
            "grid": [float(self.balance_min), float(self.balance_max), int(self.levels)],
            "seed": int(self.seed),
            "actuator": self.actuator.key(),
        }
        if not self.intensity.is_paper:
            key["intensity"] = self.intensity.key()
        return key


@dataclass(frozen=True)
class NoiseBank:
    """Precomputed loops, one per balance level.

    Attributes
    ----------
    signals : ndarray, shape (levels, n_samples), float32
        C-contiguous; row ``i`` is the loop for ``balances[i]`` at 0 dB band level.
    balances : ndarray, shape (levels,)
    peaks : ndarray, shape (levels,)
        ``max |signals[i]|`` (what the engine's limiter uses).
    fs : float
    key : dict
        The cache key it was built for.
    """

    signals: NDArray[np.float32]
    balances: NDArray[np.float64]
    peaks: NDArray[np.float64]
    fs: float
    key: dict[str, Any]

    @property
    def levels(self) -> int:
        return int(self.signals.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.signals.shape[1])

    def channel_offsets(self, channels: int) -> NDArray[np.int64]:
        """Read offsets that decorrelate channels (evenly spread over the loop).

        Returns
        -------
        offsets : ndarray, shape (channels,)
        """
        if channels < 1:
            raise ParameterError(f"need at least one channel, got {channels}")
        return (np.arange(channels, dtype=np.int64) * self.n_samples) // channels


def _felt_power_scale(
    shaper: SpectralShaper, power: NDArray[np.float64], actuator: ActuatorResponse, intensity: IntensityWeighting
) -> NDArray[np.float64]:
    """Pre-equalise per-bin powers (levels, n_bins) in place; the felt level under ``intensity`` is 0 dB."""
    inverse = actuator.inverse_gain(shaper.freqs) ** 2
    felt = inverse * 10.0 ** (actuator.response_db(shaper.freqs) / 10.0)
    before = PAPER_WEIGHTING.levels_from_bin_powers(shaper.freqs, power)  # what solve_balance set to 0 dB
    after = power @ (intensity.power_weights(shaper.freqs) * felt)
    power *= inverse
    power *= (before / after)[:, np.newaxis]
    return power


def build_bank(basis: Basis, spec: BankSpec, *, progress: Progress | None = None) -> NoiseBank:
    """Synthesise the bank (no I/O).

    Parameters
    ----------
    basis : Basis
    spec : BankSpec
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    bank : NoiseBank
    """
    shaper = SpectralShaper(fs=spec.fs, n_samples=spec.n_samples)
    balances = spec.balances()
    if progress:
        progress(0.0, "solving spectra")
    weights = np.stack([shaper.solve_balance(basis, float(b), level_db=0.0) for b in balances])
    power = shaper.power_envelope(weights)
    if not (spec.actuator.is_flat and spec.intensity.is_paper):
        power = _felt_power_scale(shaper, power, spec.actuator, spec.intensity)
    phasors = shaper.random_phases(np.random.default_rng(spec.seed))
    signals = np.empty((balances.size, spec.n_samples), dtype=np.float32)
    chunk = 8
    for start in range(0, balances.size, chunk):
        stop = min(start + chunk, balances.size)
        signals[start:stop] = shaper.render(power[start:stop], phasors)
        if progress:
            progress(stop / balances.size, f"rendered {stop}/{balances.size} levels")
    peaks = np.abs(signals).max(axis=1).astype(np.float64)
    return NoiseBank(signals=signals, balances=balances, peaks=peaks, fs=float(spec.fs), key=spec.key(basis))


def felt_spectra(
    bank: NoiseBank, actuator: ActuatorResponse, *, max_hz: float = 1300.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-bin powers of every bank level as ``actuator`` renders them (electrical x response).

    Parameters
    ----------
    bank : NoiseBank
    actuator : ActuatorResponse
        The response the bank was equalised for.
    max_hz : float
        Bins above are left out (the texture ends at the top band's neighbour, 1172 Hz).

    Returns
    -------
    freqs : ndarray, shape (n_bins,)
    power : ndarray, shape (levels, n_bins)
        Mean-square power per bin (relative: only ratios matter to the trims).
    """
    freqs = np.asarray(np.fft.rfftfreq(bank.n_samples, 1.0 / bank.fs), dtype=np.float64)
    keep = int(np.searchsorted(freqs, max_hz, side="right"))
    freqs = freqs[:keep]
    felt = 10.0 ** (actuator.response_db(freqs) / 10.0)
    power = np.empty((bank.levels, keep))
    for i in range(bank.levels):  # one row at a time: a (levels, n/2) complex array would be ~75 MB
        spectrum = np.fft.rfft(bank.signals[i].astype(np.float64))[:keep]
        power[i] = (spectrum.real**2 + spectrum.imag**2) * felt
    return freqs, power


def default_cache_dir() -> Path:
    """The platform cache folder for banks (``~/.cache/vibsynth/banks`` on Linux)."""
    import platformdirs

    return Path(platformdirs.user_cache_dir("vibsynth")) / "banks"


def cache_path(cache_dir: Path, key: dict[str, Any]) -> Path:
    """File name of a bank in a cache folder (hash of the key)."""
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return Path(cache_dir) / f"bank-{digest}.npz"


def _read_cache(path: Path, key: dict[str, Any], fs: float) -> NoiseBank:
    with np.load(path, allow_pickle=False) as data:
        stored_key = json.loads(str(data["key"]))
        if stored_key != json.loads(json.dumps(key)):
            raise ValueError("key mismatch")
        signals = np.ascontiguousarray(data["signals"], dtype=np.float32)
        balances = np.asarray(data["balances"], dtype=np.float64)
        peaks = np.asarray(data["peaks"], dtype=np.float64)
    levels, n = key["grid"][2], key["n_samples"]
    if signals.shape != (levels, n) or balances.shape != (levels,) or peaks.shape != (levels,):
        raise ValueError("shape mismatch")
    if not (np.all(np.isfinite(peaks)) and np.all(peaks > 0)):
        raise ValueError("bad peaks")
    return NoiseBank(signals=signals, balances=balances, peaks=peaks, fs=fs, key=key)


def _write_cache(path: Path, bank: NoiseBank) -> None:
    """Write the cache file through :func:`vibsynth.formats.files.atomic_write`, streamed (no in-memory copy)."""
    from vibsynth.formats.files import atomic_write

    def write(handle: BinaryIO) -> None:
        np.savez(
            handle, signals=bank.signals, balances=bank.balances, peaks=bank.peaks, key=np.array(json.dumps(bank.key))
        )

    atomic_write(path, write)


def load_or_build(
    basis: Basis,
    spec: BankSpec,
    *,
    cache_dir: str | os.PathLike[str] | None = None,
    progress: Progress | None = None,
) -> tuple[NoiseBank, str]:
    """The bank from the disk cache, or built (and cached).

    Parameters
    ----------
    basis : Basis
    spec : BankSpec
    cache_dir : path-like, optional
        None = :func:`default_cache_dir`; ``""`` disables the cache.
    progress : callable, optional

    Returns
    -------
    bank : NoiseBank
    origin : {"cached", "built", "rebuilt"}
        "rebuilt" when a cache file existed but was unusable (a warning was logged).
    """
    key = spec.key(basis)
    if cache_dir == "":
        return build_bank(basis, spec, progress=progress), "built"
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache_path(folder, key)
    origin = "built"
    if path.exists():
        started = time.perf_counter()
        try:
            bank = _read_cache(path, key, float(spec.fs))
            log.info("bank loaded from %s in %.0f ms", path, 1000 * (time.perf_counter() - started))
            return bank, "cached"
        except Exception as exc:  # any corruption: rebuild, never fatal
            log.warning("bank cache %s is unusable (%s); rebuilding it", path, exc)
            origin = "rebuilt"
    bank = build_bank(basis, spec, progress=progress)
    try:
        _write_cache(path, bank)
    except OSError as exc:
        log.warning("cannot write bank cache %s (%s); continuing without it", path, exc)
    return bank, origin
