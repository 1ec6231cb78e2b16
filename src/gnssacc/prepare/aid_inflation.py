r"""How much a ground-vehicle aid's white sigma must grow to stand for its errors' correlation.

An aid applied every update as white noise of variance ``sigma^2`` whose errors are correlated
from one update to the next (slip through a turn, the suspension's pitch under acceleration, a
residual mounting angle times a varying speed) is averaged by the filter as if each update were
independent. Over a filter memory of many updates the mean of ``N`` such errors has the variance
``sigma^2 tau / N``, ``tau = 1 + 2 sum_k rho(k)`` the errors' integrated autocorrelation time
[updates] (their spectral density at zero frequency relative to white noise of the same
variance): the white model that states what the filter averages has the sigma ``sqrt(tau)``
times larger (``sqrt((1 + phi) / (1 - phi))`` for a first-order error of correlation ``phi``
from update to update). Applying the aid once every ``tau`` updates with the white sigma carries
the same information (a decorrelation interval); the inflation keeps the aid's epochs and both
estimators as they are.

Why not from the aid's own innovations
--------------------------------------
The filter follows a slowly varying aid error with its state: with a gain ``K`` on a state that
the aid's updates pull, the innovation is ``nu = (1 - z^-1) / (1 - (1 - K) z^-1) e`` of the error
``e``, a high-pass with a zero at zero frequency. The slow part of ``e``, which is what ``tau``
measures, is missing from the innovations: their autocorrelations sum to about zero whatever
``tau`` is (on KITTI the constraint's innovations: 0.39, 0.20, 0.04 at lags 1-3, then within
noise and below zero, ``tau`` 2.3 summed to Geyer's cut; the lag-1 form ``(1 + r) / (1 - r)``
2.3 as well, against about 12 that made the positions consistent). A likelihood of the aid's own
one-step innovations cannot see ``tau`` either: it fits the white sigma of the high-passed part.

The measurements the aid's errors do not enter see it: a filter that trusts a correlated aid too
much predicts the next GNSS fixes (and zero-rate updates) with a covariance too small for the
errors the aid has pulled into its state. So the factor is identified by the predictive
likelihood of those other updates (:func:`correlation_inflation`): the aid's sigma grows by
``10**d`` while that likelihood rises by more than :data:`MIN_GAIN` over the white fit (a
likelihood-ratio test; ``d >= 0``: the white fit's sigma is the least the aid's own innovations
allow). The search starts from the sigma in use wherever the white fit left it, at a floor too:
the likelihood decides there as anywhere, so two fits a hair apart end a hair apart. On KITTI
seed 0 the fixes' log-likelihood rises by 37 from the white fit to a factor of about 3.5 on the
constraint's sigmas, and falls again beyond.
"""

from __future__ import annotations

from collections.abc import Callable

#: Log-likelihood gain of the other updates an inflation must bring to be applied: half the
#: 1e-3 quantile of chi-square with 1 dof (a likelihood-ratio test; the white fit is the model
#: without it).
MIN_GAIN = 5.41
#: Step of the search [decades of the sigma].
STEP_DECADES = 0.25
#: Largest inflation searched [decades]: a factor of 100, a correlation time 10^4 updates long.
MAX_DECADES = 2.0


def climb(
    loglik: Callable[[float], float], step: float = STEP_DECADES, top: float = MAX_DECADES
) -> tuple[float, float, int]:
    """The ``d`` in ``[0, top]`` that maximises ``loglik(d)``: steps of ``step`` up from 0 while
    it rises, then the vertex of the parabola through the best step and its neighbours
    (evaluated, kept when better). Returns ``d``, ``loglik(d) - loglik(0)`` and the evaluations
    made."""
    grid = [0.0]
    values = [float(loglik(0.0))]
    while grid[-1] < top - 1e-12:
        grid.append(min(grid[-1] + step, top))
        values.append(float(loglik(grid[-1])))
        if values[-1] <= values[-2]:
            break
    best = max(range(len(grid)), key=values.__getitem__)
    d, value = grid[best], values[best]
    if 0 < best < len(grid) - 1:
        (a, fa), (b, fb), (c, fc) = zip(grid[best - 1 : best + 2], values[best - 1 : best + 2])
        den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
        if den != 0.0:
            vertex = b - 0.5 * ((b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)) / den
            if a < vertex < c and vertex != b:
                fv = float(loglik(vertex))
                grid.append(vertex)
                if fv > value:
                    d, value = vertex, fv
    return d, value - values[0], len(grid)


def correlation_inflation(loglik: Callable[[float], float]) -> tuple[float, int]:
    """The factor on an aid's white sigma that makes it stand for errors correlated in time.

    Parameters
    ----------
    loglik : callable
        ``d`` [decades] -> the log-likelihood of the updates the aid's errors do not enter (the
        GNSS fixes, the zero-rate updates) of one filter pass with the aid's sigmas times
        ``10**d``.

    Returns
    -------
    factor : float
        ``10**d`` at the maximum of :func:`climb` when it gains more than :data:`MIN_GAIN` over
        ``d = 0``, otherwise 1.
    evaluations : int
        The passes made.
    """
    d, gain, n = climb(loglik)
    return (10.0**d if gain > MIN_GAIN else 1.0), n
