r"""The window-consistent prediction of the acceleration fitted to Doppler velocities
(``ekf-vaccw``, ``smoother-vaccw``): its kernel, the antenna's lever-arm term, the EKF's Jacobian.

Kernel
------
The least-squares slope of ``m`` velocities, ``a~ = sum_j C_j v_j`` with ``C_j = (t_j - mean t) /
sum_i (t_i - mean t)^2`` (:func:`gnssacc.core.gnss_fit.velocity_accelerations`), satisfies
``sum C_j = 0`` and ``sum C_j t_j = 1``, so with ``v_j = v_0 + int_{t_0}^{t_j} a ds``

    a~ = int K(s) a(s) ds,    K(s) = sum_{j: t_j > s} C_j

(piecewise constant, ``int K = 1``; for three uniform velocities the box ``1 / (2 dt)`` over the
window): :func:`slope_weights` is ``int K`` over each IMU sample, exactly. The INS side is then
the same kernel integral of ``a = R f + g - 2 omega_ie x v`` as the window-consistent position
form's (:mod:`.accel_model`, ``F_b, M, G`` of
:func:`gnssacc.estimators.mechanization.kernel_force_integrals`, the earth rate's Coriolis term
with the velocity at the update epoch; the transport rate's, below 1e-4 m/s^2, left out).

Lever arm
---------
The velocities are the antenna's, ``v_ant = v + R (w x l) - omega_ie x (R l)``, so
``a~ = int K a ds + sum_j C_j R_j (w_j x l)`` (the earth-rate term's share, ``omega_ie x (R_k sum_j
C_j R_{b_k b_j} l)``, is of order 1e-5 m/s^2 and left out). With ``R_j = R_k R_{b_k b_j}`` (the body
rotation from the gyros, walking back from the update epoch ``t_k``) the term is ``R_k u_l``,
``u_l = sum_j C_j R_{b_k b_j} (w_j x l)`` (:func:`lever_term`), and under the EKF's error convention
(the gyro-bias error turns the relative rotation, ``R^est_{b_k b_j} = (I - [(Gamma_j db) x])
R_{b_k b_j}``, ``Gamma_j = int_{t_j}^{t_k} R_{b_k b_tau} d tau``, and adds to the rate)

    d u_l / d b_g = sum_j C_j ([(R_{b_k b_j} (w_j x l)) x] Gamma_j - R_{b_k b_j} [l x]).

EKF: ``dz = R_k (F_b + u_l) + g - 2 omega_ie x v - a~``,
``H = [0, -2 [omega_ie x], -[(R_k (F_b + u_l)) x], R_k M, R_k (G + d u_l / d b_g)]``.
"""

from __future__ import annotations

import numpy as np

from ...core.rotations import cross3, skew
from ..layout import ATT, BA, BG, VEL
from .base import Measurement, zero_jacobian


def slope_coefficients(t: np.ndarray) -> np.ndarray:
    """``C_j`` [1/s] of the least-squares slope over velocities at times ``t`` [s] (module
    notes)."""
    u = np.asarray(t, float) - np.mean(t)
    return u / float(u @ u)


def slope_weights(t_vel: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``int_lo^hi K(s) ds`` of the slope's kernel over intervals ``[lo_i, hi_i]`` inside the window
    ``t_vel`` [s]: ``sum_j C_j (min(hi, t_j) - min(lo, t_j))``, exact (``K`` piecewise constant);
    they sum to 1 over intervals that tile the window."""
    t = np.asarray(t_vel, float)
    C = slope_coefficients(t)
    t0 = t[0]
    lo = np.asarray(lo, float)[:, None] - t0
    hi = np.asarray(hi, float)[:, None] - t0
    return (np.minimum(hi, t - t0) - np.minimum(lo, t - t0)) @ C


def _exp_so3(v: np.ndarray) -> np.ndarray:
    th = float(np.sqrt(v @ v))
    K = skew(v)
    if th < 1e-8:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / (th * th) * (K @ K)


def lever_term(
    imu_t: np.ndarray,
    omega_b: np.ndarray,
    t_vel: np.ndarray,
    omega_vel: np.ndarray,
    lever_b: np.ndarray,
    b_g: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``u_l`` [m/s^2, body at the window's end] and ``d u_l / d b_g`` [m/s] (module notes).

    Parameters
    ----------
    imu_t, omega_b : ndarray (N,), (N, 3)
        The IMU's times and raw gyro [rad/s] (sample ``i`` holds over ``(t[i-1], t[i]]``).
    t_vel : ndarray (m,)
        The window's velocity times [s]; the IMU covers them.
    omega_vel : ndarray (m, 3)
        The raw gyro held at each velocity [rad/s].
    lever_b : ndarray (3,)
    b_g : ndarray (3,)
        Gyro-bias estimate [rad/s].
    """
    C = slope_coefficients(t_vel)
    u = np.zeros(3)
    d_bg = np.zeros((3, 3))
    R, Gam = np.eye(3), np.zeros((3, 3))
    i = int(np.searchsorted(imu_t, t_vel[-1], side="left"))  # the sample holding at t_k
    t = float(t_vel[-1])
    L = skew(lever_b)
    for j in range(len(t_vel) - 1, -1, -1):
        while t > t_vel[j] + 1e-12:  # walk back to t_j, one sample (or its overlap) at a time
            lo = max(float(imu_t[i - 1]), float(t_vel[j])) if i > 0 else float(t_vel[j])
            h = t - lo
            Rm = R @ _exp_so3(-0.5 * h * (omega_b[i] - b_g))
            Gam = Gam + h * Rm
            R = R @ _exp_so3(-h * (omega_b[i] - b_g))
            t = lo
            if i > 0 and lo <= float(imu_t[i - 1]) + 1e-12:
                i -= 1
        a = R @ cross3(omega_vel[j] - b_g, lever_b)
        u += C[j] * a
        d_bg += C[j] * (skew(a) @ Gam - R @ L)
    return u, d_bg


def velocity_window_acceleration(
    s,
    a_n: np.ndarray,
    cov: np.ndarray,
    F_b: np.ndarray,
    M: np.ndarray,
    G: np.ndarray,
    g_n: np.ndarray,
    w_ie_n: np.ndarray,
    lever: tuple[np.ndarray, np.ndarray] | None,
) -> Measurement:
    """The window-consistent update of an acceleration ``a_n`` [m/s^2] (covariance ``cov``) fitted
    to the antenna's velocities (module notes); ``F_b, M, G`` the slope kernel's integrals at the
    state's biases, ``lever`` the output of :func:`lever_term` (``None``: no lever arm)."""
    u_l, d_ul = lever if lever is not None else (np.zeros(3), np.zeros((3, 3)))
    R = s.R_nb
    a_b = R @ (F_b + u_l)
    W = skew(w_ie_n)
    H = zero_jacobian(s, 3)
    H[:, VEL] = -2.0 * W
    H[:, ATT] = -skew(a_b)
    H[:, BA] = R @ M
    H[:, BG] = R @ (G + d_ul)
    a_pred = a_b + g_n - 2.0 * W @ s.v_n
    return Measurement("acc", a_pred - a_n, H, cov)
