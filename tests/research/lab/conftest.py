"""Fixtures of the lab tests: stimulus folders made from the real HaTT texture spectra, a preset library."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

#: Textures of the Penn Haptic Texture Toolkit spanning bright to dull spectra (one model each).
HATT_TEXTURES = ("Brick 1", "Cork", "Carpet 1", "Book", "ABS Plastic", "Aluminum Foil")
#: The paper's stimuli were at 2800 Hz.
RATE = 2800.0


def hatt_recording(freqs_hz: np.ndarray, psd: np.ndarray, *, seconds: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary vibration whose spectrum is a HaTT model's PSD ((m/s^2)^2/Hz -> samples in m/s^2).

    Random-phase noise with the PSD's magnitudes (interpolated log-log on the FFT grid), so the
    recording's band powers and levels are those of the real texture model.
    """
    n = int(round(seconds * RATE))
    grid = np.fft.rfftfreq(n, 1.0 / RATE)
    inside = np.clip(grid, freqs_hz[0], freqs_hz[-1])
    density = np.exp(np.interp(np.log(inside), np.log(freqs_hz), np.log(psd)))
    density[0] = 0.0
    # one-sided PSD -> |X_k|^2 with numpy's unnormalised rfft: P(f) df = 2 |X_k|^2 / n^2
    magnitude = np.sqrt(density * (RATE / n) * n**2 / 2.0)
    phases = np.exp(2j * np.pi * rng.random(grid.size))
    return np.fft.irfft(magnitude * phases, n=n)


@pytest.fixture(scope="session")
def hatt_folder(hatt_psd, tmp_path_factory) -> Path:
    """A folder of 6 WAVs (1.5 s at 2800 Hz, float32) made from 6 HaTT textures' spectra."""
    from vibsynth.formats.psd import read_psd_table
    from vibsynth.formats.recordings import write_wav

    table = read_psd_table(hatt_psd)
    folder = tmp_path_factory.mktemp("hatt-stimuli")
    rng = np.random.default_rng(17)
    for name in HATT_TEXTURES:
        row = table.labels.index(name)
        samples = hatt_recording(table.freqs_hz, table.psd[row], seconds=1.5, rng=rng)
        write_wav(folder / f"{name}.wav", samples, RATE)
    return folder


@pytest.fixture(scope="session")
def presets():
    """The shipped presets (18: the paper's number of stimuli)."""
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    return PresetLibrary(shipped_presets_dir(), None).presets
