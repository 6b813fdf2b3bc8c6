"""Fit a basis from a folder of recordings or from a table of PSDs.

The default basis shipped in ``vibsynth/data/default_basis.yaml`` is made by
:func:`fit_default_basis` from ``shared/datasets/hatt-psd/psd.csv.gz``
(regenerate with ``python scripts/fit_default_basis.py``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from vibsynth._version import __version__
from vibsynth.dsp.basis import Basis, band_powers_from_psd, fit_basis, to_db
from vibsynth.dsp.filterbank import band_powers
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.psd import read_psd_table
from vibsynth.formats.recordings import iter_recordings, read_recording

__all__ = ["HATT_CITATION", "fit_from_psd_table", "fit_from_recordings", "fit_default_basis", "Progress"]

Progress = Callable[[int, int, str], None]

HATT_CITATION = (
    'H. Culbertson, J. J. Lopez Delgado, K. J. Kuchenbecker, "One hundred data-driven haptic texture '
    'models and open-source methods for rendering on 3D objects", IEEE Haptics Symposium 2014.'
)
HATT_TERMS = "The Penn Haptic Texture Toolkit's terms allow non-profit research use; cite the paper above."

_METHOD = (
    "PCA (SVD) over 30-band dB spectra (analog 2nd-order Butterworth band-pass bank, 30 bands, 10-1000 Hz), "
    "each spectrum's mean dB across bands removed first; every spectrum weighs the same; "
    "V1 oriented so that positive t1 = more high-frequency energy."
)


def fit_from_psd_table(path: str | os.PathLike[str], *, provenance: dict[str, str] | None = None) -> Basis:
    """Fit a basis from a PSD table (see :func:`vibsynth.formats.psd.read_psd_table`).

    Parameters
    ----------
    path : path-like
        CSV (optionally gzipped): label column(s), then one column per frequency in Hz.
    provenance : dict, optional
        Extra provenance fields.

    Returns
    -------
    basis : Basis
    """
    table = read_psd_table(path)
    band_db = to_db(band_powers_from_psd(table.freqs_hz, table.psd))
    info = {
        "source": Path(path).name,
        "source_kind": "psd-table",
        "n_labels": str(len(set(table.labels))),
        "method": _METHOD,
        "created_by": f"vibsynth {__version__}",
    }
    info.update(provenance or {})
    return fit_basis(band_db, provenance=info)


def fit_from_recordings(
    folder: str | os.PathLike[str],
    *,
    fs: float | None = None,
    progress: Progress | None = None,
    provenance: dict[str, str] | None = None,
) -> Basis:
    """Fit a basis from every recording (.wav, .csv, .txt) in a folder.

    Parameters
    ----------
    folder : path-like
    fs : float, optional
        Sample rate of CSV/TXT recordings.
    progress : callable, optional
        Called as ``progress(done, total, name)`` after each file.
    provenance : dict, optional

    Returns
    -------
    basis : Basis

    Raises
    ------
    InputError
        The folder is missing or has too few recordings; a recording is unusable
        (the message names it).
    """
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    files = list(iter_recordings(root))
    if not files:
        raise InputError(f"{root}: no recordings (.wav, .csv, .txt) found")
    spectra = []
    for i, path in enumerate(files, start=1):
        rec = read_recording(path, fs=fs)
        try:
            powers = band_powers(rec.samples, fs=rec.fs)
        except ParameterError as exc:
            raise InputError(f"{path}: {exc}") from None
        if not np.all(powers > 0):
            raise InputError(f"{path}: silent in some of the 10-1000 Hz bands")
        spectra.append(to_db(powers))
        if progress is not None:
            progress(i, len(files), path.name)
    info = {
        "source": str(root.name),
        "source_kind": "recordings",
        "n_files": str(len(files)),
        "method": _METHOD,
        "created_by": f"vibsynth {__version__}",
    }
    info.update(provenance or {})
    try:
        return fit_basis(np.stack(spectra), provenance=info)
    except ParameterError as exc:
        raise InputError(f"{root}: {exc}") from None


def fit_default_basis(psd_path: str | os.PathLike[str]) -> Basis:
    """Fit the shipped default basis from ``hatt-psd/psd.csv.gz`` with its provenance."""
    return fit_from_psd_table(
        psd_path,
        provenance={
            "source": "shared/datasets/hatt-psd/psd.csv.gz",
            "dataset": "Spectra of the Penn Haptic Texture Toolkit (HaTT) texture models: "
            "1,425 AR-model PSDs of 100 textures, many scanning speeds and forces",
            "citation": HATT_CITATION,
            "terms": HATT_TERMS,
            "caveats": "Below about 30 Hz the AR(20) models at 10 kHz are nearly flat (extrapolated); "
            "quiet smooth textures are dominated by sensor noise and look bright.",
            "created_by": "vibsynth (scripts/fit_default_basis.py)",
        },
    )
