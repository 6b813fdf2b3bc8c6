"""PSD tables: a CSV of power spectral densities, one column per texture (basis fitting input)."""

from __future__ import annotations

import csv
import gzip
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    pass


@dataclass(frozen=True)
class PsdTable:
    """A table of one-sided PSDs (one row per spectrum).

    Attributes
    ----------
    freqs_hz : ndarray, shape (n_freqs,)
    psd : ndarray, shape (n_rows, n_freqs)
    labels : list of str
        First column (e.g. texture name) of each row.
    meta : list of dict
        Other non-frequency columns of each row (e.g. speed, force), as strings.
    """

    freqs_hz: NDArray[np.float64]
    psd: NDArray[np.float64]
    labels: list[str]
    meta: list[dict[str, str]]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_psd_table(path: str | os.PathLike[str]) -> PsdTable:
    """Read a PSD table (CSV, optionally gzipped) like ``hatt-psd/psd.csv.gz``.

    Columns whose header is a number are frequencies in Hz; the first other
    column is the label, the rest are kept as metadata.

    Raises
    ------
    InputError
        Missing file, no frequency columns, ragged rows, non-numeric or non-positive PSD values.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    opener = gzip.open if p.suffix == ".gz" else open
    try:
        with opener(p, "rt", newline="", encoding="utf-8") as handle:
            reader = csv.reader(handle)
            header = next(reader)
            freq_cols = [i for i, h in enumerate(header) if _is_number(h)]
            other_cols = [i for i, h in enumerate(header) if not _is_number(h)]
            if len(freq_cols) < 2:
                raise InputError(f"{p}: no frequency columns (headers that are numbers in Hz)")
            rows, labels, meta = [], [], []
            for line_no, row in enumerate(reader, start=2):
                if len(row) != len(header):
                    raise InputError(f"{p}:{line_no}: has {len(row)} fields, header has {len(header)}")
                try:
                    rows.append([float(row[i]) for i in freq_cols])
                except ValueError:
                    raise InputError(f"{p}:{line_no}: PSD value is not a number") from None
                labels.append(row[other_cols[0]] if other_cols else str(line_no))
                meta.append({header[i]: row[i] for i in other_cols[1:]})
    except (OSError, EOFError, StopIteration, UnicodeDecodeError, gzip.BadGzipFile) as exc:
        raise InputError(f"{p}: cannot read PSD table ({exc})") from None
    psd = np.asarray(rows, dtype=np.float64)
    freqs = np.asarray([float(header[i]) for i in freq_cols])
    if psd.size == 0:
        raise InputError(f"{p}: has no rows")
    if not np.all(np.isfinite(psd)) or np.any(psd <= 0):
        raise InputError(f"{p}: PSD values must be finite and positive")
    return PsdTable(freqs_hz=freqs, psd=psd, labels=labels, meta=meta)
