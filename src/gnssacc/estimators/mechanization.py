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

import math

import numpy as np
from numba import njit

from ..core import earth
from ..core.memo import LastMade
from ..checks.quality import InflationSegments
from .kalman import joseph_update
from .layout import I_ATT, I_BA, I_BG, I_POS, I_VEL, N_NAV, POS, StateLayout

#: Window [s] over which the body rates are averaged into the rotation performed
#: (:func:`turn_rates`): longer than vibration's and the suspension's sway's periods, shorter than
#: a turn.
TURN_WINDOW_S = 1.0

_A, _E2, _W, _F = earth.A, earth.E2, earth.OMEGA_IE, earth.F
_GE, _K, _M = earth.GAMMA_E, earth.SOMIGLIANA_K, earth.M_RATIO


@njit(cache=True)
def radii(lat):
    """Meridian and prime-vertical radii of curvature ``R_M, R_N`` [m] at latitude ``lat`` [rad]
    (WGS-84; compiled, the same as :func:`gnssacc.core.earth.radii`)."""
    s2 = np.sin(lat) ** 2
    w = 1.0 - _E2 * s2
    return _A * (1.0 - _E2) / w**1.5, _A / np.sqrt(w)


@njit(cache=True)
def _normal_gravity(s2, r, h):
    """Normal gravity magnitude [m/s^2] and its height derivative [1/s^2] from ``s2 =
    sin^2(lat)``, ``r = sqrt(1 - e^2 s2)`` and the height ``h`` [m]."""
    g0 = _GE * (1.0 + _K * s2) / r
    c1 = 2.0 / _A * (1.0 + _F + _M - 2.0 * _F * s2)
    return g0 * (1.0 - c1 * h + 3.0 * h * h / (_A * _A)), g0 * (-c1 + 6.0 * h / (_A * _A))


@njit(cache=True)
def _gravity(lat, h):
    """Normal gravity magnitude [m/s^2] and its height derivative [1/s^2]."""
    s2 = np.sin(lat) ** 2
    return _normal_gravity(s2, np.sqrt(1.0 - _E2 * s2), h)


@njit(cache=True)
def _geodetic(lat, h):
    """``R_M, R_N`` [m], ``sin(lat)``, ``cos(lat)`` and normal gravity [m/s^2] at ``lat`` [rad],
    ``h`` [m]: :func:`radii` and :func:`_gravity` with one sine, one cosine and one root (the
    strapdown needs them at every IMU sample)."""
    s = math.sin(lat)
    s2 = s * s
    w = 1.0 - _E2 * s2
    r = math.sqrt(w)
    g = _normal_gravity(s2, r, h)[0]
    return _A * (1.0 - _E2) / (w * r), _A / r, s, math.cos(lat), g


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
def _exp_so3_into(p0, p1, p2, out):
    """``out = Exp([p x])`` by Rodrigues' formula, ``I + a K + b (p p^T - |p|^2 I)``, no
    allocation. Below ``|p|`` = 1 mrad (a sample's turn at 100 Hz, the earth's and the transport
    rate's) ``a = sin(th)/th`` and ``b = (1 - cos th)/th^2`` by their series to ``th^4``: the
    next terms are below 1e-21, and no sine, cosine or root is taken."""
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    if th2 < 1e-6:
        a = 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0)
        b = 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0)
    else:
        th = np.sqrt(th2)
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / th2
    out[0, 0] = 1.0 + b * (p0 * p0 - th2)
    out[1, 1] = 1.0 + b * (p1 * p1 - th2)
    out[2, 2] = 1.0 + b * (p2 * p2 - th2)
    out[0, 1] = -a * p2 + b * p0 * p1
    out[1, 0] = a * p2 + b * p0 * p1
    out[0, 2] = a * p1 + b * p0 * p2
    out[2, 0] = -a * p1 + b * p0 * p2
    out[1, 2] = -a * p0 + b * p1 * p2
    out[2, 1] = a * p0 + b * p1 * p2


@njit(cache=True)
def _mm3_into(A, B, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit(cache=True)
def _strapdown(pos, v_n, R_nb, f_b, omega_ib_b, dt, w_ie_sign, work):
    """:func:`strapdown_step` with a (3, 3, 3) work array: no allocation in the per-sample path."""
    lat, h = pos[0], pos[2]
    R_M, R_N, s_lat, c_lat, g = _geodetic(lat, h)
    W = _W * w_ie_sign
    wie0, wie2 = W * c_lat, -W * s_lat
    wen0, wen1 = v_n[1] / (R_N + h), -v_n[0] / (R_M + h)
    wen2 = -v_n[1] * (s_lat / c_lat) / (R_N + h)
    E_n, E_b, T = work[0], work[1], work[2]
    _exp_so3_into(-(wie0 + wen0) * dt, -wen1 * dt, -(wie2 + wen2) * dt, E_n)
    _exp_so3_into(omega_ib_b[0] * dt, omega_ib_b[1] * dt, omega_ib_b[2] * dt, E_b)
    _mm3_into(E_n, R_nb, T)
    _mm3_into(T, E_b, E_n)  # E_n now holds R_new
    # Specific force rotated by the mean of the old and new attitude.
    f0 = 0.5 * (
        (R_nb[0, 0] + E_n[0, 0]) * f_b[0]
        + (R_nb[0, 1] + E_n[0, 1]) * f_b[1]
        + (R_nb[0, 2] + E_n[0, 2]) * f_b[2]
    )
    f1 = 0.5 * (
        (R_nb[1, 0] + E_n[1, 0]) * f_b[0]
        + (R_nb[1, 1] + E_n[1, 1]) * f_b[1]
        + (R_nb[1, 2] + E_n[1, 2]) * f_b[2]
    )
    f2 = 0.5 * (
        (R_nb[2, 0] + E_n[2, 0]) * f_b[0]
        + (R_nb[2, 1] + E_n[2, 1]) * f_b[1]
        + (R_nb[2, 2] + E_n[2, 2]) * f_b[2]
    )
    # Coriolis (2 w_ie + w_en) x v.
    c0, c1, c2 = 2.0 * wie0 + wen0, wen1, 2.0 * wie2 + wen2
    vN, vE, vD = v_n[0], v_n[1], v_n[2]
    nN = vN + (f0 - (c1 * vD - c2 * vE)) * dt
    nE = vE + (f1 - (c2 * vN - c0 * vD)) * dt
    nD = vD + (f2 - (c0 * vE - c1 * vN) + g) * dt
    pos[0] += 0.5 * (vN + nN) / (R_M + h) * dt
    pos[1] += 0.5 * (vE + nE) / ((R_N + h) * math.cos(pos[0])) * dt
    pos[2] -= 0.5 * (vD + nD) * dt
    v_n[0], v_n[1], v_n[2] = nN, nE, nD
    for i in range(3):
        for j in range(3):
            R_nb[i, j] = E_n[i, j]


@njit(cache=True)
def kernel_force_integrals(f_b, omega_b, h, w, b_a, b_g):
    """Kernel-weighted specific force over an acceleration window, in the body frame at its end.

    Walks the samples backward from the window's end ``t_k``, integrating the body rotation
    ``R_{b_k b_s}`` from the bias-corrected gyro (earth rate neglected: see
    :mod:`gnssacc.estimators.aids.accel_model`), each sample taken at the midpoint of its overlap.

    Parameters
    ----------
    f_b, omega_b : ndarray (n, 3)
        The window's raw IMU samples in time order, body [m/s^2], [rad/s].
    h : ndarray (n,)
        Each sample's overlap with the window [s].
    w : ndarray (n,)
        Its kernel weight ``int K`` [-]
        (:func:`gnssacc.estimators.aids.accel_model.window_samples`).
    b_a, b_g : ndarray (3,)
        Bias estimates [m/s^2], [rad/s].

    Returns
    -------
    F : ndarray (3,)
        ``int K R_{b_k b_s} (f - b_a) ds`` [m/s^2].
    M : ndarray (3, 3)
        ``int K R_{b_k b_s} ds`` [-].
    G : ndarray (3, 3)
        ``int K [u x] Gamma ds`` [m/s], ``u = R_{b_k b_s} (f - b_a)``, ``Gamma(s) = int_s^{t_k}
        R_{b_k b_tau} d tau``: the sensitivity of ``F`` to the gyro-bias error.
    """
    F = np.zeros(3)
    M = np.zeros((3, 3))
    G = np.zeros((3, 3))
    R = np.eye(3)  # R_{b_k b(s)} at the start of the current step (walking back)
    Gam = np.zeros((3, 3))  # Gamma at that time
    E = np.empty((3, 3))
    Rm = np.empty((3, 3))
    Gm = np.empty((3, 3))
    u = np.empty(3)
    for i in range(h.shape[0] - 1, -1, -1):
        hi = h[i]
        p0, p1, p2 = omega_b[i, 0] - b_g[0], omega_b[i, 1] - b_g[1], omega_b[i, 2] - b_g[2]
        _exp_so3_into(-0.5 * hi * p0, -0.5 * hi * p1, -0.5 * hi * p2, E)
        _mm3_into(R, E, Rm)
        for r in range(3):
            for c in range(3):
                Gm[r, c] = Gam[r, c] + 0.5 * hi * Rm[r, c]
        for r in range(3):
            u[r] = (
                Rm[r, 0] * (f_b[i, 0] - b_a[0])
                + Rm[r, 1] * (f_b[i, 1] - b_a[1])
                + Rm[r, 2] * (f_b[i, 2] - b_a[2])
            )
        wi = w[i]
        for r in range(3):
            F[r] += wi * u[r]
            for c in range(3):
                M[r, c] += wi * Rm[r, c]
                # [u x] Gm, row r
                G[r, c] += wi * (
                    u[(r + 1) % 3] * Gm[(r + 2) % 3, c] - u[(r + 2) % 3] * Gm[(r + 1) % 3, c]
                )
        for r in range(3):
            for c in range(3):
                Gam[r, c] += hi * Rm[r, c]
        _exp_so3_into(-0.5 * hi * p0, -0.5 * hi * p1, -0.5 * hi * p2, E)
        _mm3_into(Rm, E, R)
    return F, M, G


@njit(cache=True)
def apply_correction(pos, v_n, R_nb, b_a, b_g, extra, dx):
    """Closed-loop feedback of an estimated error ``dx`` (estimate minus truth, order
    ``[dp, dv, phi, b_a, b_g (, x_e)]``) into the nominal state, in place.

    ``R_nb <- Exp(-phi) R_nb``; the biases are added because ``f_est = f_raw - b_a_hat`` carries
    the residual ``b_a``. ``extra`` holds the nominal values of the states after the fifteenth
    (:class:`gnssacc.estimators.ekf.FilterState`: the GNSS Gauss-Markov error, the odometry scale
    factor), corrected as ``x_e <- x_e - dx_e``.
    """
    R_M, R_N = radii(pos[0])
    pos[0] -= dx[0] / (R_M + pos[2])
    pos[1] -= dx[1] / ((R_N + pos[2]) * np.cos(pos[0]))
    pos[2] += dx[2]
    E = np.empty((3, 3))
    T = np.empty((3, 3))
    _exp_so3_into(-dx[I_ATT], -dx[I_ATT + 1], -dx[I_ATT + 2], E)
    _mm3_into(E, R_nb, T)
    for i in range(3):
        v_n[i] -= dx[I_VEL + i]
        b_a[i] += dx[I_BA + i]
        b_g[i] += dx[I_BG + i]
        for j in range(3):
            R_nb[i, j] = T[i, j]
    for i in range(dx.shape[0] - N_NAV):
        extra[i] -= dx[N_NAV + i]


@njit(cache=True)
def update_state(P, H, R, dz, gate, consider, pos, v_n, R_nb, b_a, b_g, x_e):
    """:func:`gnssacc.estimators.kalman.joseph_update`, then, when applied, its estimated error
    fed back into the nominal state (``pos, v_n, R_nb, b_a, b_g, x_e``, in place:
    :func:`apply_correction`): one call per update from Python.

    Returns
    -------
    nis, logdet, used, wz
        As :func:`joseph_update`'s.
    """
    dx, nis, logdet, used, wz = joseph_update(P, H, R, dz, gate, consider)
    if used:
        apply_correction(pos, v_n, R_nb, b_a, b_g, x_e, dx)
    return nis, logdet, used, wz


@njit(cache=True)
def strapdown_step(pos, v_n, R_nb, f_b, omega_ib_b, dt, w_ie_sign=1.0):
    """Advance the nominal state by ``dt`` [s] with a held IMU sample (in place).

    Attitude: ``R <- Exp(-omega_in dt) R Exp(omega_ib dt)`` (paper eq. 3); velocity: paper eq. 2
    with the specific force rotated by the mean of the old and new attitude; position: paper
    eq. 1 with the trapezoidal velocity. ``w_ie_sign = -1`` reverses the earth rate, which makes
    the same equations integrate a time-reversed recording exactly.
    """
    _strapdown(pos, v_n, R_nb, f_b, omega_ib_b, dt, w_ie_sign, np.empty((3, 3, 3)))


@njit(cache=True)
def system_matrix(pos, v_n, R_nb, f_b, w_ie_sign=1.0):
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
    w_ie_sign : float
        +1, or -1 for a time-reversed recording.
    """
    F = np.zeros((N_NAV, N_NAV))
    _system_matrix_into(F, pos, v_n, R_nb, f_b, w_ie_sign)
    return F


@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    """``a x b`` as three scalars (``[a x] b``)."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _system_matrix_into(F, pos, v_n, R_nb, f_b, w_ie_sign):
    """:func:`system_matrix` written into ``F``, scalar arithmetic only: the per-sample path
    allocates nothing. Every call writes the same entries, so the rest of ``F`` (zero from the
    caller) stays zero."""
    lat, h = pos[0], pos[2]
    vN, vE, vD = v_n[0], v_n[1], v_n[2]
    R_M, R_N = radii(lat)
    W = _W * w_ie_sign
    g, dg_dh = _gravity(lat, h)
    rm, rn = R_M + h, R_N + h
    tl, cl, sl = np.tan(lat), np.cos(lat), np.sin(lat)
    wie0, wie2 = W * cl, -W * sl  # earth rate, NED (east component 0)
    wen0, wen1, wen2 = vE / rn, -vN / rm, -vE * tl / rn  # transport rate
    p, v, a = I_POS, I_VEL, I_ATT  # block offsets (numba constants)
    # Position rows (metres): d(dp)/dt = F_pp dp + dv.
    F[p, p] = -vD / rm
    F[p, p + 2] = vN / rm
    F[p + 1, p] = vE * tl / rm
    F[p + 1, p + 1] = -(vD / rn + vN * tl / rm)
    F[p + 1, p + 2] = vE / rn
    for i in range(3):
        F[p + i, v + i] = 1.0
    # Sensitivities of omega_ie + omega_en (d/dlat, d/dh) and of omega_en (d/dv):
    # drho_dv has [0, 1] = 1/rn, [1, 0] = -1/rm, [2, 1] = -tl/rn.
    rho_lat2 = -vE / (rn * cl * cl)  # d(w_en_D)/dlat
    dh0, dh1, dh2 = -vE / rn**2, vN / rm**2, vE * tl / rn**2
    # Velocity rows: dv_dot = -[(2 w_ie + w_en) x] dv + [v x] d(2 w_ie + w_en) + dg - [(R f) x] phi
    # + R b_a.
    c0, c1, c2 = 2.0 * wie0 + wen0, wen1, 2.0 * wie2 + wen2
    # -[c x] + [v x] drho_dv, column by column ([v x] e_k = v x e_k).
    x0, x1, x2 = _cross(vN, vE, vD, 0.0, -1.0 / rm, 0.0)
    F[v, v], F[v + 1, v], F[v + 2, v] = x0, -c2 + x1, c1 + x2
    y0, y1, y2 = _cross(vN, vE, vD, 1.0 / rn, 0.0, -tl / rn)
    F[v, v + 1], F[v + 1, v + 1], F[v + 2, v + 1] = c2 + y0, y1, -c0 + y2
    F[v, v + 2], F[v + 1, v + 2], F[v + 2, v + 2] = -c1, c0, 0.0
    n0, n1, n2 = _cross(vN, vE, vD, 2.0 * (-W * sl), 0.0, 2.0 * (-W * cl) + rho_lat2)
    d0, d1, d2 = _cross(vN, vE, vD, dh0, dh1, dh2)
    F[v, p], F[v + 1, p], F[v + 2, p] = n0 / rm, n1 / rm, n2 / rm
    F[v, p + 2], F[v + 1, p + 2], F[v + 2, p + 2] = -d0, -d1, -d2 - dg_dh  # dp_D = -dh, g_D = g(h)
    a0 = R_nb[0, 0] * f_b[0] + R_nb[0, 1] * f_b[1] + R_nb[0, 2] * f_b[2]
    a1 = R_nb[1, 0] * f_b[0] + R_nb[1, 1] * f_b[1] + R_nb[1, 2] * f_b[2]
    a2 = R_nb[2, 0] * f_b[0] + R_nb[2, 1] * f_b[1] + R_nb[2, 2] * f_b[2]
    _neg_skew_into(F, v, a, a0, a1, a2)
    # Attitude rows: phi_dot = -[w_in x] phi - d(w_in) + R b_g.
    F[a, p], F[a + 1, p], F[a + 2, p] = W * sl / rm, 0.0, (W * cl - rho_lat2) / rm
    F[a, p + 2], F[a + 1, p + 2], F[a + 2, p + 2] = dh0, dh1, dh2
    F[a, v], F[a, v + 1], F[a, v + 2] = 0.0, -1.0 / rn, 0.0
    F[a + 1, v], F[a + 1, v + 1], F[a + 1, v + 2] = 1.0 / rm, 0.0, 0.0
    F[a + 2, v], F[a + 2, v + 1], F[a + 2, v + 2] = 0.0, tl / rn, 0.0
    _neg_skew_into(F, a, a, wie0 + wen0, wen1, wie2 + wen2)
    for i in range(3):
        for j in range(3):
            F[v + i, I_BA + j] = R_nb[i, j]
            F[a + i, I_BG + j] = R_nb[i, j]


@njit(cache=True)
def _neg_skew_into(F, r, c, a0, a1, a2):
    """``F[r:r+3, c:c+3] = -[a x]``."""
    F[r, c], F[r, c + 1], F[r, c + 2] = 0.0, a2, -a1
    F[r + 1, c], F[r + 1, c + 1], F[r + 1, c + 2] = -a2, 0.0, a0
    F[r + 2, c], F[r + 2, c + 1], F[r + 2, c + 2] = a1, -a0, 0.0


# Column ranges of the non-zero entries of F, per block row (the bias rows of F are zero).
_NZ_P = (I_POS, I_ATT)  # position rows: dp, dv
_NZ_V = (I_POS, I_BG)  # velocity rows: dp, dv, phi, b_a
#: Rows of F that are not zero: position, velocity, attitude.
_N_MOVING = I_BA


@njit(cache=True)
def _propagate_cov(P, F, A, R_nb, dt, q_a, q_g, q_ba, q_bg, phi_order):
    """P <- Phi P Phi^T + Q with Phi = I + F dt (+ (F dt)^2 / 2) and Q = G Qc G^T dt.

    For the first-order case ``Phi P Phi^T = P + dt (F P + P F^T) + dt^2 F P F^T`` is evaluated
    with F's sparsity (only the position, velocity and attitude rows are non-zero), about 4x fewer
    operations than dense. ``A`` is a (9, 15) work array. Only the navigation block of ``P`` is
    touched, so ``P`` may carry more states (passing the whole array, not a view, keeps one
    compiled version of this kernel).
    """
    n = N_NAV
    if phi_order == 2:
        Phi = _transition(F, dt, phi_order)
        Pn = np.empty((n, n))
        PhiT = np.empty((n, n))
        for i in range(n):
            for j in range(n):
                Pn[i, j] = P[i, j]
                PhiT[i, j] = Phi[j, i]
        Pn = _mm(_mm(Phi, Pn), PhiT)
        for i in range(n):
            for j in range(n):
                P[i, j] = Pn[i, j]
    else:
        # A = F P over the non-zero columns of each row of F.
        for i in range(_N_MOVING):
            for j in range(n):
                acc = 0.0
                if i < I_VEL:
                    for k in range(_NZ_P[0], _NZ_P[1]):
                        acc += F[i, k] * P[k, j]
                elif i < I_ATT:
                    for k in range(_NZ_V[0], _NZ_V[1]):
                        acc += F[i, k] * P[k, j]
                else:
                    for k in range(I_BA):
                        acc += F[i, k] * P[k, j]
                    for k in range(I_BG, I_BG + 3):
                        acc += F[i, k] * P[k, j]
                A[i, j] = acc
        dt2 = dt * dt
        for i in range(_N_MOVING):
            for j in range(i, n):
                if j < _N_MOVING:
                    # (F P F^T)[i, j] = sum_k A[i, k] F[j, k]
                    fpf = 0.0
                    for k in range(n):
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
            P[I_VEL + i, I_VEL + j] += sa * dt
            P[I_ATT + i, I_ATT + j] += sg * dt
        P[I_BA + i, I_BA + i] += q_ba[i] * dt
        P[I_BG + i, I_BG + i] += q_bg[i] * dt


@njit(cache=True)
def _propagate_gm(P, F, dt, gm_tau, gm_var):
    """The first-order Gauss-Markov states after the navigation states (:class:`gnssacc.estimators.
    layout.StateLayout`: the GNSS fix error, the odometry scale factor), ``x' = a x + w``,
    ``a = exp(-dt / tau)``, stationary variance ``gm_var`` (``gm_tau``, ``gm_var``: one entry per
    such state). Their cross-covariance with the navigation states follows
    ``P_xg' = (I + F dt) P_xg a``; nothing couples them in F."""
    n, m = P.shape[0], N_NAV
    for c in range(m, n):
        a = np.exp(-dt / gm_tau[c - m])
        col = np.empty(m)
        for i in range(m):
            v = P[i, c]
            if i < _N_MOVING:
                for k in range(m):
                    v += dt * F[i, k] * P[k, c]
            col[i] = a * v
        for i in range(m):
            P[i, c] = col[i]
            P[c, i] = col[i]
        for d in range(m, n):
            P[c, d] *= a * np.exp(-dt / gm_tau[d - m])
        P[c, c] += gm_var[c - m] * (1.0 - a * a)
    for c in range(m, n):
        for d in range(c + 1, n):
            P[d, c] = P[c, d]


@njit(cache=True)
def _propagate_all(P, F, A, R_nb, dt, q_a, q_g, q_ba, q_bg, phi_order, gm_tau, gm_var):
    """The navigation states, then the Gauss-Markov states when P has them."""
    if P.shape[0] > N_NAV:
        _propagate_gm(P, F, dt, gm_tau, gm_var)  # needs only P_xg and F: order-independent
    _propagate_cov(P, F, A, R_nb, dt, q_a, q_g, q_ba, q_bg, phi_order)


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
def _transition(F, dt, phi_order):
    """``I + F dt (+ (F dt)^2 / 2)``, the error-state transition over one step. Explicit loops:
    numba's array expressions (``F * dt``) cost seconds of compilation each."""
    S = np.empty((N_NAV, N_NAV))
    for i in range(N_NAV):
        for j in range(N_NAV):
            S[i, j] = F[i, j] * dt
    if phi_order == 2:
        S2 = _mm(S, S)
        for i in range(N_NAV):
            for j in range(N_NAV):
                S[i, j] = S[i, j] + 0.5 * S2[i, j]
    for i in range(N_NAV):
        S[i, i] += 1.0
    return S


@njit(cache=True)
def _step_phi(Phi, F, dt, phi_order):
    """Phi <- (I + F dt (+ (F dt)^2 / 2)) Phi: the error-state transition over one step."""
    C = _mm(_transition(F, dt, phi_order), Phi)
    for i in range(N_NAV):
        for j in range(N_NAV):
            Phi[i, j] = C[i, j]


@njit(cache=True)
def propagate(
    t_imu,
    f_imu,
    w_imu,
    k,
    t_cur,
    t_to,
    pos,
    v_n,
    R_nb,
    b_a,
    b_g,
    P,
    q_a,
    q_g,
    q_ba,
    q_bg,
    seg_i0,
    seg_i1,
    seg_qa,
    seg_qg,
    phi_order,
    with_cov,
    cov_every,
    Phi,
    with_phi,
    w_ie_sign,
    gm_tau,
    gm_var,
    q_turn,
    w_turn,
    rest,
    rest_R,
):
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
        gyro PSDs per body axis (:func:`gnssacc.checks.quality.inflation_segments`).
    phi_order : int
        1 or 2.
    with_cov : bool
        Propagate P too.
    cov_every : int
        Propagate P once every this many IMU samples (and always at ``t_to``) with the summed
        interval and noise; 1 (the default everywhere but the noise tuner) is every sample.
    Phi : ndarray (15, 15)
        Transition-matrix accumulator, ``Phi <- Phi_step Phi`` per sample when ``with_phi``
        (for the observability analysis; needs ``cov_every == 1``).
    with_phi : bool
    w_ie_sign : float
        +1, or -1 to integrate a time-reversed recording (the earth then turns the other way).
    gm_tau, gm_var : ndarray (n - 15,)
        Correlation time [s] and stationary variance of the first-order Gauss-Markov states
        after the fifteenth, when P has them (n x n): the GNSS error [m^2], the odometry scale
        factor [-].
    q_turn : float
        Gyro PSD per unit rotation rate [rad^2/s per rad/s]: ``q_turn |w_turn - b_g|`` is added to
        each body axis's gyro PSD (:attr:`gnssacc.estimators.settings.ImuNoise.gyro_turn_psd`).
    w_turn : ndarray (N, 3)
        The rotation the body performs: each sample's rate averaged over
        :data:`TURN_WINDOW_S` [rad/s, body] (:func:`turn_rates`).
    rest : ndarray (N,) or (0,) of bool
        Samples at rest (in a stationary span; empty: none). There the error model ``F`` is
        linearised about what a vehicle at rest has and the updates cannot change: the specific
        force ``f^n = -g^n`` (no horizontal part) and the attitude of the first sample at rest
        (``rest_R``), instead of the sample's specific force (whose horizontal part at rest is
        vibration, noise and the filter's own tilt-bias error) and the attitude of the moment
        (which the updates move). With either, the directions a still IMU cannot observe (tilt
        against horizontal accelerometer bias, yaw against gyro bias) turn from sample to sample
        and the updates "measure" them; held, they stay unobservable (the first-estimates
        Jacobian of an observability-consistent filter). The nominal state always integrates
        ``f_imu``.
    rest_R : ndarray (4, 3)
        The attitude held at rest (rows 0-2, ``R_nb``) and, in ``rest_R[3, 0]``, 1 once it is
        held (the pass's first sample at rest sets it): carried from one call to the next
        (:class:`Propagator` keeps it, one per pass).

    Returns
    -------
    k, t_cur : int, float
        Updated sample index and time (``t_cur == t_to`` unless the IMU data ended first).
    """
    n = t_imu.shape[0]
    if with_phi and P.shape[0] > N_NAV:
        with_phi = False  # the transition-matrix accumulator covers the 15 navigation states only
    f = np.empty(3)
    fl = np.empty(3)  # the force the error model takes at rest (else the sample's own, f)
    at_rest = False
    w = np.empty(3)
    A = np.empty((_N_MOVING, N_NAV))
    F = np.zeros((N_NAV, N_NAV))
    work = np.empty((3, 3, 3))
    qa_k = np.empty(3)
    qg_k = np.empty(3)
    qa_int = np.zeros(3)
    qg_int = np.zeros(3)
    dt_acc = 0.0
    count = 0
    while t_cur < t_to and k < n:
        t_end = t_imu[k] if t_imu[k] < t_to else t_to
        dt = t_end - t_cur
        if dt > 0.0:
            for i in range(3):
                f[i] = f_imu[k, i] - b_a[i]
                w[i] = w_imu[k, i] - b_g[i]
            at_rest = k < rest.shape[0] and rest[k]
            if at_rest:
                if rest_R[3, 0] == 0.0:  # the pass's first sample at rest: hold its attitude
                    for i in range(3):
                        for j in range(3):
                            rest_R[i, j] = R_nb[i, j]
                    rest_R[3, 0] = 1.0
                g = _gravity(pos[0], pos[2])[0]
                for i in range(3):
                    fl[i] = -g * rest_R[2, i]  # R^T (0, 0, -g)
            if with_cov:
                j = _segment_index(k, seg_i0, seg_i1)
                q_w = 0.0
                if q_turn > 0.0:
                    r2 = 0.0
                    for i in range(3):
                        r2 += (w_turn[k, i] - b_g[i]) ** 2
                    q_w = q_turn * math.sqrt(r2)
                for i in range(3):
                    qa_int[i] += (q_a[i] + (seg_qa[j, i] if j >= 0 else 0.0)) * dt
                    qg_int[i] += (q_g[i] + q_w + (seg_qg[j, i] if j >= 0 else 0.0)) * dt
                dt_acc += dt
                count += 1
                if count >= cov_every or t_end >= t_to:
                    _cov_step(
                        P,
                        F,
                        A,
                        Phi,
                        with_phi,
                        pos,
                        v_n,
                        rest_R[:3] if at_rest else R_nb,
                        fl if at_rest else f,
                        w_ie_sign,
                        qa_int,
                        qg_int,
                        qa_k,
                        qg_k,
                        dt_acc,
                        q_ba,
                        q_bg,
                        phi_order,
                        gm_tau,
                        gm_var,
                    )
                    dt_acc = 0.0
                    count = 0
            _strapdown(pos, v_n, R_nb, f, w, dt, w_ie_sign, work)
        t_cur = t_end
        if t_cur >= t_imu[k]:
            k += 1
    if with_cov and count > 0:  # the IMU data ended before t_to: flush what was accumulated
        _cov_step(
            P,
            F,
            A,
            Phi,
            with_phi,
            pos,
            v_n,
            rest_R[:3] if at_rest else R_nb,
            fl if at_rest else f,
            w_ie_sign,
            qa_int,
            qg_int,
            qa_k,
            qg_k,
            dt_acc,
            q_ba,
            q_bg,
            phi_order,
            gm_tau,
            gm_var,
        )
    return k, t_cur


@njit(cache=True)
def _cov_step(
    P,
    F,
    A,
    Phi,
    with_phi,
    pos,
    v_n,
    R_nb,
    f,
    w_ie_sign,
    qa_int,
    qg_int,
    qa_k,
    qg_k,
    dt_acc,
    q_ba,
    q_bg,
    phi_order,
    gm_tau,
    gm_var,
):
    """One covariance (and transition-matrix) step over ``dt_acc`` [s] with the noise integrated
    over it (``qa_int``, ``qg_int``: PSD x time, reset to zero here; ``qa_k``, ``qg_k``:
    scratch)."""
    _system_matrix_into(F, pos, v_n, R_nb, f, w_ie_sign)
    for i in range(3):
        qa_k[i] = qa_int[i] / dt_acc
        qg_k[i] = qg_int[i] / dt_acc
        qa_int[i] = 0.0
        qg_int[i] = 0.0
    _propagate_all(P, F, A, R_nb, dt_acc, qa_k, qg_k, q_ba, q_bg, phi_order, gm_tau, gm_var)
    if with_phi:
        _step_phi(Phi, F, dt_acc, phi_order)


#: The last :func:`turn_rates` computed, from ``t`` and ``omega_b`` (by identity), their
#: fingerprint and the window, one per run (a windowed tuning passes over the whole run and
#: its windows' stretches in turn). The tuner's ~90 passes over one run share it: computed
#: afresh it cost 90 ms a pass on a 2,400 s run.
_LAST_TURN_RATES = LastMade(slots=8)


def _is_float64(x) -> bool:
    return isinstance(x, np.ndarray) and x.dtype == np.float64


def turn_rates(t: np.ndarray, omega_b: np.ndarray, window_s: float = TURN_WINDOW_S) -> np.ndarray:
    """The rotation the body performs: each sample's rate averaged over the samples within
    ``window_s / 2`` of it [rad/s, body], (N, 3), C-contiguous (not to be written to: the same
    array is returned again for the same ``t`` and ``omega_b`` objects, unchanged).

    A constant gyro cross-axis or scale-factor error grows an attitude error with the angle turned;
    vibration and the sensor's own noise turn the body back and forth, and the error they make
    averages out. ``t`` [s] (N,), ``omega_b`` [rad/s] (N, 3).
    """
    # np.asarray of a view makes a new view each call: the arrays themselves, when they are ones
    t, omega_b = (x if _is_float64(x) else np.asarray(x, float) for x in (t, omega_b))
    mark = (len(t), float(t[0]), float(t[-1]), float(omega_b.sum())) if len(t) else None
    rates = _LAST_TURN_RATES.get((t, omega_b), (mark, window_s))
    if rates is not None:
        return rates
    c = np.vstack([np.zeros(3), np.cumsum(omega_b, axis=0)])
    lo = np.searchsorted(t, t - 0.5 * window_s, side="left")
    hi = np.searchsorted(t, t + 0.5 * window_s, side="right")
    rates = np.ascontiguousarray((c[hi] - c[lo]) / (hi - lo)[:, None])
    return _LAST_TURN_RATES.keep((t, omega_b), (mark, window_s), rates)


def kernel_array(x, dtype) -> np.ndarray:
    """``x`` as the kernels take it: C-contiguous and writable. numba compiles a separate version
    of a kernel for read-only arrays (a broadcast, a memory map), which would cost a second full
    compilation; the IMU arrays are copied only when they are read-only or not contiguous. An
    array that already is what the kernels take is returned itself (not a new view of it: the
    cache of :func:`turn_rates` recognises the IMU arrays of a run by their identity)."""
    if (
        isinstance(x, np.ndarray)
        and x.dtype == dtype
        and x.flags.c_contiguous
        and x.flags.writeable
    ):
        return x
    a = np.ascontiguousarray(x, dtype)
    return a if a.flags.writeable else a.copy()


class Propagator:
    """The IMU samples and the noise model, bound once; :meth:`advance` moves a state in time.

    Parameters
    ----------
    t, f_b, omega_ib_b : ndarray
        IMU times [s] (N,), specific force [m/s^2] and angular rate [rad/s] (N, 3), body frame.
    q_a, q_g, q_ba, q_bg : ndarray (3,)
        White-noise and bias random-walk PSDs (see :func:`propagate`).
    segments : gnssacc.checks.quality.InflationSegments
        The extra noise over suspect IMU spans (:func:`gnssacc.checks.quality.inflation_segments`).
    phi_order : int
        1 or 2.
    cov_every : int
        Covariance propagated every this many samples (1: every sample).
    w_ie_sign : float
        +1, or -1 for a time-reversed recording.
    layout : gnssacc.estimators.layout.StateLayout, optional
        The states the filter carries: the Gauss-Markov ones after the navigation states are
        propagated with their correlation times and variances (default: none).
    q_turn : float
        Gyro PSD per unit rotation rate [rad^2/s per rad/s] (see :func:`propagate`; default 0).
    rest : ndarray (N,) of bool, optional
        The samples at rest (see :func:`propagate`; default: none).
    """

    def __init__(
        self,
        t,
        f_b,
        omega_ib_b,
        q_a,
        q_g,
        q_ba,
        q_bg,
        segments: InflationSegments,
        phi_order: int = 1,
        cov_every: int = 1,
        w_ie_sign: float = 1.0,
        layout: StateLayout | None = None,
        q_turn: float = 0.0,
        rest=None,
    ):
        self.t, self.f, self.w = (kernel_array(x, float) for x in (t, f_b, omega_ib_b))
        #: The samples at rest, about whose specific force the error model is linearised (see
        #: :func:`propagate`); empty: none.
        self.rest = np.zeros(0, bool) if rest is None else np.ascontiguousarray(rest, bool)
        #: The attitude held at rest and whether it is held (see :func:`propagate`).
        self.rest_R = np.zeros((4, 3))
        self.q = tuple(np.array(q, float) for q in (q_a, q_g, q_ba, q_bg))
        self.q_turn = float(q_turn)
        self.w_turn = turn_rates(self.t, self.w) if self.q_turn > 0.0 else np.zeros((1, 3))
        segments = InflationSegments._make(segments)
        # In the kernel's argument order: sample ranges, accelerometer, gyro.
        self.segments = (
            np.array(segments.i0, np.int64),
            np.array(segments.i1, np.int64),
            np.array(segments.q_accel, float).reshape(-1, 3),
            np.array(segments.q_gyro, float).reshape(-1, 3),
        )
        self.phi_order, self.cov_every, self.w_ie_sign = (
            int(phi_order),
            max(int(cov_every), 1),
            float(w_ie_sign),
        )
        layout = layout or StateLayout()
        #: Correlation times and variances of the states after the navigation ones, in order.
        self.extra_tau, self.extra_var = layout.markov_tau, layout.markov_var
        #: Transition-matrix accumulator (used when ``with_phi``); reset it with :meth:`reset_phi`.
        self.Phi = np.eye(N_NAV)
        self.with_phi = False

    def reset_phi(self) -> None:
        self.Phi[:, :] = np.eye(N_NAV)

    def advance(
        self, s, k: int, t_cur: float, t_to: float, with_cov: bool = True
    ) -> tuple[int, float]:
        """Propagate the state ``s`` (``pos, v_n, R_nb, b_a, b_g, P``, in place) to ``t_to``.

        ``k`` is the first sample with ``t[k] > t_cur``; returns the updated ``k, t_cur``.
        """
        seg_i0, seg_i1, seg_qa, seg_qg = self.segments
        return propagate(
            self.t,
            self.f,
            self.w,
            k,
            t_cur,
            t_to,
            s.pos,
            s.v_n,
            s.R_nb,
            s.b_a,
            s.b_g,
            s.P,
            *self.q,
            seg_i0,
            seg_i1,
            seg_qa,
            seg_qg,
            self.phi_order,
            with_cov,
            self.cov_every,
            self.Phi,
            self.with_phi,
            self.w_ie_sign,
            self.extra_tau,
            self.extra_var,
            self.q_turn,
            self.w_turn,
            self.rest,
            self.rest_R,
        )


def warm_up(propagation: bool = True, update: bool = True) -> float:
    """Compile (or load from cache) the numba kernels of an EKF run: ``propagation``, and
    ``update`` (the update and the correction); return the seconds it took. See
    :mod:`gnssacc.estimators.kernels` for the background version."""
    import time
    from types import SimpleNamespace

    t0 = time.perf_counter()
    z3 = np.zeros(3)
    s = SimpleNamespace(
        pos=np.array([0.5, 0.1, 0.0]),
        v_n=z3.copy(),
        R_nb=np.eye(3),
        b_a=z3.copy(),
        b_g=z3.copy(),
        P=np.eye(N_NAV),
    )
    if propagation:
        seg_i = np.zeros(1, np.int64)
        prop = Propagator(
            np.array([0.0, 0.01, 0.02]),
            np.zeros((3, 3)),
            np.zeros((3, 3)),
            z3,
            z3,
            z3,
            z3,
            InflationSegments(seg_i, seg_i + 1, np.zeros((1, 3)), np.zeros((1, 3))),
        )
        prop.advance(s, 1, 0.0, 0.015)
    if update:
        H = np.zeros((3, N_NAV))
        H[:, POS] = np.eye(3)
        # ``consider`` passed as the EKF passes it (an omitted default is another signature).
        dx = joseph_update(s.P, H, np.eye(3), np.ones(3), 0.0, -1)[0]
        apply_correction(s.pos, s.v_n, s.R_nb, s.b_a, s.b_g, np.zeros(0), dx)
    return time.perf_counter() - t0


@njit(cache=True)
def half_interval_rotations(omega_b, dt):
    """``Exp(omega dt / 2)`` per sample (n, 3, 3): the rotation of the body over the first half of
    each sample's interval, with the rate ``omega_b`` [rad/s] (n, 3) held over ``dt`` [s] (n,).

    The arithmetic of ``scipy.spatial.transform.Rotation.from_rotvec(0.5 * omega_b * dt[:, None])
    .as_matrix()``, operation for operation (through the unit quaternion, a Taylor series of its
    scale below 1e-3 rad), so that the preintegration's numbers did not change when it replaced
    that call (a tenth of its cost)."""
    n = omega_b.shape[0]
    out = np.empty((n, 3, 3))
    for i in range(n):
        rx = 0.5 * omega_b[i, 0] * dt[i]
        ry = 0.5 * omega_b[i, 1] * dt[i]
        rz = 0.5 * omega_b[i, 2] * dt[i]
        angle = math.sqrt(rx * rx + ry * ry + rz * rz)
        if angle <= 1e-3:
            angle2 = angle * angle
            scale = 0.5 - angle2 / 48.0 + angle2 * angle2 / 3840.0
        else:
            scale = math.sin(angle / 2.0) / angle
        x, y, z, w = scale * rx, scale * ry, scale * rz, math.cos(angle / 2.0)
        x2, y2, z2, w2 = x * x, y * y, z * z, w * w
        xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
        m = out[i]
        m[0, 0] = x2 - y2 - z2 + w2
        m[1, 0] = 2.0 * (xy + zw)
        m[2, 0] = 2.0 * (xz - yw)
        m[0, 1] = 2.0 * (xy - zw)
        m[1, 1] = -x2 + y2 - z2 + w2
        m[2, 1] = 2.0 * (yz + xw)
        m[0, 2] = 2.0 * (xz + yw)
        m[1, 2] = 2.0 * (yz - xw)
        m[2, 2] = -x2 - y2 + z2 + w2
    return out


def warm_up_intervals() -> float:
    """Compile (or load) :func:`half_interval_rotations` (the smoothers' preintegration); return
    the seconds it took."""
    import time

    t0 = time.perf_counter()
    half_interval_rotations(np.zeros((2, 3)), np.full(2, 0.01))
    return time.perf_counter() - t0


def warm_up_window() -> float:
    """Compile (or load) the window-consistent acceleration update's kernel
    (:func:`kernel_force_integrals`); return the seconds it took."""
    import time

    t0 = time.perf_counter()
    n = 4
    kernel_force_integrals(
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.full(n, 0.01),
        np.full(n, 0.25),
        np.zeros(3),
        np.zeros(3),
    )
    return time.perf_counter() - t0
