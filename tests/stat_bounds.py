"""Acceptance bounds derived from sampling statistics, shared by the tests (not a test module).

Every bound is chosen for a stated false-failure rate: the probability that the assertion fails
when the product is right. :data:`ALPHA` is that rate for one test; a test that makes several
checks splits it among them (Bonferroni).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import binom, chi2

#: False-failure rate of one test.
ALPHA = 1e-3
#: The factor in variance within which a noise model that is not the simulator's own is claimed
#: right: a preset tuned on other data, the noise tuner's identification, or a grade's datasheet
#: values on an IMU with errors they do not model (vibration, scale factor). Such a run's NIS is
#: accepted in the chi-square band widened by this factor on each side; a model 1.5x off in
#: variance is outside it once the chi-square band is tighter than 1.5 / 1.2 = 1.25.
CALIBRATION = 1.2


def chi2_mean_band(dof: float, alpha: float = ALPHA) -> tuple[float, float]:
    """Two-sided band of a chi-square variable with ``dof`` degrees of freedom, divided by ``dof``
    (the mean NIS or NEES per degree of freedom of ``dof`` independent unit-variance terms)."""
    lo, hi = chi2.ppf([alpha / 2, 1 - alpha / 2], dof)
    return float(lo / dof), float(hi / dof)


def effective_count(n: int, acf1: float | None) -> float:
    """Independent samples worth of ``n`` samples with lag-1 autocorrelation ``acf1`` (an AR(1)
    sequence: the variance of its mean is that of ``n (1 - r) / (1 + r)`` independent ones).
    Negative or missing ``acf1`` counts every sample."""
    r = 0.0 if acf1 is None or not np.isfinite(acf1) else max(float(acf1), 0.0)
    return n * (1.0 - r) / (1.0 + r)


def nis_band(
    n_updates: int,
    dof: int = 3,
    acf1: float | None = None,
    calibration: float = 1.0,
    alpha: float = ALPHA,
) -> tuple[float, float]:
    """Band of a run's mean NIS per dof over ``n_updates`` updates of ``dof`` each: chi-square with
    the effective number of updates, widened by ``calibration``.

    ``acf1`` is the lag-1 autocorrelation of the innovations (as the EKF reports it). Squares of
    jointly Gaussian variables with correlation ``r`` have correlation ``r^2``, so the NIS series
    has lag-1 autocorrelation ``acf1^2`` (:func:`effective_count`; an AR(1) model, conservative for
    the short moving-average correlation of overlapping acceleration windows, whose lag-2 term is
    smaller than AR(1)'s)."""
    r2 = None if acf1 is None or not np.isfinite(acf1) else float(acf1) ** 2
    lo, hi = chi2_mean_band(dof * effective_count(n_updates, r2), alpha)
    return lo / calibration, hi * calibration


def sign_test_min(n: int, alpha: float = ALPHA) -> int:
    """Smallest count of ``n`` paired comparisons (won by either side with probability 1/2 when the
    two are equally good) that a method does not reach with probability above ``1 - alpha``:
    ``k`` with ``P(Binomial(n, 1/2) < k) <= alpha``."""
    return int(binom.ppf(alpha, n, 0.5))


def paired_not_worse(a: np.ndarray, b: np.ndarray, alpha: float = ALPHA) -> tuple[float, float]:
    """Mean relative difference ``mean(a / b - 1)`` and the one-sided t bound it stays below unless
    ``a`` is worse than ``b`` on average (a false failure at most ``alpha`` when ``a`` is not worse)."""
    from scipy.stats import t as student

    d = np.asarray(a, float) / np.asarray(b, float) - 1.0
    se = d.std(ddof=1) / np.sqrt(len(d))
    return float(d.mean()), float(student.ppf(1 - alpha, len(d) - 1) * se)


def gnss_prmse_band(sigma_ned: np.ndarray, n: int, alpha: float = ALPHA) -> tuple[float, float]:
    """Band of the 3-D RMS error of ``n`` fixes with independent zero-mean Gaussian errors of
    1-sigma ``sigma_ned`` [m] per axis. ``n PRMSE^2`` is a weighted sum of chi-square(1) terms,
    taken as ``c chi2(nu)`` with matched mean and variance (Welch-Satterthwaite)."""
    w = np.tile(np.asarray(sigma_ned, float) ** 2, n)
    c, nu = np.sum(w**2) / np.sum(w), np.sum(w) ** 2 / np.sum(w**2)
    lo, hi = c * chi2.ppf([alpha / 2, 1 - alpha / 2], nu)
    return float(np.sqrt(lo / n)), float(np.sqrt(hi / n))


def nees_band(
    n_epochs: int, dof: int, rho: float, calibration: float = 1.0, alpha: float = ALPHA
) -> tuple[float, float]:
    """Band of a run's time-averaged NEES per dof over ``n_epochs`` epochs whose normalised errors
    have lag-1 autocorrelation ``rho`` (``exp(-dt / tau)`` for errors that follow a Gauss-Markov
    process of correlation time ``tau``): the squared errors then correlate by ``rho^2``, and the
    mean is chi-square with ``dof`` times the effective number of epochs, widened by ``calibration``.
    A single run with errors correlated over a minute bounds the NEES only loosely."""
    lo, hi = chi2_mean_band(dof * effective_count(n_epochs, rho**2), alpha)
    return lo / calibration, hi * calibration
