r"""The velocity of a point of the vehicle: the model both ground-vehicle aids share (the
non-holonomic constraint, :mod:`gnssacc.estimators.aids.nhc`; wheel odometry,
:mod:`gnssacc.estimators.aids.odometry`).

The velocity of a point ``l_b`` (body) from the IMU, relative to the earth, in the body frame, is
``v_l = R_nb^T v_n + omega_eb x l_b`` with ``omega_eb = (omega_meas - b_g_est) - R_nb^T omega_ie``.
Under the error convention of :mod:`gnssacc.estimators.aids.base`,
``R_est^T v_est = R^T v + R^T dv + R^T [v x] phi``, the bias-corrected rate is ``omega + db_g`` and
``R_est^T omega_ie = R^T omega_ie + R^T [omega_ie x] phi``, so

    H_v = [0, R^T, R^T [v x] + [l x] R^T [omega_ie x], 0, -[l x]]   (blocks dp, dv, phi, b_a, b_g)

The smoother's factors use the same model on GTSAM's variables
(:func:`gnssacc.factors.vehicle_velocity`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..layout import I_ATT, I_BG, I_VEL
from ..small_linalg import matmul_into, matvec, rows_contiguous, skew_into

#: How many of its own 1-sigma an estimator's speed is taken wide in the aids' decisions.
K_SIGMA = 3.0
_IDENTITY = np.eye(3)


def held_samples(imu_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the IMU sample held at each time ``t`` (sample ``k`` holds over ``(t[k-1],
    t[k]]``)."""
    return np.minimum(np.searchsorted(imu_t, t, side="left"), len(imu_t) - 1)


@njit(cache=True)
def vehicle_model(R_nb, v_n, b_g, omega_meas_b, lever_b, w_ie_n, R_vb, vb_rows, n):
    """:func:`vehicle_velocity` compiled (the per-update path of both ground-vehicle aids), with
    numpy's arithmetic (:mod:`gnssacc.estimators.small_linalg`): the state's ``R_nb``, ``v_n``
    [m/s, NED], ``b_g`` [rad/s], ``n`` states; ``R_vb`` (3, 3, C order) the body to vehicle axes
    (the identity: the body's own, applied all the same), ``vb_rows`` whether the caller's
    ``R_vb`` was in C order (numpy sums otherwise: :mod:`gnssacc.estimators.small_linalg`)."""
    Rt = R_nb.T
    u = matvec(Rt, v_n, False)
    H = np.zeros((3, n))
    for r in range(3):
        for c in range(3):
            H[r, I_VEL + c] = Rt[r, c]
    S, L = np.empty((3, 3)), np.empty((3, 3))
    skew_into(u, S)
    v_b = u.copy()
    if lever_b[0] != 0.0 or lever_b[1] != 0.0 or lever_b[2] != 0.0:
        w_ie_b = matvec(Rt, w_ie_n, False)
        w = omega_meas_b - b_g - w_ie_b
        v_b[0] += w[1] * lever_b[2] - w[2] * lever_b[1]
        v_b[1] += w[2] * lever_b[0] - w[0] * lever_b[2]
        v_b[2] += w[0] * lever_b[1] - w[1] * lever_b[0]
        W, LW = np.empty((3, 3)), np.empty((3, 3))
        skew_into(lever_b, L)
        skew_into(w_ie_b, W)
        matmul_into(L, W, LW, 0)
        S += LW
        for r in range(3):
            for c in range(3):
                H[r, I_BG + c] = -L[r, c]
    matmul_into(S, Rt, H, I_ATT)
    out_H = np.empty((3, n))
    matmul_into(R_vb, H, out_H, 0)
    return matvec(R_vb, v_b, vb_rows), out_H


def vehicle_velocity(
    s,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity of the point ``lever_b`` [m, body] from the IMU, relative to the earth, in the body
    frame [m/s], and its Jacobian ``H_v`` (3 x states) w.r.t. the error state (module notes);
    with ``R_vb`` (body to vehicle axes, a constant), in the vehicle's axes: ``R_vb v``, ``R_vb
    H_v`` (the model is :func:`vehicle_model`).

    Parameters
    ----------
    s : gnssacc.estimators.state.FilterState
    omega_meas_b : ndarray (3,)
        Raw gyro reading [rad/s, body] (the state's bias is removed here).
    lever_b : ndarray (3,)
    w_ie_n : ndarray (3,)
        Earth rate [rad/s, NED].
    R_vb : ndarray (3, 3), optional
        ``None``: the body's axes.
    """
    R, rows = vehicle_axes(R_vb)
    return vehicle_model(s.R_nb, s.v_n, s.b_g, omega_meas_b, lever_b, w_ie_n, R, rows, s.P.shape[0])


def vehicle_axes(R_vb: np.ndarray | None) -> tuple[np.ndarray, bool]:
    """:func:`vehicle_model`'s ``R_vb`` (C order: one compiled version for either order; the
    identity for ``None``) and ``vb_rows`` for the body to vehicle axes ``R_vb``."""
    R = _IDENTITY if R_vb is None else R_vb
    rows = rows_contiguous(R)
    return (R if rows else np.ascontiguousarray(R)), rows
