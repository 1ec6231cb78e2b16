"""The few distribution quantiles and tails the tool states, from ``scipy.special``.

The same functions ``scipy.stats`` evaluates for them (its ``chi2``, ``t`` and ``binom`` call
these special functions), without importing ``scipy.stats``, which costs every run 0.4-2 s
(the docstrings of its hundred distributions are processed when it loads). ``scipy.special``
itself is imported at the first call: the numba kernels' modules import this one, and the
package's build compiles them where scipy is not installed (``setup.py``).
"""

from __future__ import annotations


def chi2_ppf(q: float, dof: float) -> float:
    """The chi-square quantile: the value below which a chi-square of ``dof`` (>0, may be
    fractional) degrees of freedom lies with probability ``q``."""
    from scipy import special

    return float(2.0 * special.gammaincinv(0.5 * dof, q))


def chi2_isf(p: float, dof: float) -> float:
    """The chi-square value exceeded with probability ``p`` by ``dof`` degrees of freedom."""
    from scipy import special

    return float(special.chdtri(dof, p))


def binom_sf(k: int, n: int, p: float) -> float:
    """P(X > k) for X binomial with ``n`` trials of success probability ``p``."""
    if k < 0:
        return 1.0
    if k >= n:
        return 0.0
    from scipy import special

    return float(special.bdtrc(k, n, p))


def t_ppf(q: float, dof: float) -> float:
    """Student's t quantile of probability ``q`` with ``dof`` degrees of freedom."""
    from scipy import special

    return float(special.stdtrit(dof, q))
