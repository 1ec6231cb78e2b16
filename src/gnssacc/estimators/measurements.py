r"""The EKF's measurement models, all of one shape: a :class:`Measurement` ``(dz, H, R)``.

Error state (estimate minus truth), order as in the paper::

    dx = [dp_n (N, E, D m), dv_n (m/s), phi (rad, n frame), b_a (m/s^2, body), b_g (rad/s, body)]

with ``R_nb_est = (I + [phi x]) R_nb``, ``f_est = f + b_a``, ``omega_est = omega + b_g``; with
time-correlated GNSS errors modelled (``gnss.gm_sigma_m > 0``) three more states follow, the
estimated Gauss-Markov part of the fix error ``x_g`` [m, NED] (estimate minus truth); with wheel
odometry, one more after them, the odometry's scale-factor error ``dk`` (estimate minus truth;
the state's place is :attr:`gnssacc.estimators.ekf.FilterState.i_scale`).
Every innovation is *predicted minus measured*, ``dz = H dx - noise``, so the closed-loop
correction subtracts ``K dz`` (:func:`gnssacc.estimators.ekf.correct`).

Models
------
``pos``
    GNSS antenna position: ``H = [I, 0, -[(R l_b) x], 0, 0 (, I)]`` (``l_b`` the lever arm; the
    fix is the antenna plus its Gauss-Markov error ``x_g`` plus white noise).
``acc``
    GNSS-derived acceleration (the paper's): ``H_a = [0, 0, -[(R f) x], R, 0]`` from
    :func:`gnssacc.estimators.gnss_accel.H_a_blocks`; or its window-consistent form (``ekf-accw``), the
    kernel-weighted INS acceleration over the fixes' window, ``H_w = [0, 0, -[(R F) x], R M, R G]``
    from :func:`gnssacc.estimators.gnss_accel.H_w_blocks`.
``zupt``
    Zero velocity while the vehicle stands still: ``dz = v_est``, ``H = [0, I, 0, 0, 0]``.
``zaru``
    Zero angular rate while it stands still: the gyro then reads the bias plus the earth rate,
    ``dz = (omega_mean - b_g_hat) - R_est^T omega_ie^n``. To first order
    ``dz = b_g - R^T [omega_ie x] phi + noise``, so ``H = [0, 0, -R^T [omega_ie x], 0, I]``.
``nhc``
    Non-holonomic constraint (:mod:`gnssacc.estimators.nhc`): the lateral and vertical
    components of the velocity of the vehicle's reference point in the body frame are zero,
    ``dz = [v_y, v_z]`` of :func:`vehicle_velocity`, ``H`` its rows 2 and 3.
``odo``
    Wheel odometry (:mod:`gnssacc.estimators.odometry`): the forward speed of the odometry's
    reference point read with a scale-factor error ``k``, ``v~ = (1 + k) v_x``;
    ``dz = (1 + k_est) v_x - v~``, ``H = [(1 + k_est) H_x, ..., v_x]`` (``H_x`` the first row of
    :func:`vehicle_velocity`'s Jacobian, ``v_x`` in the scale state's column).

The velocity of a point ``l_b`` (body) from the IMU, in the body frame, is
``v_l = R_nb^T v_n + omega_eb x l_b`` with ``omega_eb = (omega_meas - b_g_est) - R_nb^T omega_ie``.
Under the error convention above, ``R_est^T v_est = R^T v + R^T dv + R^T [v x] phi``, the
bias-corrected rate is ``omega + db_g`` and ``R_est^T omega_ie = R^T omega_ie + R^T [omega_ie x] phi``, so

    H_v = [0, R^T, R^T [v x] + [l x] R^T [omega_ie x], 0, -[l x]]   (blocks dp, dv, phi, b_a, b_g)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.earth import radii
from ..core.rotations import cross3, skew
from .gnss_accel import H_a_blocks, H_w_blocks, predicted_acceleration
from .layout import ATT, BA, BG, GNSS_ERROR, POS, VEL

#: Update kinds, in the order they are reported.
KINDS = ("pos", "acc", "zupt", "zaru", "nhc", "odo")
#: Tail probability of the chi-square bound an innovation's NIS is counted beyond (one in 1000).
TAIL_P = 1e-3
_TAIL_BOUNDS: dict = {}


def tail_bound(dof: int) -> float:
    """The NIS exceeded with probability :data:`TAIL_P` by Gaussian innovations of ``dof``."""
    if dof not in _TAIL_BOUNDS:
        from scipy.stats import chi2

        _TAIL_BOUNDS[dof] = float(chi2.isf(TAIL_P, dof))
    return _TAIL_BOUNDS[dof]


@dataclass
class Measurement:
    """One linearised measurement at the current state.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    dz : ndarray, shape (m,)
        Innovation, predicted minus measured.
    H : ndarray, shape (m, 15)
        Jacobian of the prediction w.r.t. the error state.
    R : ndarray, shape (m, m)
        Measurement noise covariance.
    gate : float
        Reject the update when its normalised innovation squared exceeds this (0: never).
    """

    kind: str
    dz: np.ndarray
    H: np.ndarray
    R: np.ndarray
    gate: float = 0.0


def position(
    s,
    lat: float,
    lon: float,
    h: float,
    sigma_ned: np.ndarray,
    lever_arm_b: np.ndarray,
    gate: float = 0.0,
    cov_ned: np.ndarray | None = None,
) -> Measurement:
    """GNSS antenna position fix (lat, lon [rad], h [m]) with 1-sigma ``sigma_ned`` [m], or with
    the full NED covariance ``cov_ned`` [m^2] (correlated axes, e.g. an RTKLIB solution's) when given."""
    R_M, R_N = radii(s.pos[0])
    l_n = s.R_nb @ lever_arm_b
    dz = (
        np.array(
            [
                (s.pos[0] - lat) * (R_M + s.pos[2]),
                (s.pos[1] - lon) * (R_N + s.pos[2]) * np.cos(s.pos[0]),
                -(s.pos[2] - h),
            ]
        )
        + l_n
    )
    H = _H(s, 3)
    H[:, POS] = np.eye(3)
    H[:, ATT] = -skew(l_n)
    if s.layout.has(GNSS_ERROR):
        dz += s.gm
        H[:, s.layout.block(GNSS_ERROR)] = np.eye(3)
    R = (
        np.diag(np.asarray(sigma_ned, float) ** 2)
        if cov_ned is None
        else np.asarray(cov_ned, float)
    )
    return Measurement("pos", dz, H, R, gate)


def _H(s, m: int) -> np.ndarray:
    """A zero Jacobian with as many columns as the filter has states."""
    return np.zeros((m, s.P.shape[0]))


def acceleration(
    s, a_n: np.ndarray, cov: np.ndarray, f_meas_b: np.ndarray, g_n: np.ndarray
) -> Measurement:
    """GNSS-derived acceleration ``a_n`` [m/s^2] (covariance ``cov``) against the INS prediction
    from the measured specific force ``f_meas_b`` [m/s^2, body] and gravity ``g_n``."""
    f_b = f_meas_b - s.b_a
    a_pred = predicted_acceleration(s.R_nb, f_b, g_n)
    d_phi, d_ba = H_a_blocks(s.R_nb, f_b)
    H = _H(s, 3)
    H[:, ATT] = d_phi
    H[:, BA] = d_ba
    return Measurement("acc", a_pred - a_n, H, cov)


def window_acceleration(
    s,
    a_n: np.ndarray,
    cov: np.ndarray,
    F_b: np.ndarray,
    M: np.ndarray,
    G: np.ndarray,
    g_n: np.ndarray,
) -> Measurement:
    """GNSS-derived acceleration ``a_n`` [m/s^2] (covariance ``cov``) against the window-consistent
    INS prediction ``R_nb F_b + g_n``, ``F_b, M, G`` the kernel integrals of
    :func:`gnssacc.estimators.mechanization.kernel_force_integrals` at the state's biases (body frame at the
    update epoch)."""
    d_phi, d_ba, d_bg = H_w_blocks(s.R_nb, F_b, M, G)
    H = _H(s, 3)
    H[:, ATT] = d_phi
    H[:, BA] = d_ba
    H[:, BG] = d_bg
    return Measurement("acc", predicted_acceleration(s.R_nb, F_b, g_n) - a_n, H, cov)


def zero_velocity(s, sigma_mps: float, gate: float = 0.0) -> Measurement:
    """The vehicle stands still: NED velocity zero within ``sigma_mps`` [m/s]."""
    H = _H(s, 3)
    H[:, VEL] = np.eye(3)
    return Measurement("zupt", s.v_n.copy(), H, np.eye(3) * sigma_mps**2, gate)


def zero_rate(
    s, omega_mean_b: np.ndarray, var_b: np.ndarray, w_ie_n: np.ndarray, gate: float = 0.0
) -> Measurement:
    """The vehicle stands still: the mean raw gyro reading ``omega_mean_b`` [rad/s] over a block
    (variance of that mean ``var_b`` [(rad/s)^2] per axis) is the bias plus the earth rate
    ``w_ie_n`` [rad/s, NED]."""
    dz = (omega_mean_b - s.b_g) - s.R_nb.T @ w_ie_n
    H = _H(s, 3)
    H[:, ATT] = -s.R_nb.T @ skew(w_ie_n)
    H[:, BG] = np.eye(3)
    return Measurement("zaru", dz, H, np.diag(var_b), gate)


def vehicle_velocity(
    s,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity of the point ``lever_b`` [m, body] from the IMU, relative to the earth, in the body
    frame [m/s], and its Jacobian ``H_v`` (3 x states) w.r.t. the error state (module docstring);
    with ``R_vb`` (body to vehicle axes, a constant), in the vehicle's axes: ``R_vb v``, ``R_vb H_v``.

    Parameters
    ----------
    s : FilterState
    omega_meas_b : ndarray (3,)
        Raw gyro reading [rad/s, body] (the state's bias is removed here).
    lever_b : ndarray (3,)
    w_ie_n : ndarray (3,)
        Earth rate [rad/s, NED].
    R_vb : ndarray (3, 3), optional
        ``None``: the body's axes.
    """
    Rt = s.R_nb.T
    u = Rt @ s.v_n
    H = _H(s, 3)
    H[:, VEL] = Rt
    # R^T [v x] = [(R^T v) x] R^T; the lever-arm terms only with a lever arm (the filter's
    # per-update cost is mostly these small products).
    if lever_b.any():
        w_ie_b = Rt @ w_ie_n
        L = skew(lever_b)
        v_b = u + cross3(omega_meas_b - s.b_g - w_ie_b, lever_b)
        H[:, ATT] = (skew(u) + L @ skew(w_ie_b)) @ Rt
        H[:, BG] = -L
    else:
        v_b = u
        H[:, ATT] = skew(u) @ Rt
    if R_vb is None:
        return v_b, H
    return R_vb @ v_b, R_vb @ H


def non_holonomic(
    s,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    sigma_mps: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> Measurement:
    """Zero lateral and vertical velocity at the vehicle's reference point ``lever_b`` [m, body],
    in the vehicle's axes (``R_vb``, see :func:`vehicle_velocity`), 1-sigma ``sigma_mps`` [m/s]
    (lateral, vertical); ``omega_meas_b`` the raw gyro [rad/s] at the epoch, ``w_ie_n`` the earth
    rate [rad/s, NED]."""
    return nhc_measurement(*vehicle_velocity(s, omega_meas_b, lever_b, w_ie_n, R_vb), sigma_mps)


def nhc_measurement(v_b: np.ndarray, H_v: np.ndarray, sigma_mps: np.ndarray) -> Measurement:
    """:func:`non_holonomic` from the vehicle velocity ``v_b`` and its Jacobian ``H_v`` of
    :func:`vehicle_velocity` (for a caller that looked at the forward speed first)."""
    return Measurement("nhc", v_b[1:3], H_v[1:3], np.diag(np.asarray(sigma_mps, float) ** 2))


def odometry(
    s,
    v_odo: float,
    sigma_mps: float,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> Measurement:
    """Wheel odometry's forward speed ``v_odo`` [m/s] (1-sigma ``sigma_mps``) of the point
    ``lever_b`` [m, body] along the vehicle's x axis (``R_vb``, see :func:`vehicle_velocity`), read
    with the scale factor of state ``s.i_scale`` (module docstring)."""
    v_b, H = vehicle_velocity(s, omega_meas_b, lever_b, w_ie_n, R_vb)
    k = 1.0 + s.scale
    H_x = H[0:1] * k
    H_x[0, s.i_scale] = v_b[0]
    return Measurement("odo", np.array([k * v_b[0] - v_odo]), H_x, np.array([[sigma_mps**2]]))
