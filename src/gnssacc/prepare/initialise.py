"""Self-initialisation from the data, at the start of the recording.

Position, velocity, roll and pitch come from the data around the first IMU sample; yaw is left
open and resolved by :mod:`gnssacc.prepare.yawbank` (a bank of yaw hypotheses scored by the EKF's
innovation likelihood), so the filter starts where the recording starts, whatever the vehicle
does first (standing, creeping, reversing).

* **Static start** (a stationary span, :mod:`gnssacc.prepare.stationary`, covers the first sample):
  position from the fixes inside the span, velocity zero, roll/pitch by levelling the span's mean
  specific force, and the gyro bias measured as the span's mean rate minus the earth rate.
* **Moving start**: position and velocity from a straight-line fit of the first
  ``[init] course_fit_s`` seconds of fixes, evaluated at the start; roll/pitch by levelling with
  the GNSS-fitted acceleration removed (it depends on the yaw hypothesis).

Every sigma is derived from the fits and residuals and floored by the ``[init]`` minimums, so the
filter starts honest rather than optimistic.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.earth import earth_rate_n, gravity_n
from ..core.errors import InputError
from ..core.gnss_fit import acceleration_row
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import euler_to_dcm
from ..estimators.settings import GnssModel

#: Prior 1-sigma of a ground vehicle's mean acceleration over a fit window [m/s^2], used to
#: shrink the (noisy) GNSS-fitted acceleration towards zero and to budget a line fit's model error.
_ACCEL_PRIOR_SIGMA = 1.0
#: A static span counts as a static start when it begins within this of the first IMU sample [s].
_STATIC_START_TOL_S = 1.0
#: Velocity 1-sigma assumed at a static start [m/s] (the zero-velocity updates refine it).
_STATIC_VEL_SIGMA = 0.05


@dataclass
class StartState:
    """What the data say about the start, before yaw is known.

    Attributes
    ----------
    t : float
        Start time [s].
    p_n, sigma_p : ndarray (3,)
        Position in the run's tangent frame [m] and its 1-sigma.
    v_n, sigma_v : ndarray (3,)
        NED velocity [m/s] and its 1-sigma.
    a_n, var_a : ndarray (3,)
        Mean NED acceleration over the fit window (shrunk towards zero) [m/s^2] and its variance.
    f_mean_b : ndarray (3,)
        Mean specific force over the levelling samples [m/s^2].
    static : slice or None
        IMU samples of the static start, if there is one.
    f_se_b : ndarray (3,)
        Standard error of ``f_mean_b`` (zero for a moving start, where the fit dominates) [m/s^2].
    omega_mean_b, omega_se_b : ndarray (3,) or None
        Mean raw gyro rate over the static start and its standard error [rad/s].
    fit_window : tuple
        Times of the first and last fix used [s].
    how : str
    """

    t: float
    p_n: np.ndarray
    sigma_p: np.ndarray
    v_n: np.ndarray
    sigma_v: np.ndarray
    a_n: np.ndarray
    var_a: np.ndarray
    f_mean_b: np.ndarray
    f_se_b: np.ndarray
    static: slice | None
    omega_mean_b: np.ndarray | None
    omega_se_b: np.ndarray | None
    fit_window: tuple
    how: str


def _line_fit(t: np.ndarray, p: np.ndarray, sigma: np.ndarray, t_ref: float):
    """Weighted straight-line fit per axis: value and rate at ``t_ref`` with their 1-sigma."""
    A = np.column_stack([np.ones_like(t), t - t_ref])
    out_p, out_v, sp, sv = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for i in range(3):
        W = 1.0 / sigma[:, i] ** 2
        cov = np.linalg.inv(A.T @ (A * W[:, None]))
        out_p[i], out_v[i] = cov @ (A.T @ (W * p[:, i]))
        sp[i], sv[i] = np.sqrt(np.diag(cov))
    return out_p, out_v, sp, sv


def _block_se(x: np.ndarray, block: int) -> np.ndarray:
    """Standard error of the mean of ``x`` (N, 3) from the scatter of block means
    (vibration-aware)."""
    nb = len(x) // block
    if nb < 3:
        return np.std(x, axis=0) / np.sqrt(max(len(x), 1))
    means = x[: nb * block].reshape(nb, block, 3).mean(axis=1)
    return np.std(means, axis=0, ddof=1) / np.sqrt(nb)


def _static_start(run: RecordedRun, cfg: RunConfig, span) -> StartState:
    imu, gnss = run.imu, run.gnss
    sl = slice(int(span.i_start), int(span.i_end))
    t0 = float(imu.t[0])
    inside = (gnss.t >= span.t_start - 0.5) & (gnss.t <= span.t_end)
    k = (
        np.flatnonzero(inside)
        if np.any(inside)
        else np.array([int(np.argmin(np.abs(gnss.t - span.t_end)))])
    )
    p_fix = run.origin.to_ned(gnss.lat[k], gnss.lon[k], gnss.h[k])
    w = 1.0 / gnss.sigma_ned[k] ** 2
    p0 = (w * p_fix).sum(axis=0) / w.sum(axis=0)
    # Averaging fixes only helps against white errors; with correlated (multipath, Gauss-Markov)
    # errors one fix's sigma is the honest floor.
    sig_p = np.median(gnss.sigma_ned[k], axis=0)
    block = max(int(round(1.0 / max(np.median(np.diff(imu.t[sl])), 1e-4))), 1)
    return StartState(
        t0,
        p0,
        sig_p,
        np.zeros(3),
        np.full(3, _STATIC_VEL_SIGMA),
        np.zeros(3),
        np.zeros(3),
        imu.f_b[sl].mean(axis=0),
        _block_se(imu.f_b[sl], block),
        sl,
        imu.omega_ib_b[sl].mean(axis=0),
        _block_se(imu.omega_ib_b[sl], block),
        (float(gnss.t[k[0]]), float(gnss.t[k[-1]])),
        f"static start ({span.t_end - span.t_start:.1f} s): position from {len(k)} fixes, "
        f"roll/pitch by levelling, gyro bias measured",
    )


def _moving_start(run: RecordedRun, cfg: RunConfig) -> StartState:
    imu, gnss = run.imu, run.gnss
    first = int(np.searchsorted(gnss.t, imu.t[0] - 0.5))
    if first >= len(gnss):
        raise InputError(run.where, "cannot initialise: no GNSS fix within the IMU time span")
    t0 = max(float(imu.t[0]), float(gnss.t[first]))
    win = float(cfg["init"]["course_fit_s"])
    stop = max(int(np.searchsorted(gnss.t, t0 + win, side="right")), first + 3)
    sel = slice(first, min(stop, len(gnss)))
    t_w = gnss.t[sel]
    if len(t_w) < 3 or t_w[-1] - t_w[0] <= 0:
        raise InputError(
            run.where,
            f"cannot initialise: fewer than three GNSS fixes near the start "
            f"({len(t_w)} in the first {win:g} s)",
        )
    p_w = run.origin.to_ned(gnss.lat[sel], gnss.lon[sel], gnss.h[sel])
    p0, v0, sp, sv = _line_fit(t_w, p_w, gnss.sigma_ned[sel], t0)
    # A line fitted to accelerating motion is off by a dt^2/2 in position and a dt in velocity
    # at the window's start: budget for a typical acceleration.
    dt = t_w - t0
    sp_model = _ACCEL_PRIOR_SIGMA * np.mean(dt**2) / 2.0
    sv_model = _ACCEL_PRIOR_SIGMA * np.mean(dt)
    B = acceleration_row(t_w)
    a_fit, var_fit = B @ p_w, (B[:, None] ** 2 * gnss.sigma_ned[sel] ** 2).sum(axis=0)
    shrink = _ACCEL_PRIOR_SIGMA**2 / (_ACCEL_PRIOR_SIGMA**2 + var_fit)
    i0, i1 = np.searchsorted(imu.t, [t_w[0], t_w[-1]])
    f_mean = imu.f_b[i0 : max(i1, i0 + 1)].mean(axis=0)
    c = cfg["init"]
    return StartState(
        t0,
        p0,
        np.maximum(np.hypot(sp, sp_model), np.median(gnss.sigma_ned[sel], axis=0)),
        v0,
        np.maximum(np.hypot(sv, sv_model), c["vel_sigma_min_mps"]),
        shrink * a_fit,
        shrink * var_fit,
        f_mean,
        np.zeros(3),
        None,
        None,
        None,
        (float(t_w[0]), float(t_w[-1])),
        f"moving start: position/velocity from a line fit over {len(t_w)} fixes "
        f"({t_w[-1] - t_w[0]:.1f} s), roll/pitch by levelling with the GNSS-fitted acceleration "
        "removed",
    )


def start_state(run: RecordedRun, cfg: RunConfig, stationary=None) -> StartState:
    """The start of the recording as the data describe it (see the module docstring), the fixes
    weighted with their noise as the estimators model it (:class:`gnssacc.estimators.settings.
    GnssModel`: the stated sigmas times ``[gnss] sigma_scale``).

    Parameters
    ----------
    run : RecordedRun
        As read (the fixes' sigmas as stated).
    cfg : RunConfig
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Stationary spans; a span at the first IMU sample makes a static start.

    Raises
    ------
    InputError
        When there are not enough GNSS fixes near the start.
    """
    run = run.with_gnss(GnssModel.from_config(cfg).fixes(run.gnss))
    spans = [] if stationary is None else stationary.spans
    if spans and spans[0].t_start - run.t_start <= _STATIC_START_TOL_S:
        return _static_start(run, cfg, spans[0])
    return _moving_start(run, cfg)


def _level(f_b: np.ndarray, a_b: np.ndarray) -> tuple[float, float]:
    """Roll and pitch from the mean specific force with the body acceleration removed."""
    g_b = a_b - f_b  # gravity direction seen in the body frame (points down)
    roll = np.arctan2(g_b[1], g_b[2])
    pitch = np.arctan2(-g_b[0], np.hypot(g_b[1], g_b[2]))
    return float(roll), float(pitch)


def hypothesis(
    run: RecordedRun, cfg: RunConfig, start: StartState, yaw: float, sigma_yaw: float
) -> InitialState:
    """The initial state for one yaw [rad] (1-sigma ``sigma_yaw``): levelling and gyro bias follow
    it."""
    c = cfg["init"]
    lat, lon, h = run.origin.to_llh(start.p_n)
    g = float(gravity_n(lat, h)[2])
    cy, sy = np.cos(yaw), np.sin(yaw)
    a = start.a_n
    roll, pitch = _level(
        start.f_mean_b, np.array([cy * a[0] + sy * a[1], -sy * a[0] + cy * a[1], a[2]])
    )
    # Tilt error: the scatter of the levelling data and the fitted acceleration's noise. Levelling
    # cannot tell an accelerometer bias from a tilt: that part of the error is tied to the bias
    # state, and the estimators start with the correlation (``levelled``).
    var_tilt = (float(np.max(start.f_se_b[:2])) ** 2 + float(np.max(start.var_a[:2]))) / g**2
    sigma_tilt = max(np.sqrt(var_tilt), c["roll_pitch_sigma_min_deg"] * DEG)
    b_g, sigma_b_g = np.zeros(3), None
    if start.omega_mean_b is not None:
        # The still gyro reads its bias plus the earth rate in body axes (which needs the yaw):
        # the bias is only as good as the yaw, which the estimators' start covariance states
        # (``gyro_bias_at_rest``; its sigma here is the mean rate's own).
        b_g = start.omega_mean_b - euler_to_dcm(roll, pitch, yaw).T @ earth_rate_n(lat)
        sigma_b_g = np.maximum(start.omega_se_b, 1.0 * DEG / 3600.0)
    return InitialState(
        t=start.t,
        lat=float(lat),
        lon=float(lon),
        h=float(h),
        v_n=start.v_n.copy(),
        rpy=np.array([roll, pitch, yaw]),
        sigma_pos_m=start.sigma_p.copy(),
        sigma_vel_mps=start.sigma_v.copy(),
        sigma_att_rad=np.array([sigma_tilt, sigma_tilt, sigma_yaw]),
        how=start.how,
        b_g=b_g,
        sigma_b_g=sigma_b_g,
        fit_window=start.fit_window,
        levelled=True,
        gyro_bias_at_rest=start.omega_mean_b is not None,
    )


def with_how(init: InitialState, how: str) -> InitialState:
    """A copy with another account of how it was found."""
    return replace(init, how=how)
