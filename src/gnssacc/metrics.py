"""Scoring against truth: PRMSE (paper eq. rmse), horizontal RMSE, outage-only PRMSE."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gnss_noise import in_spans
from .rotations import wrap_angle
from .recording import RecordedRun
from .solution import NavSolution


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
    """

    prmse_m: float | None
    hrmse_m: float | None
    prmse_outage_m: float | None
    n_epochs: int
    rpy_rmse_deg: list | None = None


def truth_at(run: RecordedRun, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Truth NED position [m] at times ``t`` (linear interpolation) and a mask of valid times."""
    tr = run.truth
    p_n = run.origin.to_ned(tr.lat, tr.lon, tr.h)
    valid = (t >= tr.t[0]) & (t <= tr.t[-1])
    out = np.column_stack([np.interp(t, tr.t, p_n[:, i]) for i in range(3)])
    return out, valid


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
        d = np.column_stack([wrap_angle(sol.rpy[m, i] - np.interp(sol.t[m], tr.t, np.unwrap(tr.rpy[:, i])))
                             for i in range(3)])
        rpy = np.degrees(np.sqrt(np.mean(d**2, axis=0))).tolist()
    return Score(_rms(err), _rms(err[:, :2]), prmse_out, len(err), rpy)


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
