r"""How fast the fixes' error wanders, from the fixes themselves [m^2/s].

Beside the white scatter from one fix to the next (the sigma a recording states, or what
:mod:`gnssacc.prepare.fix_noise` measures when it states none), fix errors wander over tens of
seconds: a receiver's own position filter, multipath, the atmosphere. Over the few seconds the
stationary check looks at (:mod:`gnssacc.prepare.stationary`, step 4) such a wander acts as a
random walk of rate ``q`` per horizontal axis: the error moves by ``sqrt(q dt)`` in ``dt``
seconds. A check that knows only the white scatter reads a parked vehicle's fixes as a creep of
several cm/s at tens of sigma (a slow rover's 20 Hz receiver-filtered fixes, 0.6 m wandering over
30 s: 0.07-0.13 m/s against sigmas of 0.003-0.012 m/s) and refuses every stop of the run.

``q`` is read where the vehicle's own motion cannot hide it: inside the IMU-still stretches, at
rest or cruising at a constant velocity, where the true position's second difference is zero.
There the second difference of the fixes at a lag of ``m`` fixes,
``d = p(k+m) - 2 p(k) + p(k-m)``, has per axis

    E[d^2] = 6 s^2 + q (t(k+m) - t(k-m))

for white scatter ``s`` and a random walk ``q`` (independent increments on both sides). The
triples are taken at the shortest lag and at a quarter of each stretch's fixes (the time scale of
the check), without overlap, so that each ``d^2`` is an independent ``E[d^2] chi^2_1`` term; a
weighted least-squares line through them gives ``q`` and its standard error. ``q`` is kept only
where it exceeds :data:`MIN_Z` standard errors (and is zero otherwise, the white model): the
check then allows for a wander the fixes prove, never for one that a few triples might suggest.
What the wander adds to the check's variances is here too (:func:`slope_variance`,
:func:`spread_from_span`), so that its tests share one model of it.
"""

from __future__ import annotations

import numpy as np

#: Standard errors by which the wander rate must exceed zero to be used.
MIN_Z = 3.0
#: Shortest stretch, in fixes, that gives triples at a long lag (two lags of at least 2 fixes).
MIN_FIXES = 9


def _triples(t: np.ndarray, p: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Squared second differences at lag ``m`` fixes, per axis, of non-overlapping triples, and
    the time each spans [s]."""
    k = np.arange(m, len(t) - m, 2 * m)
    d = p[k + m] - 2.0 * p[k] + p[k - m]
    span = t[k + m] - t[k - m]
    return (d**2).reshape(-1), np.repeat(span, p.shape[1])


def _line(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares ``y = a + q x`` for chi-square(1) terms of mean ``a + q x`` (weight
    ``1 / (2 mean^2)``, the means from an unweighted fit first): ``[a, q]`` and their covariance."""
    A = np.column_stack([np.ones_like(x), x])
    beta = np.linalg.lstsq(A, y, rcond=None)[0]
    for _ in range(2):
        mean = np.maximum(A @ beta, 1e-3 * max(float(np.mean(y)), 1e-12))
        w = 1.0 / (2.0 * mean**2)
        info = A.T @ (A * w[:, None])
        beta = np.linalg.solve(info, A.T @ (w * y))
    return beta, np.linalg.inv(info)


def fix_wander(t: np.ndarray, p_h: np.ndarray, stretches: list[tuple[float, float]]) -> float:
    """The horizontal fixes' random-walk rate ``q`` per axis [m^2/s] (module notes), 0 unless the
    fixes inside the IMU-still ``stretches`` prove it.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Fix times [s], increasing.
    p_h : ndarray, shape (M, 2)
        Fix positions north / east [m].
    stretches : list of (float, float)
        IMU-still stretches ``(t_start, t_end)`` [s].

    Returns
    -------
    float
        ``q`` [m^2/s]: the fix error's variance grows by ``q dt`` per axis over ``dt`` seconds.
    """
    ys, xs = [], []
    for t0, t1 in stretches:
        k0, k1 = np.searchsorted(t, t0, side="left"), np.searchsorted(t, t1, side="right")
        if k1 - k0 < MIN_FIXES:
            continue
        tt, pp = t[k0:k1], p_h[k0:k1]
        for m in (1, max((k1 - k0 - 1) // 4, 2)):
            y, x = _triples(tt, pp, m)
            ys.append(y)
            xs.append(x)
    if not ys:
        return 0.0
    y, x = np.concatenate(ys), np.concatenate(xs)
    if len(y) < 4 or np.ptp(x) <= 0.0:
        return 0.0
    beta, cov = _line(x, y)
    q, se = float(beta[1]), float(np.sqrt(max(cov[1, 1], 0.0)))
    return q if q > MIN_Z * se else 0.0


def slope_variance(wander: float, duration_s: float) -> float:
    """What a random walk of rate ``wander`` [m^2/s] adds to the variance of a least-squares
    slope through fixes spanning ``duration_s`` [s]: ``6 q / (5 T)`` [(m/s)^2]."""
    return 1.2 * wander / max(float(duration_s), 1e-9)


def spread_from_span(wander: float, t: np.ndarray, t_start: float, t_end: float) -> np.ndarray:
    """What a random walk of rate ``wander`` [m^2/s] adds to the variance of fixes at times ``t``
    [s] about a span's mean fix: ``q (d + duration / 3)`` [m^2], ``d`` the time outside the span
    (zero inside), ``duration / 3`` the spread of the walk over the span about its mean."""
    t = np.asarray(t, float)
    away = np.maximum(t_start - t, 0.0) + np.maximum(t - t_end, 0.0)
    return wander * (away + (t_end - t_start) / 3.0)
