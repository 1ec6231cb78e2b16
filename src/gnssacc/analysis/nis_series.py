"""The EKF's position NIS over the run, as ``nis.png`` and ``summary.png`` show it: a moving mean
over a window of updates that never spans a GNSS outage, the chi-square band of such a mean, and
the fraction of the run the moving mean lies inside that band.

A run's mean NIS can sit inside its band while the moving mean lies outside it for most of the
run (an early burst averaged with a quiet rest): the fraction in band says which.
"""

from __future__ import annotations

import numpy as np

from ..core.distributions import chi2_ppf

#: Updates averaged by the moving mean (``nis.png``'s window).
WINDOW = 20
#: A step between updates longer than this many times their median step ends a segment (an outage).
GAP_FACTOR = 3.0


def segments(t: np.ndarray, factor: float = GAP_FACTOR) -> list[slice]:
    """Slices of ``t`` between its gaps (steps above ``factor`` times the median step)."""
    t = np.asarray(t, float)
    if len(t) < 3:
        return [slice(0, len(t))]
    dt = np.diff(t)
    cuts = np.flatnonzero(dt > factor * np.median(dt)) + 1
    edges = [0, *cuts.tolist(), len(t)]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def moving_mean(t: np.ndarray, x: np.ndarray, window: int = WINDOW) -> np.ndarray:
    """The mean of the last ``window`` values at each sample, NaN until a segment (see
    :func:`segments`) has that many: no mean spans a gap."""
    x = np.asarray(x, float)
    out = np.full(len(x), np.nan)
    for s in segments(t):
        seg = x[s]
        if len(seg) < window:
            continue
        c = np.cumsum(np.insert(seg, 0, 0.0))
        out[s.start + window - 1 : s.stop] = (c[window:] - c[:-window]) / window
    return out


def band_of_mean(window: int = WINDOW, dof: int = 3, level: float = 0.997) -> tuple[float, float]:
    """Two-sided ``level`` band of a mean of ``window`` independent NIS values per dof."""
    k = dof * window
    a = (1.0 - level) / 2.0
    return chi2_ppf(a, k) / k, chi2_ppf(1.0 - a, k) / k


def fraction_in_band(t: np.ndarray, nis: np.ndarray, window: int = WINDOW) -> float | None:
    """Fraction of the moving means (:func:`moving_mean`) inside :func:`band_of_mean`; ``None``
    when no segment holds ``window`` updates."""
    m = moving_mean(t, nis, window)
    m = m[np.isfinite(m)]
    if not len(m):
        return None
    lo, hi = band_of_mean(window)
    return float(np.mean((m >= lo) & (m <= hi)))
