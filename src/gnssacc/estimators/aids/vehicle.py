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

from ...core.rotations import cross3, skew
from ..layout import ATT, BG, VEL
from .base import zero_jacobian

#: How many of its own 1-sigma an estimator's speed is taken wide in the aids' decisions.
K_SIGMA = 3.0


def held_samples(imu_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the IMU sample held at each time ``t`` (sample ``k`` holds over ``(t[k-1],
    t[k]]``)."""
    return np.minimum(np.searchsorted(imu_t, t, side="left"), len(imu_t) - 1)


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
    H_v``.

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
    Rt = s.R_nb.T
    u = Rt @ s.v_n
    H = zero_jacobian(s, 3)
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
