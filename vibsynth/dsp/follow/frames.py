"""What the tracker gives per frame."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

__all__ = ["TrackFrames"]


@dataclass(frozen=True)
class TrackFrames:
    """The frames completed by one block (or a whole signal), all arrays of shape (n_frames,).

    Attributes
    ----------
    end_sample : ndarray of int64
        Absolute input sample index (at the input rate) where each frame ends.
    level_db : ndarray of float64
        Input level: vibration mode the 80-200 Hz band level (dB re unit RMS), audio mode the
        fast K-weighted loudness (LUFS-like); ``-inf`` for silence.
    intensity : ndarray of float64
        Intensity knob 0..1 (0 = gate closed or silence).
    balance : ndarray of float64
        Balance knob, within the live range.
    gate_open : ndarray of bool
    onset_strength : ndarray of float64
        0 = no onset in the frame; otherwise the transient's strength in (0, 1].
    """

    end_sample: NDArray[np.int64]
    level_db: NDArray[np.float64]
    intensity: NDArray[np.float64]
    balance: NDArray[np.float64]
    gate_open: NDArray[np.bool_]
    onset_strength: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.end_sample.size)

    @classmethod
    def empty(cls) -> TrackFrames:
        f = np.zeros(0)
        return cls(np.zeros(0, dtype=np.int64), f, f.copy(), f.copy(), np.zeros(0, dtype=bool), f.copy())

    @classmethod
    def concat(cls, parts: Sequence[TrackFrames]) -> TrackFrames:
        """Join consecutive frame sets."""
        if not parts:
            return cls.empty()
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))
