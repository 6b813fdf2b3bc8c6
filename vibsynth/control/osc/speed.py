"""The speed curve: finger speed (mm/s) -> intensity, for ``/vibsynth/ch/{n}/speed``."""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

from vibsynth.errors import ConfigError


class SpeedCurve:
    """Scanning speed (mm/s) -> intensity, piecewise linear; optional balance shift.

    Parameters
    ----------
    points : sequence of (mm/s, intensity)
        Strictly increasing speeds >= 0, intensities in [0, 1]. Below the first point the
        first intensity applies, above the last the last one. The default
        ``[[0, 0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1]]`` is silent at rest.
    balance_per_decade : float
        Balance added per decade of speed above 100 mm/s (0 = speed leaves balance alone).

    Raises
    ------
    ConfigError
        If the points are not a valid curve.
    """

    REFERENCE_MM_S = 100.0

    def __init__(self, points: Sequence[Sequence[float]], balance_per_decade: float = 0.0) -> None:
        try:
            pts = [(float(s), float(v)) for s, v in points]
            self.balance_per_decade = float(balance_per_decade)
        except (TypeError, ValueError):
            raise ConfigError("speed.curve must be a list of [mm/s, intensity] pairs") from None
        if len(pts) < 1 or not all(math.isfinite(s) and math.isfinite(v) for s, v in pts):
            raise ConfigError("speed.curve needs at least one finite [mm/s, intensity] point")
        if any(s < 0 or not 0.0 <= v <= 1.0 for s, v in pts):
            raise ConfigError("speed.curve speeds must be >= 0 and intensities within [0, 1]")
        if any(b[0] <= a[0] for a, b in zip(pts, pts[1:])):
            raise ConfigError("speed.curve speeds must be strictly increasing")
        if not math.isfinite(self.balance_per_decade):
            raise ConfigError("speed.balance_per_decade must be finite")
        self.speeds = [s for s, _ in pts]
        self.levels = [v for _, v in pts]

    def intensity(self, speed: float) -> float:
        """Intensity for a speed in mm/s (>= 0)."""
        xs, ys = self.speeds, self.levels
        if speed <= xs[0]:
            return ys[0]
        if speed >= xs[-1]:
            return ys[-1]
        i = bisect.bisect_right(xs, speed)
        x0, x1, y0, y1 = xs[i - 1], xs[i], ys[i - 1], ys[i]
        return y0 + (y1 - y0) * (speed - x0) / (x1 - x0)

    def balance_shift(self, speed: float) -> float:
        """Balance offset for a speed (0 at and below 100 mm/s)."""
        if self.balance_per_decade == 0.0 or speed <= self.REFERENCE_MM_S:
            return 0.0
        return self.balance_per_decade * math.log10(speed / self.REFERENCE_MM_S)
