"""The acceleration effect as a paired difference: the figure data of ``accel_effect.png``.

Per pair of methods that differ only in the GNSS-derived acceleration (``ekf-acc`` and ``ekf``,
``smoother-acc`` and ``smoother``), the per-epoch difference ``d = aided - base`` of the horizontal
error [m] (with truth), or of the horizontal distance to the raw fixes [m] (without truth: the
agreement with the fixes, not accuracy). Negative ``d`` means the acceleration helps.

The per-epoch differences are correlated in time (the two estimates drift together), so the 95 %
interval of their mean comes from batch means: the run cut into :data:`N_BATCHES` consecutive
blocks, a Student-t interval over the block means. Without that the interval would be many times
too narrow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from .metrics import state_errors

#: ``(base, aided)`` method pairs compared, in the figure's order.
PAIRS = (("ekf", "ekf-acc"), ("smoother", "smoother-acc"))
#: Consecutive blocks whose means give the interval of the mean difference.
N_BATCHES = 20


@dataclass
class PairedDifference:
    """One pair's per-epoch difference and its mean with a 95 % interval.

    Attributes
    ----------
    base, aided : str
        Method ids (``d = aided - base``).
    t : ndarray, shape (K,)
        Epochs [s, the run's clock].
    d : ndarray, shape (K,)
        Difference of the horizontal error (or distance to the fixes) [m].
    mean, lo, hi : float
        Mean of ``d`` and its 95 % interval [m] (batch means).
    n_batches : int
        Blocks behind the interval.
    truth : bool
        Whether ``d`` is of errors against the truth (else of distances to the raw fixes).
    base_mean : float
        The base method's mean horizontal error (or distance) at the same epochs [m]: the scale
        of the difference.
    """

    base: str
    aided: str
    t: np.ndarray
    d: np.ndarray
    mean: float
    lo: float
    hi: float
    n_batches: int
    truth: bool
    base_mean: float = float("nan")

    @property
    def decided(self) -> bool:
        """Whether the interval excludes zero (the sign of the effect is told by the run)."""
        return self.hi < 0 or self.lo > 0


def batch_interval(d: np.ndarray, n_batches: int = N_BATCHES) -> tuple[float, float, float, int]:
    """``(mean, lo, hi, k)``: the mean of ``d`` and its 95 % Student-t interval over ``k``
    consecutive block means (``k`` at most ``n_batches``, each block at least 2 values)."""
    from ..core.distributions import t_ppf

    d = np.asarray(d, float)
    d = d[np.isfinite(d)]
    mean = float(np.mean(d)) if len(d) else float("nan")
    k = min(n_batches, len(d) // 2)
    if k < 2:
        return mean, float("nan"), float("nan"), k
    means = np.array([b.mean() for b in np.array_split(d, k)])
    half = t_ppf(0.975, k - 1) * means.std(ddof=1) / np.sqrt(k)
    return mean, mean - half, mean + half, k


def horizontal_distance(
    run: RecordedRun, sol: NavSolution, truth: bool
) -> tuple[np.ndarray, np.ndarray]:
    """``(t, distance)``: the horizontal error [m] at the solution epochs (``truth``), or the
    horizontal distance [m] of the solution (interpolated) to each raw fix inside its span."""
    if truth:
        e = state_errors(run, sol)
        return np.asarray(sol.t, float), np.hypot(e[:, 0], e[:, 1])
    g = run.gnss
    inside = (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    f = run.origin.to_ned(g.lat[inside], g.lon[inside], g.h[inside])
    d = np.hypot(*[np.interp(g.t[inside], sol.t, p[:, i]) - f[:, i] for i in range(2)])
    return g.t[inside], d


def paired_difference(
    run: RecordedRun, base: NavSolution, aided: NavSolution, truth: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, aided - base, base)`` at the base's epochs where both are defined (the aided distance
    interpolated when its epochs differ)."""
    t0, d0 = horizontal_distance(run, base, truth)
    t1, d1 = horizontal_distance(run, aided, truth)
    if len(t1) != len(t0) or not np.array_equal(t0, t1):
        ok1 = np.isfinite(d1)
        if not np.any(ok1):
            return t0[:0], d0[:0], d0[:0]
        inside = (t0 >= t1[ok1][0]) & (t0 <= t1[ok1][-1])
        d1 = np.where(inside, np.interp(t0, t1[ok1], d1[ok1]), np.nan)
    d = d1 - d0
    ok = np.isfinite(d)
    return t0[ok], d[ok], d0[ok]


def accel_effects(run: RecordedRun, sols: dict[str, NavSolution]) -> list[PairedDifference]:
    """The paired difference of every pair of :data:`PAIRS` the run has both methods of."""
    truth = run.truth is not None
    out = []
    for base, aided in PAIRS:
        if base not in sols or aided not in sols:
            continue
        t, d, d0 = paired_difference(run, sols[base], sols[aided], truth)
        if len(d) < 4:
            continue
        mean, lo, hi, k = batch_interval(d)
        out.append(PairedDifference(base, aided, t, d, mean, lo, hi, k, truth, float(d0.mean())))
    return out
