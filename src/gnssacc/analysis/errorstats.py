r"""Error statistics of one solution against the truth, as ``evo`` users expect them, and its NEES
against a chi-square band.

Everything is estimate minus truth at the solution's epochs (truth interpolated linearly,
:func:`gnssacc.analysis.observability.state_errors`), over the scored window:

* **Position** (``position``): the 3-D error norm ``|dp|`` with evo's statistics (``rmse``, ``mean``,
  ``median``, ``std``, ``min``, ``max``: those ``evo_ape --pose_relation trans_part`` prints, with
  ``--align`` off); the horizontal norm with the circular error probable ``cep50`` and ``cep95``
  (the 50th and 95th percentiles of ``|dp_NE|``); per axis N/E/D ``rmse``, ``mean`` (the bias) and
  ``max_abs``.
* **Like for like with the raw fixes** (``at_fixes``): the solution interpolated to the epochs of
  the raw fixes inside its span and the window, against the fixes' own error at the same epochs.
  Fixes exist outside outages only, so this is the non-outage comparison.
* **Outages** (``outage`` / ``no_outage``): the 3-D RMSE over the solution's epochs inside and
  outside the GNSS outages.
* **Velocity** [m/s] and **attitude** (roll, pitch, yaw [deg]) per axis, when the truth has them.
* **NEES per dof** of position and attitude, per axis and pooled, with its band (:func:`nees_band`).

The solutions keep per-state sigmas, not full covariances: the NEES here is the per-axis one,
``mean((e_i / sigma_i)^2)``, which equals the full NEES per dof for a covariance diagonal in those
axes (:func:`gnssacc.analysis.metrics.truth_figures`).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.distributions import chi2_ppf
from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from ..core.states import ATT, POS, VEL
from ..sources.gnss_noise import in_spans
from .consistency import NIS_BAND

#: Two-sided probability outside the NEES band for a consistent estimator (a 3-sigma band).
NEES_ALPHA = 0.0027
AXES_NED = ("N", "E", "D")
AXES_RPY = ("roll", "pitch", "yaw")


def summary(x: np.ndarray) -> dict | None:
    """evo's statistics of a 1-D array of error magnitudes: rmse, mean, median, std (population),
    min, max, and n (``None`` when empty)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if not len(x):
        return None
    return {
        "rmse": float(np.sqrt(np.mean(x**2))),
        "mean": float(np.mean(x)),
        "median": float(np.median(x)),
        "std": float(np.std(x)),
        "min": float(np.min(x)),
        "max": float(np.max(x)),
        "n": int(len(x)),
    }


def per_axis(e: np.ndarray, names, unit: float = 1.0) -> dict | None:
    """Per column of ``e`` (rows with a NaN left out): ``rmse``, ``mean`` (signed) and ``max_abs``,
    times ``unit``."""
    e = np.asarray(e, float)
    e = e[np.all(np.isfinite(e), axis=1)] * unit
    if not len(e):
        return None
    return {
        n: {
            "rmse": float(np.sqrt(np.mean(e[:, i] ** 2))),
            "mean": float(np.mean(e[:, i])),
            "max_abs": float(np.max(np.abs(e[:, i]))),
        }
        for i, n in enumerate(names)
    }


def horizontal(e_ne: np.ndarray) -> dict | None:
    """:func:`summary` of the horizontal error norm with ``cep50`` and ``cep95`` [same unit]."""
    d = np.hypot(e_ne[:, 0], e_ne[:, 1])
    out = summary(d)
    if out is not None:
        d = d[np.isfinite(d)]
        out.update(cep50=float(np.percentile(d, 50)), cep95=float(np.percentile(d, 95)))
    return out


def effective_count(z: np.ndarray) -> float:
    """Independent epochs the mean of squares of normalised errors ``z`` (n,) or (n, m) is worth.

    For jointly Gaussian errors the squares of two terms of correlation ``rho`` correlate by
    ``rho^2``, so the mean of ``z^2`` over ``n`` epochs and ``m`` axes has the variance of a mean
    of ``n_eff m`` independent chi-square(1) terms with

        n_eff = n m / sum_ij c_ij^2 sqrt(tau_i tau_j),   tau_i = 1 + 2 sum_{k=1..K_i} rho_i(k)^2

    (``n (1 - r^2) / (1 + r^2)`` for one AR(1) axis of lag-1 correlation ``r``): ``rho_i(k)`` is
    axis ``i``'s autocorrelation at lag ``k`` epochs, summed up to Geyer's cut ``K_i`` (the first
    pair ``rho(2k) + rho(2k + 1)`` that is not positive: beyond it the estimate is noise), and
    ``c_ij`` the correlation of axes ``i`` and ``j`` at the same epoch (their lagged
    cross-correlations taken to decay as the autocorrelations). The correlations are those of a
    consistent estimator's errors, whose mean is zero: they are estimated about zero, not about
    the sample mean (which would hide a correlation as long as the run and make the band too
    narrow); an offset the estimator does not know of therefore counts as correlated, and only a
    large one is told from chance in a single run. Clipped to ``[1, n]``.
    """
    z = np.asarray(z, float)
    z = z.reshape(len(z), -1)
    n, m = z.shape
    power = np.sum(z**2, axis=0)
    if n < 3 or not np.all(power > 0):
        return float(max(n, 1))
    z = z / np.sqrt(power / n)
    rho = np.fft.irfft(np.abs(np.fft.rfft(z, 2 * n, axis=0)) ** 2, 2 * n, axis=0)[:n] / n
    tau = np.empty(m)
    for i in range(m):
        pairs = rho[0 : 2 * ((n - 1) // 2) : 2, i] + rho[1 : 2 * ((n - 1) // 2) + 1 : 2, i]
        stop = np.flatnonzero(pairs <= 0.0)
        cut = 2 * stop[0] if len(stop) else n - 1
        tau[i] = 1.0 + 2.0 * np.sum(rho[1 : cut + 1, i] ** 2)
    c = (z.T @ z) / n
    total = np.sum(c**2 * np.sqrt(np.outer(tau, tau)))
    return float(min(max(n * m / total, 1.0), n))


def chi2_band(n_eff: float, dof: int, alpha: float = NEES_ALPHA) -> tuple[float, float]:
    """The chi-square interval of probability ``1 - alpha`` of a mean NEES per dof over ``n_eff``
    independent epochs of ``dof`` each (``n_eff dof`` degrees of freedom; with correlated epochs,
    :func:`effective_count`, the scaled chi-square of the same variance)."""
    k = max(n_eff * dof, 1.0)
    return chi2_ppf(alpha / 2, k) / k, chi2_ppf(1.0 - alpha / 2, k) / k


def nees_band(n_eff: float, dof: int) -> tuple[float, float]:
    """The band a consistent mean NEES per dof lies in: :func:`chi2_band` of probability
    ``1 - NEES_ALPHA``, widened to at least :data:`gnssacc.analysis.consistency.NIS_BAND` (stated
    sigmas right within ``sqrt(2)``)."""
    lo, hi = chi2_band(n_eff, dof)
    return min(lo, NIS_BAND[0]), max(hi, NIS_BAND[1])


def nees(e: np.ndarray, s: np.ndarray, names) -> dict | None:
    """Mean NEES per dof of an error block ``e`` with 1-sigma ``s`` (K, m): pooled ``value`` with its
    ``band``, and ``per_axis`` ``{name: {value, band}}``; ``outside``: the axes (names) whose NEES
    leaves its band, ``pooled_outside`` whether the pooled figure does."""
    ok = np.all(np.isfinite(e), axis=1) & np.all(s > 0, axis=1)
    if ok.sum() < 2:
        return None
    z = e[ok] / s[ok]
    axes, outside = {}, []
    for i, name in enumerate(names):
        value = float(np.mean(z[:, i] ** 2))
        band = nees_band(effective_count(z[:, i]), 1)
        axes[name] = {"value": value, "band": list(band)}
        if not band[0] <= value <= band[1]:
            outside.append(name)
    n_eff = effective_count(z)
    value = float(np.mean(z**2))
    band = nees_band(n_eff, z.shape[1])
    return {
        "value": value,
        "band": list(band),
        "n": int(ok.sum()),
        "n_eff": n_eff,
        "per_axis": axes,
        "outside": outside,
        "pooled_outside": not band[0] <= value <= band[1],
    }


def _in_window(t: np.ndarray, window) -> np.ndarray:
    return np.ones(len(t), bool) if window is None else (t >= window[0]) & (t <= window[1])


def at_fixes(run: RecordedRun, sol: NavSolution, window=None) -> dict | None:
    """The solution and the raw fixes against the truth at the same epochs: the fix epochs inside
    the solution's span, the truth's and ``window``. ``prmse_m`` / ``gnss_prmse_m`` [m], ``n``."""
    from .metrics import truth_at

    g = run.gnss
    if run.truth is None or len(sol) < 2 or not len(g):
        return None
    p_true, valid = truth_at(run, g.t)
    keep = valid & _in_window(g.t, window) & (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    if not np.any(keep):
        return None
    p_sol = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    p_at = np.column_stack([np.interp(g.t[keep], sol.t, p_sol[:, i]) for i in range(3)])
    p_fix = run.origin.to_ned(g.lat[keep], g.lon[keep], g.h[keep])
    rms = lambda d: float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    return {
        "prmse_m": rms(p_at - p_true[keep]),
        "gnss_prmse_m": rms(p_fix - p_true[keep]),
        "n": int(keep.sum()),
    }


def fix_residuals(run: RecordedRun, sol: NavSolution, window=None) -> dict | None:
    """evo's statistics of the 3-D distance from the solution (interpolated) to each raw fix inside its
    span and ``window`` [m]: what can be said without truth (how well the method agrees with the fixes,
    not how accurate it is). Antenna lever arms are not applied."""
    g = run.gnss
    if len(sol) < 2 or not len(g):
        return None
    keep = _in_window(g.t, window) & (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    if not np.any(keep):
        return None
    p_sol = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    p_at = np.column_stack([np.interp(g.t[keep], sol.t, p_sol[:, i]) for i in range(3)])
    return summary(
        np.linalg.norm(p_at - run.origin.to_ned(g.lat[keep], g.lon[keep], g.h[keep]), axis=1)
    )


def error_statistics(run: RecordedRun, sol: NavSolution, window=None) -> dict:
    """The statistics of the module docstring for one solution (empty without truth).

    Returns
    -------
    dict
        ``position`` (3-D norm, evo's statistics [m]), ``horizontal`` (with ``cep50``, ``cep95`` [m]),
        ``position_axes`` (N/E/D [m]), ``no_outage`` / ``outage`` (3-D RMSE [m] or ``None``),
        ``at_fixes``, ``velocity_axes`` [m/s], ``velocity`` (norm), ``attitude_axes`` (roll/pitch/yaw
        [deg]), ``nees_position``, ``nees_attitude``, ``fix_residual`` (:func:`fix_residuals`); ``None``
        where the truth lacks what one needs. Without truth only ``fix_residual``.
    """
    from .observability import state_errors

    if not len(sol):
        return {}
    if run.truth is None:
        return {"fix_residual": fix_residuals(run, sol, window)}
    keep = _in_window(sol.t, window)
    err = state_errors(run, sol)[keep]
    sig = np.asarray(sol.sigma, float)[keep]
    t = sol.t[keep] - run.t_start
    dp = err[:, POS]
    out = {
        "position": summary(np.linalg.norm(dp, axis=1)),
        "horizontal": horizontal(dp[:, :2]),
        "position_axes": per_axis(dp, AXES_NED),
        "no_outage": None,
        "outage": None,
        "at_fixes": at_fixes(run, sol, window),
        "velocity": summary(np.linalg.norm(err[:, VEL], axis=1)),
        "velocity_axes": per_axis(err[:, VEL], AXES_NED),
        "attitude_axes": per_axis(err[:, ATT], AXES_RPY, math.degrees(1.0)),
        "nees_position": nees(dp, sig[:, POS], AXES_NED),
        "nees_attitude": nees(err[:, ATT], sig[:, ATT], AXES_RPY),
        "fix_residual": fix_residuals(run, sol, window),
    }
    if run.outages:
        inside = in_spans(t, run.outages)
        rms = lambda d: summary(np.linalg.norm(d, axis=1))
        out["outage"], out["no_outage"] = rms(dp[inside]), rms(dp[~inside])
    return out


def fix_statistics(run: RecordedRun, window=None) -> dict:
    """The raw fixes' errors against the truth at their epochs inside ``window`` (those
    :func:`gnssacc.analysis.metrics.gnss_score` scores): ``position``, ``horizontal`` and
    ``position_axes`` as in :func:`error_statistics` (empty without truth)."""
    from .metrics import truth_at

    if run.truth is None:
        return {}
    g = run.gnss
    p_true, valid = truth_at(run, g.t)
    valid &= _in_window(g.t, window)
    err = (run.origin.to_ned(g.lat, g.lon, g.h) - p_true)[valid]
    if not len(err):
        return {}
    return {
        "position": summary(np.linalg.norm(err, axis=1)),
        "horizontal": horizontal(err[:, :2]),
        "position_axes": per_axis(err, AXES_NED),
    }
