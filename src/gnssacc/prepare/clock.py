"""Stage 2 of the clock-offset measurement: the IMU-to-GNSS offset that maximises an EKF's innovation
likelihood, around stage 1's cross-correlation estimate (:mod:`gnssacc.checks.timeoffset`).

The EKF (position updates, the configured noise) is run with the IMU shifted by ``delta`` and the
log-likelihood of its position innovations is maximised over ``delta`` within a bracket around
stage 1 (scipy's bounded ``minimize_scalar``); the uncertainty comes from the curvature of the
log-likelihood over a step of about two sigma (:data:`CURVATURE_DROP`: it is jagged on a smaller
scale). This uses all the information the fixes hold. The EKF pass is handed in
(:class:`gnssacc.prepare.filter_pass.FilterPass`): this stage precedes the estimators.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..checks.quality import check_imu
from ..checks.timeoffset import MIN_CENTRES, OffsetEstimate, shifted
from ..core.config import RunConfig
from ..core.recording import RecordedRun
from .filter_pass import FilterPass
from .stationary import detect_stationary, params_from_config
from .yawbank import select_yaw

#: Position innovations of the first seconds after the EKF start are not scored by stage 2: the
#: start's own errors (the same for every shift) settle there [s].
BURN_IN_S = 10.0


#: Stage 2's uncertainty is the curvature of the log-likelihood over a step that lowers it by this
#: much on average (a 2-sigma step), from a parabola through five points. On a smaller scale the
#: log-likelihood is jagged: by ~1.5 within 20 ms on a 3-minute slow-UGV run with a consumer IMU and
#: 3 m fixes, where the step a drop of 1 chose gave a sigma of 12 ms for an error of 0.2 s.
CURVATURE_DROP = 2.0


#: Stage 2 searches stage 1's estimate +- this many of its sigmas, within the bounds below [s].
BRACKET_SIGMAS = 4.0
BRACKET_MIN_S, BRACKET_MAX_S = 0.5, 2.0


class _ShiftLikelihood:
    """Negative log-likelihood of the EKF's position innovations with the IMU shifted by ``delta``,
    over a fixed set of fixes (those at least :data:`BURN_IN_S` after the start and inside the IMU
    span for every shift of the bracket), from one start state.

    The start lies where the IMU has data for every shift of the bracket (a given ``run.init``
    when it does, else the yaw bank's start on the IMU from ``half_width_s`` after its first
    sample): a filter started before the shifted IMU's first sample pays for the shift with its
    whole start, which pins the likelihood's maximum to the unshifted IMU, i.e. to stage 1."""

    def __init__(self, run: RecordedRun, cfg: RunConfig, half_width_s: float, filter_pass: FilterPass):
        quality = check_imu(run.imu, cfg)
        t_first = run.t_start + half_width_s
        if run.init is not None and float(run.init.t) >= t_first:
            self.init = run.init
        else:
            late = replace(run, imu=run.imu.select(run.imu.t >= t_first), init=None)
            stationary = detect_stationary(late.imu, late.gnss, late.origin, params_from_config(cfg))
            self.init = select_yaw(late, cfg, stationary, check_imu(late.imu, cfg), filter_pass=filter_pass).init
        self.run, self.cfg, self.quality, self.filter_pass = run, cfg, quality, filter_pass
        self.t_lo = max(float(self.init.t), run.t_start + half_width_s) + BURN_IN_S
        self.t_hi = run.t_end - half_width_s
        self.n_scored = int(np.sum((run.gnss.t >= self.t_lo) & (run.gnss.t <= self.t_hi)))

    def __call__(self, delta_s: float) -> float:
        # Covariance every sample: with cm-level fixes, propagating it every few samples makes the
        # likelihood jump by tens as the shift moves the fixes across those steps.
        sol = self.filter_pass(shifted(self.run, float(delta_s)), self.cfg, "ekf", init=self.init, quality=self.quality,
                      output_times=np.zeros(0), record_innovations=True)
        t, ll = np.asarray(sol.stats["nis_pos_t"]), np.asarray(sol.stats["loglik_pos_series"])
        m = (t >= self.t_lo) & (t <= self.t_hi)
        return -float(ll[m].sum()) if m.sum() == self.n_scored else float("inf")


def refine_offset(run: RecordedRun, cfg: RunConfig, start: OffsetEstimate, *,
                  filter_pass: FilterPass) -> OffsetEstimate | None:
    """Stage 2 of the module notes around a stage-1 estimate.

    Parameters
    ----------
    run : RecordedRun
        With ``start.offset_s`` already added to its IMU time stamps.
    cfg : RunConfig
        The noise model of the EKF passes.
    start : OffsetEstimate
        Stage 1 (determined).
    filter_pass : FilterPass
        The EKF pass whose likelihood is maximised.

    Returns
    -------
    OffsetEstimate or None
        The total offset (``start.offset_s`` plus the shift found); ``None`` when the likelihood
        has no maximum inside the bracket (too few fixes, a flat likelihood, or stage 1 far off).
    """
    from scipy.optimize import minimize_scalar

    hw = float(np.clip(BRACKET_SIGMAS * start.sigma_s, BRACKET_MIN_S, BRACKET_MAX_S))
    cost = _ShiftLikelihood(run, cfg, hw, filter_pass)
    if cost.n_scored < MIN_CENTRES:
        return None
    res = minimize_scalar(cost, bounds=(-hw, hw), method="bounded", options={"xatol": 0.002})
    d, f0 = float(res.x), float(res.fun)
    if not np.isfinite(f0) or abs(d) > 0.9 * hw:
        return None
    # Curvature of the log-likelihood over a step that lowers it by CURVATURE_DROP on average, from a
    # parabola fitted to five points (module notes: it is jagged on a smaller scale).
    h = 0.01
    while True:
        fp, fm = cost(d + h), cost(d - h)
        if 0.5 * (fp + fm) - f0 >= CURVATURE_DROP or h >= 0.25 * hw:
            break
        h *= 2.0
    x = np.array([-h, -0.5 * h, 0.0, 0.5 * h, h])
    y = np.array([fm, cost(d - 0.5 * h), f0, cost(d + 0.5 * h), fp])
    if not np.all(np.isfinite(y)):
        return None
    curv = 2.0 * float(np.polyfit(x, y, 2)[0])
    if not (curv > 0 and np.isfinite(curv)):
        return None
    return replace(start, offset_s=start.offset_s + d, sigma_s=max(float(1.0 / np.sqrt(curv)), 0.001),
                   method="EKF likelihood")
