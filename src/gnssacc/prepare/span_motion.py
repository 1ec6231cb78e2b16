"""Is an IMU-still span at rest or cruising? The fixes around it, linked to it by the IMU.

An IMU cannot tell standing from a constant-speed cruise, and inside a GNSS outage the fixes
in and just around a span (:mod:`gnssacc.prepare.stationary`, step 4) are missing or too few
to tell. The fixes before and after the outage still can, once the IMU carries them to the
span: relative to the span, the IMU measures the velocity change and the path outside it
(biases and gravity cancel against the span's own mean readings). What it cannot measure is
the heading of that path in the north/east plane, nor the span's own velocity ``v_n``, which is
constant through the span (it is IMU-still). So every fix within ``link_reach_s`` of the
span, with ``t_s`` the span's start and ``P(t)`` the IMU path in the span's level axes
(:func:`level_path`), is modelled as::

    p_n(t_k) = p_s + v_n (t_k - t_s) + R(psi) P(t_k)        (P = 0 inside the span)

linear in the start position ``p_s`` and ``v_n`` for a given heading ``psi`` of the span's
level axes, over which the fit is minimised (a dense grid: the heading is unknown in
preparation). "At rest" is ``v_n = 0``; the generalised likelihood ratio of the two fits,
``chi2_rest - chi2_moving``, is chi-square with 2 degrees of freedom at rest once divided by
the residuals' correlation factor (:func:`correlation_inflation`). Each fix's sigma is
widened by the IMU path's error bound at its time (the detector's ``excursion_floor_mps2``,
second-order tilt and gyro cross-axis terms, integrated twice).

Frames and units: body FRD for the IMU; north/east [m] for the fixes; SI inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.recording import GnssFixes, GnssVelocity, ImuData
from ..core.stationary_params import StationaryParams
from .fix_wander import spread_from_span

#: Gravity for error budgets only [m/s^2] (2 % accuracy is plenty there).
G_APPROX = 9.8


@dataclass(frozen=True)
class LinkedMotion:
    """What the IMU-linked fixes say about a span's velocity.

    Attributes
    ----------
    speed_mps : float
        Fitted horizontal speed through the span, ``|v_n|`` [m/s].
    speed_sigma_mps : float
        Its 1-sigma per axis at the fitted heading, ``sqrt((var v_N + var v_E) / 2)`` [m/s].
    glr : float
        ``chi2_rest - chi2_moving`` (chi-square, 2 dof, at rest) [-].
    n_fixes : int
        Fixes and GNSS velocities used (inside the span and within ``link_reach_s`` around it).
    """

    speed_mps: float
    speed_sigma_mps: float
    glr: float
    n_fixes: int

    def shows_motion(self, p: StationaryParams) -> bool:
        """True when "at rest" is refuted: the ratio beyond the two-dimensional ``gnss_k_sigma``
        (its square is the chi-square-2 quantile of the same probability) and the speed above
        ``gnss_speed_floor_mps`` (the fixes' own slow wander)."""
        return self.glr > p.gnss_k_sigma**2 and self.speed_mps > p.gnss_speed_floor_mps


def level_acceleration(f_b: np.ndarray, theta: np.ndarray, f_ref_b: np.ndarray) -> np.ndarray:
    """Horizontal acceleration (n, 2) [m/s^2] in a span's level x/y axes at samples with specific
    force ``f_b`` (n, 3) [m/s^2, body FRD], rotated by ``theta`` (n, 3) [rad] from the span.

    With the span's mean specific force ``f_ref_b`` as the rest reference (gravity and the
    accelerometer bias), the body acceleration is ``f - f_ref + theta_xy x f_ref`` to first order
    in the tilt change; a turn about body z leaves gravity in place, so the horizontal part is
    rotated by the heading change ``theta_z`` only."""
    tilt = theta * np.array([1.0, 1.0, 0.0])
    return _turned(f_b - f_ref_b + np.cross(tilt, f_ref_b), theta[:, 2])


def _turned(x_b: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """The x/y part of body vectors ``x_b`` (n, 3) in the span's level axes, for heading changes
    ``psi`` (n,) [rad] from the span."""
    c, s = np.cos(psi), np.sin(psi)
    return np.column_stack([c * x_b[:, 0] - s * x_b[:, 1], s * x_b[:, 0] + c * x_b[:, 1]])


def tilt_error(theta: np.ndarray, cross_axis: float, g: float = G_APPROX) -> np.ndarray:
    """What :func:`level_acceleration` misses [m/s^2] (n,): the second-order tilt
    ``0.5 g |theta_xy|^2``, and the tilt a turn fakes through gyro cross-axis coupling,
    ``g cross_axis |theta_z|``."""
    return g * (0.5 * np.sum(theta[:, :2] ** 2, axis=1) + cross_axis * np.abs(theta[:, 2]))


def fix_rate_inflation(t: np.ndarray, corr_s: float) -> float:
    """Variance factor for fixes at times ``t`` [s] faster than one per ``corr_s`` [s]: their
    errors are taken as correlated over ``corr_s``, so they count ``corr_s / interval`` times
    less (:class:`gnssacc.core.stationary_params.StationaryParams`, ``gnss_corr_s``)."""
    interval = float(np.median(np.diff(t))) if len(t) > 1 else corr_s
    return max(1.0, corr_s / max(interval, 1e-9))


def outward_samples(
    t: np.ndarray, i_edge: int, before: bool, reach_s: float, gap_limit_s: float
) -> np.ndarray:
    """IMU sample indices from the span's edge outward over ``reach_s`` seconds, cut at the first
    interval longer than ``gap_limit_s`` (nothing is known across an IMU gap).

    ``i_edge`` is the span's first sample (``before``) or its last; the edge itself is excluded.
    """
    if before:
        lo = int(np.searchsorted(t, t[i_edge] - reach_s, side="left"))
        idx = np.arange(i_edge - 1, lo - 1, -1)
    else:
        hi = int(np.searchsorted(t, t[i_edge] + reach_s, side="right"))
        idx = np.arange(i_edge + 1, hi)
    steps = np.abs(np.diff(t[np.concatenate([[i_edge], idx])]))
    gap = np.flatnonzero(steps > gap_limit_s)
    return idx[: gap[0]] if gap.size else idx


@dataclass(frozen=True)
class LevelPath:
    """The antenna's motion from a span's edge outward, by the IMU, in the span's level axes.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Sample times [s], in time order (every array below in the same order).
    P : ndarray, shape (n, 2)
        ``p(t) - p_edge - v_edge (t - t_edge)`` of the antenna, level x/y [m].
    bound : ndarray, shape (n,)
        Error bound of ``|P|`` [m].
    V : ndarray, shape (n, 2)
        ``v(t) - v_edge`` of the antenna, level x/y [m/s].
    bound_v : ndarray, shape (n,)
        Error bound of ``|V|`` [m/s].
    """

    t: np.ndarray
    P: np.ndarray
    bound: np.ndarray
    V: np.ndarray
    bound_v: np.ndarray

    def at(self, t_q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``P, bound, V, bound_v`` interpolated at times ``t_q`` [s] within the path."""
        col = lambda x: np.interp(t_q, self.t, x)  # noqa: E731
        P = np.column_stack([col(self.P[:, 0]), col(self.P[:, 1])])
        V = np.column_stack([col(self.V[:, 0]), col(self.V[:, 1])])
        return P, col(self.bound), V, col(self.bound_v)


def level_path(
    imu: ImuData,
    idx: np.ndarray,
    i_edge: int,
    f_ref_b: np.ndarray,
    omega_ref_b: np.ndarray,
    p: StationaryParams,
    lever_b: np.ndarray | None = None,
) -> LevelPath:
    """The antenna's path from a span's edge outward, in the span's level axes, by the IMU, and
    its error bound.

    Parameters
    ----------
    idx : ndarray of int
        Samples ordered outward from the edge sample ``i_edge`` (:func:`outward_samples`).
    f_ref_b, omega_ref_b : ndarray, shape (3,)
        The span's mean specific force [m/s^2] and angular rate [rad/s], body FRD: the rest
        reference (gravity and both biases).
    lever_b : ndarray, shape (3,), optional
        The antenna from the IMU, body FRD [m]: it swings about the IMU as the vehicle turns
        (the heading's swing is modelled, the tilt's ``|l| |theta_xy|`` bounded).
    """
    t = imu.t[idx]
    sign = 1.0 if len(idx) and idx[0] > i_edge else -1.0
    dt = np.abs(np.diff(np.concatenate([[imu.t[i_edge]], t])))
    w = imu.omega_ib_b[idx] - omega_ref_b
    # Rotation from the span to each sample (small-angle in roll and pitch, yaw kept whole).
    theta = sign * np.cumsum(w * dt[:, None], axis=0)
    V = sign * np.cumsum(level_acceleration(imu.f_b[idx], theta, f_ref_b) * dt[:, None], axis=0)
    P = sign * np.cumsum(V * dt[:, None], axis=0)
    err = tilt_error(theta, p.chain_cross_axis)
    bound_v = np.cumsum((err + p.excursion_floor_mps2) * dt)
    bound = np.cumsum(bound_v * dt)
    if lever_b is not None and np.any(lever_b):
        l_b = np.tile(lever_b, (len(idx), 1))
        P = P + _turned(l_b, theta[:, 2]) - lever_b[:2]
        V = V + _turned(np.cross(w, l_b), theta[:, 2])
        bound = bound + np.linalg.norm(lever_b) * np.linalg.norm(theta[:, :2], axis=1)
        bound_v = bound_v + np.linalg.norm(lever_b) * np.linalg.norm(w[:, :2], axis=1)
    o = slice(None, None, int(sign))  # outward -> time order
    return LevelPath(t[o], P[o], bound[o], V[o], bound_v[o])


def _position_rows(t_k, p_k, P_k, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Design rows (north then east per fix) for ``[p_N, p_E, v_N, v_E, cos, sin]``."""
    m = len(t_k)
    A = np.zeros((2 * m, 6))
    A[0::2, 0], A[1::2, 1] = 1.0, 1.0
    A[0::2, 2], A[1::2, 3] = t_k - t_s, t_k - t_s
    A[0::2, 4], A[0::2, 5] = P_k[:, 0], -P_k[:, 1]
    A[1::2, 4], A[1::2, 5] = P_k[:, 1], P_k[:, 0]
    return A, p_k[:, :2].reshape(-1)


def _velocity_rows(v_k, V_k) -> tuple[np.ndarray, np.ndarray]:
    """Design rows (north then east per velocity) for ``[p_N, p_E, v_N, v_E, cos, sin]``."""
    A = np.zeros((2 * len(v_k), 6))
    A[0::2, 2], A[1::2, 3] = 1.0, 1.0
    A[0::2, 4], A[0::2, 5] = V_k[:, 0], -V_k[:, 1]
    A[1::2, 4], A[1::2, 5] = V_k[:, 1], V_k[:, 0]
    return A, v_k[:, :2].reshape(-1)


def _paths(imu, span, p: StationaryParams, dt_med: float, lever_b) -> list:
    """The level paths before and after the span (None where the IMU has no samples)."""
    out = []
    for before in (True, False):
        i_edge = span.i_start if before else span.i_end - 1
        idx = outward_samples(imu.t, i_edge, before, p.link_reach_s, p.gap_factor * dt_med)
        path = None
        if len(idx):
            path = level_path(imu, idx, i_edge, span.f_mean_b, span.omega_mean_b, p, lever_b)
        out.append(path)
    return out


def _pieces(times: np.ndarray, span, paths: list) -> list:
    """Index arrays of ``times`` before, inside and after the span, each with its path (None
    inside: the span does not move relative to itself)."""
    inside = np.flatnonzero((times >= span.t_start) & (times <= span.t_end))
    out = [(inside, None)]
    for path in paths:
        if path is not None:
            lo, hi = path.t[0], path.t[-1]
            out.append((np.flatnonzero((times >= lo) & (times <= hi)), path))
    return out


def _carried(path, t_q: np.ndarray, velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """The carried path ``P`` (or its velocity ``V``) and its bound at times ``t_q`` [s]; zeros
    inside the span (``path`` None: the span does not move relative to itself)."""
    if path is None:
        return np.zeros((len(t_q), 2)), np.zeros(len(t_q))
    P, bound, V, bound_v = path.at(t_q)
    return (V, bound_v) if velocity else (P, bound)


def _fix_block(gnss: GnssFixes, p_n, span, paths, p: StationaryParams, wander: float = 0.0):
    """Position rows, observations and variances of the fixes in and around the span; the fixes'
    wander ``wander`` [m^2/s] adds :func:`gnssacc.prepare.fix_wander.spread_from_span` (the random
    walk's spread from the span's fixes, taken per fix; not scaled for the fix rate, which is about
    the white part)."""
    A, y, var, t = [np.zeros((0, 6))], [np.zeros(0)], [np.zeros(0)], [np.zeros(0)]
    walks = [np.zeros(0)]
    for k, path in _pieces(gnss.t, span, paths):
        if k.size == 0:
            continue
        P, bound = _carried(path, gnss.t[k], velocity=False)
        a, obs = _position_rows(gnss.t[k], p_n[k], P, span.t_start)
        A.append(a)
        y.append(obs)
        walks.append(np.repeat(spread_from_span(wander, gnss.t[k], span.t_start, span.t_end), 2))
        var.append((gnss.sigma_ned[k, :2] ** 2 + bound[:, None] ** 2).reshape(-1))
        t.append(gnss.t[k])
    corr = fix_rate_inflation(np.unique(np.concatenate(t)), p.gnss_corr_s)
    return np.vstack(A), np.concatenate(y), np.concatenate(var) * corr + np.concatenate(walks)


def _velocity_block(vel, span, paths):
    """Velocity rows, observations and variances of the GNSS velocities in and around the span
    (those with both horizontal axes measured)."""
    A, y, var = [np.zeros((0, 6))], [np.zeros(0)], [np.zeros(0)]
    if vel is None or len(vel) == 0:
        return A[0], y[0], var[0]
    both = np.all(np.isfinite(vel.v_ned[:, :2]) & np.isfinite(vel.sigma_ned[:, :2]), axis=1)
    for k, path in _pieces(vel.t, span, paths):
        k = k[both[k]]
        if k.size == 0:
            continue
        V, bound_v = _carried(path, vel.t[k], velocity=True)
        a, obs = _velocity_rows(vel.v_ned[k], V)
        A.append(a)
        y.append(obs)
        var.append((vel.sigma_ned[k, :2] ** 2 + bound_v[:, None] ** 2).reshape(-1))
    return np.vstack(A), np.concatenate(y), np.concatenate(var)


def linked_motion(
    imu: ImuData,
    span,
    gnss: GnssFixes,
    p_n: np.ndarray,
    p: StationaryParams,
    dt_med: float,
    lever_b: np.ndarray | None = None,
    velocity: GnssVelocity | None = None,
    wander: float = 0.0,
) -> LinkedMotion | None:
    """Test "at rest" for a span against the fixes (and GNSS velocities) in it and within
    ``link_reach_s`` around it, carried to it by the IMU (module notes). None when there are
    too few to tell.

    Parameters
    ----------
    span : gnssacc.prepare.stationary.StationarySpan
        Its sample range and mean readings are used.
    p_n : ndarray, shape (M, 3)
        The fixes in the local NED frame [m].
    dt_med : float
        Median IMU interval [s].
    lever_b : ndarray, shape (3,), optional
        The GNSS antenna from the IMU, body FRD [m] (default: at the IMU).
    velocity : GnssVelocity, optional
        The receiver's velocities of the antenna [m/s], NED: rows ``v_n + R(psi) V(t)``.
    wander : float
        The fixes' random-walk rate per horizontal axis [m^2/s]
        (:func:`gnssacc.prepare.fix_wander.fix_wander`).
    """
    paths = _paths(imu, span, p, dt_med, lever_b)
    blocks = [
        _fix_block(gnss, p_n, span, paths, p, wander),
        _velocity_block(velocity, span, paths),
    ]
    n_obs = sum(len(b[1]) // 2 for b in blocks)
    if n_obs < 3:
        return None
    A = np.vstack([b[0] for b in blocks])
    y = np.concatenate([b[1] for b in blocks])
    n_fix = len(blocks[0][1])

    def fit(inflate: tuple):
        var = np.concatenate([b[2] * f for b, f in zip(blocks, inflate)])
        w = 1.0 / np.sqrt(var)
        Aw, yw = A * w[:, None], y * w
        return Aw, yw, _profiled_fit(Aw[:, :4], Aw[:, 4:], yw)

    # The first fit's residuals tell how correlated each kind's errors are; the second uses that.
    resid = fit((1.0, 1.0))[2][2]
    inflate = tuple(correlation_inflation(r.reshape(-1, 2)) for r in (resid[:n_fix], resid[n_fix:]))
    Aw, yw, (chi_full, x_full, _) = fit(inflate)
    chi_rest = _profiled_fit(Aw[:, :2], Aw[:, 4:], yw)[0]
    cov_v = np.linalg.pinv(Aw[:, :4].T @ Aw[:, :4])[2:, 2:]
    return LinkedMotion(
        float(np.hypot(*x_full[2:4])),
        float(np.sqrt(max(np.trace(cov_v), 0.0) / 2.0)),
        max(chi_rest - chi_full, 0.0),
        n_obs,
    )


def correlation_inflation(r: np.ndarray) -> float:
    """Variance factor for fix errors correlated from one fix to the next, learnt from the
    normalised residuals ``r`` (n, 2) of the fit, in time order: ``(1 + rho) / (1 - rho)`` for
    their lag-1 correlation ``rho`` (an AR(1) error's variance of a mean or slope, the factor
    by which the fixes count less than independent ones); clipped to ``[1, n / 3]``.

    A receiver's errors wander (multipath, atmosphere; tens of seconds), and over the tens of
    seconds of fixes used here that wander would pass for a slow crawl."""
    n = len(r)
    power = float(np.sum(r**2))
    if n < 4 or power <= 0.0:
        return 1.0
    rho = min(max(float(np.sum(r[1:] * r[:-1])) / power, 0.0), 0.99)
    return float(min(max((1.0 + rho) / (1.0 - rho), 1.0), max(n / 3.0, 1.0)))


def _profiled_fit(L: np.ndarray, G: np.ndarray, y: np.ndarray, n_psi: int = 3600):
    """Least squares ``y ~ L x + G (cos psi, sin psi)`` minimised over the linear ``x`` and the
    heading ``psi`` (a grid of ``n_psi``; the residual is a quadratic form in ``(cos, sin)``
    once the linear part is projected out). Returns the minimum chi-square, ``x`` there and the
    residuals."""
    Q, _ = np.linalg.qr(L)
    proj = lambda v: v - Q @ (Q.T @ v)  # noqa: E731 - the residual maker of L
    r0, R = proj(y), np.column_stack([proj(G[:, 0]), proj(G[:, 1])])
    psi = np.linspace(0.0, 2.0 * np.pi, n_psi, endpoint=False)
    cs = np.vstack([np.cos(psi), np.sin(psi)])
    M, b = R.T @ R, R.T @ r0
    chi = r0 @ r0 - 2.0 * (b @ cs) + np.einsum("ik,ij,jk->k", cs, M, cs)
    k = int(np.argmin(chi))
    x = np.linalg.lstsq(L, y - G @ cs[:, k], rcond=None)[0]
    return float(chi[k]), x, y - L @ x - G @ cs[:, k]
