"""Self-initialisation from the data: position and velocity from GNSS, roll/pitch by
accelerometer levelling, yaw from the GNSS course (body x assumed forward).

The filter starts at the centre of the first window of fixes (``init.course_fit_s`` long)
whose straight-line fit shows the vehicle moving faster than ``init.course_min_speed_mps``.
Every sigma is derived from the fit covariances and the levelling residuals, floored by the
``[init]`` minimums, so the filter starts honest rather than optimistic.
"""
from __future__ import annotations

import numpy as np

from .config import DEG, RunConfig
from .earth import gravity_n
from .errors import InputError
from .gnss_accel import acceleration_row
from .run import InitialState, RecordedRun

#: Longest static start examined for levelling [s]; more adds nothing and costs memory.
_STATIC_SEARCH_S = 300.0

#: Prior 1-sigma of a ground vehicle's mean acceleration over the levelling window [m/s^2],
#: used to shrink the (noisy) GNSS-fitted acceleration towards zero.
_ACCEL_PRIOR_SIGMA = 1.0


def initial_sigmas(init: InitialState, cfg: RunConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial 1-sigma of position [m], velocity [m/s] and attitude error (n frame) [rad].

    The initial state's own sigmas, replaced by any ``[init]`` overrides of the configuration;
    both estimators start from these.
    """
    over = cfg.initial_sigma_overrides()
    att = np.array(init.sigma_att_rad, float)
    if "roll_pitch" in over:
        att[:2] = over["roll_pitch"]
    if "yaw" in over:
        att[2] = over["yaw"]
    return (np.asarray(over.get("pos", init.sigma_pos_m), float), np.asarray(over.get("vel", init.sigma_vel_mps), float),
            att)


def static_start(run: RecordedRun, cfg: RunConfig) -> float | None:
    """End time [s] of a static period at the start of the run, or ``None`` if there is none."""
    c = cfg["init"]
    imu = run.imu
    n = int(np.searchsorted(imu.t, imu.t[0] + _STATIC_SEARCH_S))
    moving = (np.linalg.norm(imu.omega_ib_b[:n], axis=1) > c["static_gyro_max_dps"] * DEG)
    first_move = int(np.argmax(moving)) if np.any(moving) else n
    # The specific force must also stay put, per axis, over one-second blocks: both its scatter
    # and its level (a smooth pull-away barely changes the norm, but shifts f_x by the
    # acceleration). A gap is never static.
    dt = np.median(np.diff(imu.t[:max(n, 2)]))
    block = max(int(round(1.0 / dt)), 2)
    thr = c["static_accel_std_max_mps2"]
    end = first_move
    gap = np.flatnonzero(np.diff(imu.t[:first_move]) > 3.0 * dt)
    if gap.size:
        end = min(end, int(gap[0]) + 1)
    ref = None
    for i in range(0, end - block + 1, block):
        f = imu.f_b[i:i + block]
        mean = f.mean(axis=0)
        ref = mean if ref is None else ref
        if np.any(f.std(axis=0) > thr) or np.any(np.abs(mean - ref) > thr):
            end = i
            break
    # Count samples rather than elapsed time, so a data gap cannot pass for a static period.
    if end == 0 or end * dt < c["static_min_s"]:
        return None
    return float(imu.t[end - 1])


def _line_fit(t: np.ndarray, p: np.ndarray, sigma: np.ndarray, t_ref: float):
    """Straight-line fit of positions: value and rate at ``t_ref`` with 1-sigma per axis, and the
    horizontal chi-square of the residuals (sum over N and E of (residual / sigma)^2)."""
    A = np.column_stack([np.ones_like(t), t - t_ref])
    out_p, out_v, sp, sv = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    chi2 = 0.0
    for i in range(3):
        W = 1.0 / sigma[:, i] ** 2
        N = A.T @ (A * W[:, None])
        cov = np.linalg.inv(N)
        x = cov @ (A.T @ (W * p[:, i]))
        out_p[i], out_v[i] = x
        sp[i], sv[i] = np.sqrt(np.diag(cov))
        if i < 2:
            chi2 += float(np.sum(W * (p[:, i] - A @ x) ** 2))
    return out_p, out_v, sp, sv, chi2


def _level(f_b: np.ndarray, a_b: np.ndarray) -> tuple[float, float]:
    """Roll and pitch from the mean specific force with the body acceleration removed."""
    g_b = a_b - f_b  # gravity direction seen in the body frame (points down)
    roll = np.arctan2(g_b[1], g_b[2])
    pitch = np.arctan2(-g_b[0], np.hypot(g_b[1], g_b[2]))
    return float(roll), float(pitch)


def initialise(run: RecordedRun, cfg: RunConfig) -> InitialState:
    """Initial state from the data (used when the source gives none).

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig

    Returns
    -------
    InitialState

    Raises
    ------
    InputError
        When the vehicle never moves fast enough to take yaw from the GNSS course.
    """
    c = cfg["init"]
    gnss = run.gnss
    p_n = run.origin.to_ned(gnss.lat, gnss.lon, gnss.h)
    win = float(c["course_fit_s"])
    t_static_end = static_start(run, cfg)
    # Slow vehicles with noisy fixes need longer windows; a window is extended only while the
    # track stays a line within the fix noise (chi-square test of the fit residuals). For a
    # constant-curvature arc the fitted direction is the course at the window centre.
    # Motion starts after a static period: a window straddling the stop would mix two motions.
    t_first = run.t_start if t_static_end is None else t_static_end
    for k in range(int(np.searchsorted(gnss.t, t_first)), len(gnss)):
        for win_k in (win, 2.0 * win, 4.0 * win):
            sel = slice(k, int(np.searchsorted(gnss.t, gnss.t[k] + win_k, side="right")))
            if sel.stop - sel.start < 3:
                continue
            t_w = gnss.t[sel]
            t_ref = 0.5 * (t_w[0] + t_w[-1])
            if t_ref >= run.t_end:
                break
            p0, v0, sp, sv, chi2 = _line_fit(t_w, p_n[sel], gnss.sigma_ned[sel], t_ref)
            dof = 2 * (len(t_w) - 2)
            if dof > 0 and chi2 > dof + 3.0 * np.sqrt(2.0 * dof):
                break  # not a line any more: a longer window would only be worse
            speed = float(np.hypot(v0[0], v0[1]))
            if speed < c["course_min_speed_mps"] or speed < 3.0 * float(np.hypot(sv[0], sv[1])):
                continue
            yaw = float(np.arctan2(v0[1], v0[0]))
            sigma_yaw = max(float(np.hypot(sv[0], sv[1])) / speed, c["yaw_sigma_min_deg"] * DEG)
            roll, pitch, sigma_tilt, how = _attitude(run, cfg, t_w, p_n[sel], gnss.sigma_ned[sel], yaw, t_static_end)
            lat, lon, h = run.origin.to_llh(p0)
            # A line fitted to accelerating motion is offset by a * var(t) / 2 at the window centre
            # (its slope stays the centre velocity on a symmetric window): budget for it.
            dt_w = t_w - t_ref
            sp_model = _ACCEL_PRIOR_SIGMA * np.mean(dt_w**2) / 2.0
            sv_model = _ACCEL_PRIOR_SIGMA * abs(np.mean(dt_w))
            return InitialState(
                t=t_ref, lat=float(lat), lon=float(lon), h=float(h), v_n=v0,
                rpy=np.array([roll, pitch, yaw]),
                # Averaging fixes only helps against white errors; with correlated (e.g. multipath,
                # Gauss-Markov) errors one fix's sigma is the honest floor.
                sigma_pos_m=np.maximum(np.hypot(sp, sp_model), np.median(gnss.sigma_ned[sel], axis=0)),
                sigma_vel_mps=np.maximum(np.hypot(sv, sv_model), c["vel_sigma_min_mps"]),
                sigma_att_rad=np.array([sigma_tilt, sigma_tilt, sigma_yaw]),
                how=f"self-initialised at t={t_ref:.2f} s: position/velocity from a line fit over "
                    f"{sel.stop - sel.start} fixes ({t_w[-1] - t_w[0]:.1f} s), yaw from GNSS course "
                    f"({speed:.1f} m/s), {how}",
            )
    raise InputError(run.where, f"cannot initialise: the GNSS track never shows a speed above "
                                f"{c['course_min_speed_mps']} m/s clearly above its noise, so yaw is unknown; "
                                f"provide an initial state (init.json) or lower [init] course_min_speed_mps")


def _attitude(run, cfg, t_w, p_w, s_w, yaw, t_static_end):
    """Roll, pitch and their 1-sigma; static levelling when possible, else moving levelling."""
    c = cfg["init"]
    imu = run.imu
    g = gravity_n(run.gnss.lat[0], run.gnss.h[0])[2]
    if t_static_end is not None:
        f_static = imu.f_b[:int(np.searchsorted(imu.t, t_static_end, side="right"))]
        roll, pitch = _level(f_static.mean(axis=0), np.zeros(3))
        # Levelling precision from the specific-force scatter; the vehicle may settle after the
        # static period ends, which the floor covers.
        sigma = np.std(f_static[:, :2], axis=0).max() / np.sqrt(len(f_static)) / g
        return roll, pitch, max(sigma, c["roll_pitch_sigma_min_deg"] * DEG), "roll/pitch from a static start"
    i0, i1 = np.searchsorted(imu.t, [t_w[0], t_w[-1]], side="left")
    if i1 - i0 < 2:
        i0, i1 = np.searchsorted(imu.t, [t_w.mean() - 0.5, t_w.mean() + 0.5])
    f_mean = imu.f_b[i0:max(i1, i0 + 1)].mean(axis=0)
    # Mean acceleration from a quadratic fit of the same fixes, shrunk towards zero by a prior
    # (a ground vehicle's mean acceleration over a few seconds is rarely above ~1 m/s^2).
    B = acceleration_row(t_w)
    a_fit = B @ p_w
    var_fit = (B[:, None] ** 2 * s_w**2).sum(axis=0)
    w = _ACCEL_PRIOR_SIGMA**2 / (_ACCEL_PRIOR_SIGMA**2 + var_fit)
    a_n = w * a_fit
    var_a = w * var_fit
    cy, sy = np.cos(yaw), np.sin(yaw)
    a_b = np.array([cy * a_n[0] + sy * a_n[1], -sy * a_n[0] + cy * a_n[1], a_n[2]])
    roll, pitch = _level(f_mean, a_b)
    sigma = float(np.sqrt(var_a[:2].max())) / g
    return roll, pitch, max(sigma, c["roll_pitch_sigma_min_deg"] * DEG), \
        "roll/pitch by levelling while moving (GNSS-fitted acceleration removed)"
