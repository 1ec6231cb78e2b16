r"""Strapdown mechanization in geodetic coordinates / NED (paper eqs. 1-3) and the 15-state
error model F, G, compiled with numba.

Nominal state: ``pos = [lat, lon, h]`` [rad, rad, m], ``v_n`` [m/s], ``R_nb``, and the
accumulated bias estimates ``b_a`` [m/s^2], ``b_g`` [rad/s].

Error state (estimate minus truth), order as in the paper:
``dx = [dp_n (N, E, D metres), dv_n, phi, b_a, b_g]`` with ``R_nb_est = (I + [phi x]) R_nb``,
``f_est = f + b_a``, ``omega_est = omega + b_g``. In this convention

* ``d(dp)/dt  = F_pp dp + dv``
* ``d(dv)/dt  = F_vp dp + F_vv dv - [(R_nb f) x] phi + R_nb b_a + R_nb w_a``
* ``d(phi)/dt = F_phi_p dp + F_phi_v dv - [omega_in x] phi + R_nb b_g + R_nb w_g``
* ``d(b)/dt   = w_b`` (random walks)

which is the paper's F and G (``F_v,ba = F_phi,bg = R_nb``). The position error is in metres,
``dp_N = (R_M + h) dlat``, ``dp_E = (R_N + h) cos(lat) dlon``, ``dp_D = -dh``; the blocks are
derived in ``system_matrix`` and checked against finite differences of the nonlinear model in
the tests.

IMU samples: sample ``k`` is held over ``(t[k-1], t[k]]``. Intervals are split exactly at event
times (GNSS epochs, outputs).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from . import earth

_A, _E2, _W, _F = earth.A, earth.E2, earth.OMEGA_IE, earth.F
_GE, _K, _M = earth.GAMMA_E, earth.SOMIGLIANA_K, earth.M_RATIO


@njit(cache=True)
def _radii(lat):
    s2 = np.sin(lat) ** 2
    w = 1.0 - _E2 * s2
    return _A * (1.0 - _E2) / w**1.5, _A / np.sqrt(w)


@njit(cache=True)
def _gravity(lat, h):
    """Normal gravity magnitude [m/s^2] and its height derivative [1/s^2]."""
    s2 = np.sin(lat) ** 2
    g0 = _GE * (1.0 + _K * s2) / np.sqrt(1.0 - _E2 * s2)
    c1 = 2.0 / _A * (1.0 + _F + _M - 2.0 * _F * s2)
    g = g0 * (1.0 - c1 * h + 3.0 * h * h / (_A * _A))
    dg_dh = g0 * (-c1 + 6.0 * h / (_A * _A))
    return g, dg_dh


# Small products are written out: numba's `@` goes through BLAS (and needs scipy), which costs
# more than the arithmetic for 3x3 matrices.
@njit(cache=True)
def _mm(A, B):
    n, m, p = A.shape[0], A.shape[1], B.shape[1]
    C = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            a = A[i, k]
            if a != 0.0:
                for j in range(p):
                    C[i, j] += a * B[k, j]
    return C


@njit(cache=True)
def _mv(A, x):
    y = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            y[i] += A[i, k] * x[k]
    return y


@njit(cache=True)
def _skew(v, out):
    out[0, 0] = 0.0
    out[0, 1] = -v[2]
    out[0, 2] = v[1]
    out[1, 0] = v[2]
    out[1, 1] = 0.0
    out[1, 2] = -v[0]
    out[2, 0] = -v[1]
    out[2, 1] = v[0]
    out[2, 2] = 0.0


@njit(cache=True)
def _exp_so3(phi):
    """Rodrigues' formula."""
    angle = np.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    K = np.empty((3, 3))
    _skew(phi, K)
    if angle < 1e-8:
        a, b = 1.0, 0.5
    else:
        a = np.sin(angle) / angle
        b = (1.0 - np.cos(angle)) / (angle * angle)
    return np.eye(3) + a * K + b * _mm(K, K)


@njit(cache=True)
def _rates(pos, v_n):
    """Earth rate and transport rate in NED [rad/s], radii [m]."""
    lat, h = pos[0], pos[2]
    R_M, R_N = _radii(lat)
    w_ie = np.array([_W * np.cos(lat), 0.0, -_W * np.sin(lat)])
    w_en = np.array([v_n[1] / (R_N + h), -v_n[0] / (R_M + h), -v_n[1] * np.tan(lat) / (R_N + h)])
    return w_ie, w_en, R_M, R_N


@njit(cache=True)
def strapdown_step(pos, v_n, R_nb, f_b, omega_ib_b, dt):
    """Advance the nominal state by ``dt`` [s] with a held IMU sample (in place).

    Attitude: ``R <- Exp(-omega_in dt) R Exp(omega_ib dt)`` (paper eq. 3); velocity: paper eq. 2
    with the specific force rotated by the mean of the old and new attitude; position: paper
    eq. 1 with the trapezoidal velocity.
    """
    w_ie, w_en, R_M, R_N = _rates(pos, v_n)
    g, _ = _gravity(pos[0], pos[2])
    R_new = _mm(_mm(_exp_so3(-(w_ie + w_en) * dt), R_nb), _exp_so3(omega_ib_b * dt))
    f_n = _mv(0.5 * (R_nb + R_new), f_b)
    cor = np.cross(2.0 * w_ie + w_en, v_n)
    v_new = np.empty(3)
    for i in range(3):
        v_new[i] = v_n[i] + (f_n[i] - cor[i]) * dt
    v_new[2] += g * dt
    vm = 0.5 * (v_n + v_new)
    pos[0] += vm[0] / (R_M + pos[2]) * dt
    pos[1] += vm[1] / ((R_N + pos[2]) * np.cos(pos[0])) * dt
    pos[2] -= vm[2] * dt
    v_n[:] = v_new
    R_nb[:, :] = R_new


@njit(cache=True)
def system_matrix(pos, v_n, R_nb, f_b):
    """Continuous-time error-state matrix F (15 x 15) at the current nominal state.

    Parameters
    ----------
    pos : ndarray (3,)
        lat, lon [rad], h [m].
    v_n : ndarray (3,)
        NED velocity [m/s].
    R_nb : ndarray (3, 3)
    f_b : ndarray (3,)
        Bias-corrected specific force [m/s^2].
    """
    lat, h = pos[0], pos[2]
    vN, vE, vD = v_n[0], v_n[1], v_n[2]
    w_ie, w_en, R_M, R_N = _rates(pos, v_n)
    g, dg_dh = _gravity(lat, h)
    rm, rn = R_M + h, R_N + h
    tl, cl, sl = np.tan(lat), np.cos(lat), np.sin(lat)

    F = np.zeros((15, 15))
    S = np.empty((3, 3))
    # Position rows (metres): d(dp)/dt = F_pp dp + dv.
    F[0, 0] = -vD / rm
    F[0, 2] = vN / rm
    F[1, 0] = vE * tl / rm
    F[1, 1] = -(vD / rn + vN * tl / rm)
    F[1, 2] = vE / rn
    for i in range(3):
        F[i, 3 + i] = 1.0

    # Sensitivities of omega_ie + omega_en (d/dlat, d/dh) and of omega_en (d/dv).
    dW_dlat = np.array([-_W * sl, 0.0, -_W * cl - vE / (rn * cl * cl)])
    dWie_dlat = np.array([-_W * sl, 0.0, -_W * cl])
    drho_dlat = np.array([0.0, 0.0, -vE / (rn * cl * cl)])
    drho_dh = np.array([-vE / rn**2, vN / rm**2, vE * tl / rn**2])
    drho_dv = np.zeros((3, 3))
    drho_dv[0, 1] = 1.0 / rn
    drho_dv[1, 0] = -1.0 / rm
    drho_dv[2, 1] = -tl / rn

    # Velocity rows: dv_dot = -[(2 w_ie + w_en) x] dv + [v x] d(2 w_ie + w_en) + dg - [(R f) x] phi + R b_a.
    Vx = np.empty((3, 3))
    _skew(v_n, Vx)
    _skew(2.0 * w_ie + w_en, S)
    Fvv = -S + _mm(Vx, drho_dv)
    col_N = _mv(Vx, 2.0 * dWie_dlat + drho_dlat) / rm
    col_D = -_mv(Vx, drho_dh)
    _skew(_mv(R_nb, f_b), S)
    for i in range(3):
        for j in range(3):
            F[3 + i, 3 + j] = Fvv[i, j]
            F[3 + i, 6 + j] = -S[i, j]
            F[3 + i, 9 + j] = R_nb[i, j]
        F[3 + i, 0] = col_N[i]
        F[3 + i, 2] = col_D[i]
    F[5, 2] += -dg_dh  # dp_D = -dh and g_D = g(h)

    # Attitude rows: phi_dot = -[w_in x] phi - d(w_in) + R b_g.
    _skew(w_ie + w_en, S)
    for i in range(3):
        F[6 + i, 0] = -dW_dlat[i] / rm
        F[6 + i, 2] = drho_dh[i]
        for j in range(3):
            F[6 + i, 3 + j] = -drho_dv[i, j]
            F[6 + i, 6 + j] = -S[i, j]
            F[6 + i, 12 + j] = R_nb[i, j]
    return F


# Column ranges of the non-zero entries of F, per block row (rows 9..14 of F are zero).
_NZ_P = (0, 6)     # position rows: dp, dv
_NZ_V = (0, 12)    # velocity rows: dp, dv, phi, b_a


@njit(cache=True)
def _propagate_cov(P, F, A, R_nb, dt, q_a, q_g, q_ba, q_bg, phi_order):
    """P <- Phi P Phi^T + Q with Phi = I + F dt (+ (F dt)^2 / 2) and Q = G Qc G^T dt.

    For the first-order case ``Phi P Phi^T = P + dt (F P + P F^T) + dt^2 F P F^T`` is evaluated
    with F's sparsity (only rows 0..8 are non-zero), about 4x fewer operations than dense.
    ``A`` is a (9, 15) work array.
    """
    if phi_order == 2:
        Phi = F * dt
        Phi = Phi + 0.5 * _mm(Phi, Phi)
        for i in range(15):
            Phi[i, i] += 1.0
        P[:, :] = _mm(_mm(Phi, P), Phi.T.copy())
    else:
        # A = F P over the non-zero columns of each row of F.
        for i in range(9):
            for j in range(15):
                acc = 0.0
                if i < 3:
                    for k in range(_NZ_P[0], _NZ_P[1]):
                        acc += F[i, k] * P[k, j]
                elif i < 6:
                    for k in range(_NZ_V[0], _NZ_V[1]):
                        acc += F[i, k] * P[k, j]
                else:
                    for k in range(9):
                        acc += F[i, k] * P[k, j]
                    for k in range(12, 15):
                        acc += F[i, k] * P[k, j]
                A[i, j] = acc
        dt2 = dt * dt
        for i in range(9):
            for j in range(i, 15):
                if j < 9:
                    # (F P F^T)[i, j] = sum_k A[i, k] F[j, k]
                    fpf = 0.0
                    for k in range(15):
                        fpf += A[i, k] * F[j, k]
                    v = P[i, j] + dt * (A[i, j] + A[j, i]) + dt2 * fpf
                else:
                    v = P[i, j] + dt * A[i, j]
                P[i, j] = v
                P[j, i] = v
    # G Qc G^T: R diag(q) R^T for the white sensor noise (body axes).
    for i in range(3):
        for j in range(3):
            sa = 0.0
            sg = 0.0
            for k in range(3):
                sa += R_nb[i, k] * q_a[k] * R_nb[j, k]
                sg += R_nb[i, k] * q_g[k] * R_nb[j, k]
            P[3 + i, 3 + j] += sa * dt
            P[6 + i, 6 + j] += sg * dt
        P[9 + i, 9 + i] += q_ba[i] * dt
        P[12 + i, 12 + i] += q_bg[i] * dt


@njit(cache=True)
def _segment_index(k, seg_i0, seg_i1):
    """Index of the disjoint sorted segment ``[i0, i1)`` containing sample ``k``, or -1."""
    lo, hi = 0, seg_i0.shape[0]
    while lo < hi:  # first segment whose end is beyond k
        mid = (lo + hi) // 2
        if seg_i1[mid] <= k:
            lo = mid + 1
        else:
            hi = mid
    if lo < seg_i0.shape[0] and seg_i0[lo] <= k:
        return lo
    return -1


@njit(cache=True)
def propagate(t_imu, f_imu, w_imu, k, t_cur, t_to, pos, v_n, R_nb, b_a, b_g, P,
              q_a, q_g, q_ba, q_bg, seg_i0, seg_i1, seg_qa, seg_qg, phi_order, with_cov):
    """Propagate nominal state and covariance from ``t_cur`` to ``t_to`` (in place).

    Parameters
    ----------
    t_imu, f_imu, w_imu : ndarray
        IMU times [s] (N,), specific force [m/s^2] and rates [rad/s] (N, 3), body frame.
    k : int
        Index of the IMU sample whose interval ``(t[k-1], t[k]]`` contains ``t_cur``
        (i.e. the first sample with ``t[k] > t_cur``).
    t_cur, t_to : float
        Current and target time [s].
    pos, v_n, R_nb, b_a, b_g, P : ndarray
        Nominal state and covariance, updated in place.
    q_a, q_g, q_ba, q_bg : ndarray (3,)
        Noise PSDs: accel [(m/s^2)^2/s], gyro [rad^2/s], bias random walks.
    seg_i0, seg_i1 : ndarray (S,) of int
    seg_qa, seg_qg : ndarray (S, 3)
        Data-quality inflation as disjoint sample segments ``[i0, i1)`` with additive accel and
        gyro PSDs per body axis (:func:`gnssacc.quality.inflation_segments`).
    phi_order : int
        1 or 2.
    with_cov : bool
        Propagate P too.

    Returns
    -------
    k, t_cur : int, float
        Updated sample index and time (``t_cur == t_to`` unless the IMU data ended first).
    """
    n = t_imu.shape[0]
    f = np.empty(3)
    w = np.empty(3)
    A = np.empty((9, 15))
    qa_k = np.empty(3)
    qg_k = np.empty(3)
    while t_cur < t_to and k < n:
        t_end = t_imu[k] if t_imu[k] < t_to else t_to
        dt = t_end - t_cur
        if dt > 0.0:
            for i in range(3):
                f[i] = f_imu[k, i] - b_a[i]
                w[i] = w_imu[k, i] - b_g[i]
            if with_cov:
                F = system_matrix(pos, v_n, R_nb, f)
                j = _segment_index(k, seg_i0, seg_i1)
                for i in range(3):
                    qa_k[i] = q_a[i] + (seg_qa[j, i] if j >= 0 else 0.0)
                    qg_k[i] = q_g[i] + (seg_qg[j, i] if j >= 0 else 0.0)
                _propagate_cov(P, F, A, R_nb, dt, qa_k, qg_k, q_ba, q_bg, phi_order)
            strapdown_step(pos, v_n, R_nb, f, w, dt)
        t_cur = t_end
        if t_cur >= t_imu[k]:
            k += 1
    return k, t_cur


def warm_up() -> float:
    """Compile (or load from cache) the numba kernels; return the seconds it took."""
    import time

    t0 = time.perf_counter()
    t = np.array([0.0, 0.01, 0.02])
    fw = np.zeros((3, 3))
    zeros3 = np.zeros(3)
    seg_i = np.zeros(1, np.int64)
    propagate(t, fw, fw, 1, 0.0, 0.015, np.array([0.5, 0.1, 0.0]), zeros3.copy(), np.eye(3), zeros3, zeros3,
              np.eye(15), zeros3, zeros3, zeros3, zeros3, seg_i, seg_i + 1, np.zeros((1, 3)), np.zeros((1, 3)), 1,
              True)
    return time.perf_counter() - t0
