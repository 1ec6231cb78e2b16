"""Nelder-Mead, step for step as scipy's (``scipy.optimize.minimize(method="Nelder-Mead")`` with
an initial simplex, no bounds, not adaptive), that says ahead which points it may ask for next.

The tuner's objective is an EKF pass; the points a step may need are known before the step (the
reflection, and after it the expansion or one of the two contractions; a shrink's new
vertices), so they can be evaluated side by side (:meth:`gnssacc.prepare.tuning._Objective`'s
``ahead``) and the step then finds them done. The search itself asks for the same points in the
same order as scipy's and ends where scipy's ends (``tests/test_nelder_mead.py`` replays scipy's
on test functions, point for point), so what is evaluated ahead changes the wall time only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

# scipy's coefficients (reflection, expansion, contraction, shrink; not adaptive).
_RHO, _CHI, _PSI, _SIGMA = 1.0, 2.0, 0.5, 0.5


#: Processes from which a step's second point is guessed and evaluated with its reflection (with
#: fewer, the guess, needed about half the time, would cost a loaded machine more than it saves).
GUESS_WIDTH = 3


class _Budget(Exception):
    """The evaluations are used up (scipy's ``_MaxFuncCallError``)."""


def nelder_mead(
    fun: Callable[[np.ndarray], float],
    simplex: np.ndarray,
    maxfev: int,
    xatol: float,
    fatol: float,
    ahead: Callable[[list], None] | None = None,
    width: int = 1,
) -> None:
    """Minimise ``fun`` from ``simplex`` ((n + 1, n)) within ``maxfev`` calls (module notes).

    Parameters
    ----------
    fun : callable
        ``x (n,) -> float``; the caller keeps the best point it was called at.
    simplex : ndarray (n + 1, n)
    maxfev : int
    xatol, fatol : float
        scipy's convergence tolerances (all vertices within ``xatol`` of the best and their values
        within ``fatol``).
    ahead : callable, optional
        Told the points a step may ask for before it asks (at most ``width``, the likeliest
        first); it may evaluate them, ``fun`` is called for them all the same.
    width : int
        How many points ``ahead`` may be told at once (the processes that can evaluate them).
    """
    sim = np.asarray(simplex, float).copy()
    n = sim.shape[1]
    calls = [0]

    def f(x):
        if calls[0] >= maxfev:
            raise _Budget
        calls[0] += 1
        return float(fun(np.copy(x)))

    fsim = np.full(n + 1, np.inf)
    _tell(ahead, list(sim[: min(n + 1, maxfev)]), width, all_of=True)
    try:
        for k in range(n + 1):
            fsim[k] = f(sim[k])
    except _Budget:
        pass
    order = np.argsort(fsim)
    sim, fsim = np.take(sim, order, 0), np.take(fsim, order, 0)
    order = np.argsort(fsim)
    fsim, sim = np.take(fsim, order, 0), np.take(sim, order, 0)
    last = "xc"  # the kind of point the last step needed after its reflection
    while calls[0] < maxfev:
        try:
            if (
                np.max(np.ravel(np.abs(sim[1:] - sim[0]))) <= xatol
                and np.max(np.abs(fsim[0] - fsim[1:])) <= fatol
            ):
                break
            last = _step(f, sim, fsim, ahead, width, last)
        except _Budget:
            pass
        order = np.argsort(fsim)
        sim, fsim = np.take(sim, order, 0), np.take(fsim, order, 0)


def _step(f, sim, fsim, ahead, width, last: str) -> str:
    """One of scipy's iterations on ``sim``/``fsim`` (in place); the kind of its second point."""
    n = sim.shape[1]
    xbar = np.add.reduce(sim[:-1], 0) / n
    xr = (1 + _RHO) * xbar - _RHO * sim[-1]
    xe = (1 + _RHO * _CHI) * xbar - _RHO * _CHI * sim[-1]
    xc = (1 + _PSI * _RHO) * xbar - _PSI * _RHO * sim[-1]
    xcc = (1 - _PSI) * xbar + _PSI * sim[-1]
    second = {"xe": xe, "xc": xc, "xcc": xcc}
    if width >= GUESS_WIDTH:  # the reflection and the likeliest second point(s) at once
        _tell(ahead, [xr, second[last]] + [v for k, v in second.items() if k != last], width)
    fxr = f(xr)
    if fxr < fsim[0]:
        fxe = f(xe)
        sim[-1], fsim[-1] = (xe, fxe) if fxe < fxr else (xr, fxr)
        return "xe"
    if fxr < fsim[-2]:
        sim[-1], fsim[-1] = xr, fxr
        return last
    kind = "xc" if fxr < fsim[-1] else "xcc"
    if kind == "xc":
        fxc = f(xc)
        if fxc <= fxr:
            sim[-1], fsim[-1] = xc, fxc
            return kind
    else:
        fxcc = f(xcc)
        if fxcc < fsim[-1]:
            sim[-1], fsim[-1] = xcc, fxcc
            return kind
    shrunk = [sim[0] + _SIGMA * (sim[j] - sim[0]) for j in range(1, n + 1)]
    _tell(ahead, shrunk, width, all_of=True)
    for j in range(1, n + 1):
        sim[j] = shrunk[j - 1]
        fsim[j] = f(sim[j])
    return kind


def _tell(ahead, points: list, width: int, all_of: bool = False) -> None:
    """``ahead`` told ``points`` (the first ``width`` of them, or all with ``all_of``)."""
    if ahead is not None and width > 1 and len(points) > 1:
        ahead(points if all_of else points[:width])
