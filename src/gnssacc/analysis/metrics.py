"""Scoring against truth: PRMSE (paper eq. rmse), horizontal RMSE, outage-only PRMSE, and the
truth figures of attitude, biases and consistency (:func:`truth_figures`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.recording import RecordedRun
from ..core.rotations import wrap_angle
from ..core.solution import NavSolution
from ..core.units import DEG_H, MG
from ..core.states import ATT, BA, BG, MOTION, N_NAV, POS, TILT, VEL, YAW
from ..sources.gnss_noise import in_spans

#: Baseline of each aided method, for the improvement column.
BASELINES = {
    "ekf-acc": "ekf",
    "ekf-accw": "ekf",
    "smoother-acc": "smoother",
    "smoother-acc-online": "smoother-online",
    "smoother-accw": "smoother",
    "smoother-accw-online": "smoother-online",
    "ekf-gm": "ekf",
    "ekf-vacc": "ekf",
    "smoother-vacc": "smoother",
    "smoother-vacc-online": "smoother-online",
    "ekf-vaccw": "ekf",
    "smoother-vaccw": "smoother",
    "smoother-vaccw-online": "smoother-online",
    "smoother-gm": "smoother",
    "smoother-gm-online": "smoother-online",
}


@dataclass
class Score:
    """Accuracy of one solution.

    Attributes
    ----------
    prmse_m : float or None
        3-D position RMSE over all scored epochs [m] (``None`` without truth).
    hrmse_m : float or None
        Horizontal (N, E) RMSE [m].
    prmse_outage_m : float or None
        3-D RMSE over the epochs inside GNSS outages [m] (``None`` without outages).
    n_epochs : int
        Epochs scored.
    rpy_rmse_deg : list of float or None
        Roll, pitch, yaw RMSE [deg] when the truth has attitude.
    truth : dict
        :func:`truth_figures` (``None`` values where the truth lacks what a figure needs).
    errors : dict
        The evo-style statistics (:func:`gnssacc.analysis.errorstats.error_statistics` for a
        solution, :func:`gnssacc.analysis.errorstats.fix_statistics` for the raw fixes).
    """

    prmse_m: float | None
    hrmse_m: float | None
    prmse_outage_m: float | None
    n_epochs: int
    rpy_rmse_deg: list | None = None
    truth: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)


def truth_at(run: RecordedRun, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Truth NED position [m] at times ``t`` (linear interpolation) and a mask of valid times."""
    tr = run.truth
    p_n = run.origin.to_ned(tr.lat, tr.lon, tr.h)
    valid = (t >= tr.t[0]) & (t <= tr.t[-1])
    out = np.column_stack([np.interp(t, tr.t, p_n[:, i]) for i in range(3)])
    return out, valid


def interp_columns(t: np.ndarray, tt: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each column of ``y`` (sampled at ``tt``) linearly interpolated at ``t``."""
    return np.column_stack([np.interp(t, tt, y[:, i]) for i in range(y.shape[1])])


def state_errors(run: RecordedRun, sol: NavSolution) -> np.ndarray:
    """Actual errors (estimate minus truth) per state at the solution epochs, NaN where unknown.

    Position needs ``run.truth``; velocity ``run.truth.v_n``; attitude ``run.truth.rpy`` (an
    attitude reference; yaw wrapped to [-pi, pi)); biases the simulator's
    ``run.sim.bias`` (per IMU sample, interpolated over ``run.imu.t``; IMU axes = body axes for
    simulated runs). Epochs outside the truth's span are NaN.

    Returns
    -------
    ndarray, shape (K, 15)
    """
    t = np.asarray(sol.t, float)
    err = np.full((len(t), N_NAV), np.nan)
    tr = run.truth
    if tr is not None:
        p_true, inside = truth_at(run, t)
        err[:, POS] = run.origin.to_ned(sol.lat, sol.lon, sol.h) - p_true
        if tr.v_n is not None:
            err[:, VEL] = sol.v_n - interp_columns(t, tr.t, tr.v_n)
        if tr.rpy is not None:
            ref = interp_columns(t, tr.t, np.unwrap(tr.rpy, axis=0))
            err[:, ATT] = wrap_angle(sol.rpy - ref)
        err[~inside, MOTION] = np.nan
    bias = run.sim.bias if run.sim is not None else None
    if bias is not None and len(bias) == len(run.imu.t):
        b_a, b_g = bias.at(t, run.imu.t)  # drawn again, at these epochs only
        err[:, BA], err[:, BG] = sol.b_a - b_a, sol.b_g - b_g
    return err


def position_errors(run: RecordedRun, sol: NavSolution) -> tuple[np.ndarray, np.ndarray]:
    """NED position error (estimate minus truth) [m] at the solution epochs that have truth."""
    p_true, valid = truth_at(run, sol.t)
    p_est = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    return (p_est - p_true)[valid], sol.t[valid]


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def _in_window(t: np.ndarray, window) -> np.ndarray:
    return np.ones(len(t), bool) if window is None else (t >= window[0]) & (t <= window[1])


def score(run: RecordedRun, sol: NavSolution, window: tuple | None = None) -> Score:
    """Score a solution against the run's truth (all ``None`` when there is no truth).

    ``window = (t_a, t_b)`` [s] restricts the scored epochs, so that methods (and the raw fixes)
    with different spans are compared over the same stretch.
    """
    if run.truth is None or len(sol) == 0:
        return Score(None, None, None, len(sol))
    err, t = position_errors(run, sol)
    keep = _in_window(t, window)
    err, t = err[keep], t[keep]
    if len(err) == 0:
        return Score(None, None, None, 0)
    outages = run.outages
    prmse_out = None
    if outages:
        m = in_spans(t - run.t_start, outages)
        prmse_out = _rms(err[m]) if np.any(m) else None
    rpy = None
    if run.truth.rpy is not None:
        tr = run.truth
        m = _in_window(sol.t, window)
        d = np.column_stack(
            [
                wrap_angle(sol.rpy[m, i] - np.interp(sol.t[m], tr.t, np.unwrap(tr.rpy[:, i])))
                for i in range(3)
            ]
        )
        rpy = np.degrees(np.sqrt(np.mean(d**2, axis=0))).tolist()
    return Score(
        _rms(err), _rms(err[:, :2]), prmse_out, len(err), rpy, truth_figures(run, sol, window)
    )


#: The figures of :func:`truth_figures`, in the order of ``summary.csv``.
TRUTH_FIGURES = (
    "tilt_rms_deg",
    "yaw_rms_deg",
    "bias_a_rms_mg",
    "bias_g_rms_deg_h",
    "nees_pos",
    "nees_att",
)


def truth_figures(run: RecordedRun, sol: NavSolution, window: tuple | None = None) -> dict:
    """Attitude, bias and consistency figures against the truth, over the epochs in ``window`` [s].

    Errors are estimate minus truth (:func:`state_errors`; the filter's
    biases are the sensor's own, ``measured = true + bias``, as the simulator draws them).

    Returns
    -------
    dict
        ``tilt_rms_deg``: RMS over epochs of ``sqrt(droll^2 + dpitch^2)`` [deg]; ``yaw_rms_deg``
        [deg]; ``bias_a_rms_mg`` [mg] and ``bias_g_rms_deg_h`` [deg/h]: RMS over epochs of the
        3-axis error norm (simulated runs only); ``nees_pos`` and ``nees_att``: the mean over
        epochs and the three axes of ``(e_i / sigma_i)^2`` (1 if consistent). The solutions keep
        per-state sigmas, not the full covariance, so this is the per-axis NEES per dof: it
        equals the full NEES per dof when the covariance is diagonal in those axes and leaves out
        the cross-correlations otherwise. Each ``None`` when the truth lacks what it needs.
    """

    keep = _in_window(sol.t, window)
    err = state_errors(run, sol)[keep] if run.truth is not None else np.full((0, N_NAV), np.nan)
    sig = np.asarray(sol.sigma, float)[keep] if len(err) else np.zeros((0, N_NAV))
    deg = np.degrees(1.0)
    return {
        "tilt_rms_deg": _rms_rows(err[:, TILT], deg),
        "yaw_rms_deg": _rms_rows(err[:, YAW], deg),
        "bias_a_rms_mg": _rms_rows(err[:, BA], 1.0 / MG),
        "bias_g_rms_deg_h": _rms_rows(err[:, BG], 1.0 / DEG_H),
        "nees_pos": _nees(err[:, POS], sig[:, POS]),
        "nees_att": _nees(err[:, ATT], sig[:, ATT]),
    }


def _rms_rows(e: np.ndarray, unit: float) -> float | None:
    """RMS over rows of the row norm, times ``unit``; rows with a NaN are left out (``None`` if all)."""
    ok = np.all(np.isfinite(e), axis=1)
    return float(unit * np.sqrt(np.mean(np.sum(e[ok] ** 2, axis=1)))) if np.any(ok) else None


def _nees(e: np.ndarray, s: np.ndarray) -> float | None:
    """Mean of ``(e / s)^2`` over the rows with finite errors and positive sigmas, and the axes."""
    ok = np.all(np.isfinite(e), axis=1) & np.all(s > 0, axis=1)
    return float(np.mean((e[ok] / s[ok]) ** 2)) if np.any(ok) else None


def gnss_score(run: RecordedRun, window: tuple | None = None) -> Score:
    """Score of the raw GNSS fixes themselves (the reference any filter must beat), at the fix
    epochs inside ``window`` [s] when given."""
    if run.truth is None:
        return Score(None, None, None, len(run.gnss))
    p_true, valid = truth_at(run, run.gnss.t)
    valid &= _in_window(run.gnss.t, window)
    err = (run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h) - p_true)[valid]
    if len(err) == 0:
        return Score(None, None, None, 0)
    return Score(_rms(err), _rms(err[:, :2]), None, len(err))


def improvement_pct(baseline: float | None, aided: float | None) -> float | None:
    """Relative PRMSE improvement of an aided method over its baseline [%] (positive = better)."""
    if baseline is None or aided is None or baseline <= 0:
        return None
    return 100.0 * (baseline - aided) / baseline
