r"""GNSS (Doppler) velocity factors: the antenna's velocity at a node (on its X, V, B), and
one between two nodes carried from the earlier node by the preintegrated IMU
(``gtsam.CustomFactor``\ s).

Error (NED, m/s, on the measured axes ``S`` only)::

    e = S (v + R (w x l_b) - omega_ie^n x (R l_b) - v~),    w = omega~ - b_g

with ``omega~`` the raw gyro held at the velocity's time, ``b_g`` the gyro half of the node's bias
and ``l_b`` the antenna's lever arm (:mod:`gnssacc.estimators.aids.gnss_velocity`). GTSAM perturbs
the pose on the right (``R = R_hat Exp(xi)``), the velocity and the bias additively; with
``a_b = w x l_b``::

    de/dxi   = S (-R [a_b x] + [omega_ie x] R [l_b x])
    de/dv    = S
    de/db_g  = S R [l_b x]

(translation and accelerometer-bias columns zero). Without a lever arm the factor is on V alone.

Between nodes (:func:`preintegrated_velocity_factor`), ``(R_f, p_f, v_f) = pim.predict((R_i, p_i,
v_i), b_i)`` as in :mod:`.preintegrated_position_factor`; on the predicted state's NavState tangent
(rotation, position, body-frame velocity increments) ``D = S [de/dxi, 0, R_f]``, so the node's
Jacobians are ``(D J_s)`` on the pose, ``(D J_s)_v R_i^T`` on the velocity and ``D J_b`` plus the
direct ``S R_f [l_b x]`` on the gyro bias. Its noise adds the preintegration's velocity and
rotation covariance through ``D`` (``R_f`` at the estimate the factor is made at).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import cross3, skew
from gnssacc.estimators.layout import B_GYRO, NAVSTATE, NAVSTATE_POSE, NAVSTATE_VEL, X_ROT


def velocity_error_jacobians(
    R: np.ndarray, w_b: np.ndarray, lever_b: np.ndarray, w_ie_n: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lever-arm term ``R (w x l) - omega_ie x (R l)`` [m/s, NED] and its Jacobians on the
    rotation tangent ``xi`` and the gyro bias (3 x 3 each; module notes)."""
    L = skew(lever_b)
    a_b = cross3(w_b, lever_b)
    term = R @ a_b - cross3(w_ie_n, R @ lever_b)
    return term, -R @ skew(a_b) + skew(w_ie_n) @ R @ L, R @ L


def _noise(cov: np.ndarray, axes: np.ndarray):
    c = np.asarray(cov, float)[np.ix_(axes, axes)]
    if np.count_nonzero(c - np.diag(np.diag(c))) == 0:
        return gtsam.noiseModel.Diagonal.Variances(np.diag(c).copy())
    return gtsam.noiseModel.Gaussian.Covariance(c)


def gnss_velocity_factor(
    keys: tuple,
    v_meas: np.ndarray,
    axes: np.ndarray,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    cov: np.ndarray,
) -> gtsam.CustomFactor:
    """The velocity ``v_meas`` [m/s, NED] on the measured ``axes`` (boolean (3,)) with covariance
    ``cov`` [m^2/s^2] (3 x 3) of the antenna at ``lever_b`` [m, body] of the node ``keys = (X, V,
    B)``; ``omega_b`` the raw gyro at the node [rad/s], ``w_ie_n`` the earth rate [rad/s, NED]."""
    axes = np.asarray(axes, bool).copy()
    v_meas, omega_b, lever_b, w_ie_n = (
        np.asarray(a, float).copy() for a in (v_meas, omega_b, lever_b, w_ie_n)
    )
    noise = _noise(cov, axes)
    S = np.eye(3)[axes]
    if not lever_b.any():
        vkey = int(keys[1])

        def plain(this, values: gtsam.Values, H: list | None) -> np.ndarray:
            if H is not None:
                H[0] = S
            return (values.atVector(vkey) - v_meas)[axes]

        return gtsam.CustomFactor(noise, [vkey], plain)
    keys = [int(k) for k in keys]
    J_pose, J_bias = np.zeros((3, 6)), np.zeros((3, 6))

    def error(this, values: gtsam.Values, H: list | None) -> np.ndarray:
        R = values.atPose3(keys[0]).rotation().matrix()
        w_b = omega_b - values.atConstantBias(keys[2]).gyroscope()
        term, d_xi, d_bg = velocity_error_jacobians(R, w_b, lever_b, w_ie_n)
        if H is not None:
            J_pose[:, X_ROT], J_bias[:, B_GYRO] = d_xi, d_bg
            H[0], H[1], H[2] = J_pose[axes], S, J_bias[axes]
        return (values.atVector(keys[1]) + term - v_meas)[axes]

    return gtsam.CustomFactor(noise, keys, error)


def preintegrated_velocity_factor(
    keys: tuple,
    pim: gtsam.PreintegratedCombinedMeasurements,
    v_meas: np.ndarray,
    axes: np.ndarray,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    cov: np.ndarray,
    R_f: np.ndarray,
) -> gtsam.CustomFactor:
    """A velocity between two nodes on the earlier node ``keys = (X_i, V_i, B_i)``, through the IMU
    ``pim`` preintegrated from the node to the velocity's time (module notes); the other
    arguments as for :func:`gnss_velocity_factor`, ``R_f`` the attitude predicted at the
    velocity's time (for the preintegration's noise)."""
    axes = np.asarray(axes, bool).copy()
    v_meas, omega_b, lever_b, w_ie_n = (
        np.asarray(a, float).copy() for a in (v_meas, omega_b, lever_b, w_ie_n)
    )
    keys = [int(k) for k in keys]
    J_s, J_b, D = np.zeros((9, 9), order="F"), np.zeros((9, 6), order="F"), np.zeros((3, 9))

    def error(this, values: gtsam.Values, H: list | None) -> np.ndarray:
        pose = values.atPose3(keys[0])
        bias = values.atConstantBias(keys[2])
        state = gtsam.NavState(pose, values.atVector(keys[1]))
        pred = pim.predict(state, bias, J_s, J_b) if H is not None else pim.predict(state, bias)
        R = pred.attitude().matrix()
        term, d_xi, d_bg = velocity_error_jacobians(R, omega_b - bias.gyroscope(), lever_b, w_ie_n)
        if H is not None:
            D[:, X_ROT], D[:, NAVSTATE_VEL] = d_xi, R
            A = D @ J_s
            J_bias = D @ J_b
            J_bias[:, B_GYRO] += d_bg
            H[0] = A[axes][:, NAVSTATE_POSE]
            H[1] = A[axes][:, NAVSTATE_VEL] @ pose.rotation().matrix().T
            H[2] = J_bias[axes]
        return (pred.velocity() + term - v_meas)[axes]

    # The preintegration's rotation and velocity noise through D (at R_f, no lever-arm rate).
    D0 = np.zeros((3, 9))
    D0[:, X_ROT] = velocity_error_jacobians(R_f, omega_b, lever_b, w_ie_n)[1]
    D0[:, NAVSTATE_VEL] = R_f
    C = np.asarray(pim.preintMeasCov())[NAVSTATE, NAVSTATE]
    total = np.asarray(cov, float) + D0 @ C @ D0.T
    return gtsam.CustomFactor(_noise(total, axes), keys, error)


def velocity_window_accel_factor(
    node_keys: list,
    C: np.ndarray,
    a_n: np.ndarray,
    axes: np.ndarray,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    cov: np.ndarray,
) -> gtsam.CustomFactor:
    """The acceleration fitted to a window of Doppler velocities against the slope of the nodes'
    antenna velocities: ``e = S (sum_j C_j v_ant(X_j, V_j, B_j) - a~)`` (``v_ant`` as in
    :func:`gnss_velocity_factor`; the window-consistent velocity form, ``smoother-vaccw``).

    Parameters
    ----------
    node_keys : list of (X, V, B) keys
        The nodes of the window's velocities, oldest first.
    C : ndarray (m,)
        The slope's coefficients [1/s]
        (:func:`gnssacc.estimators.aids.velocity_window.slope_coefficients`).
    a_n : ndarray (3,)
        The fitted acceleration [m/s^2, NED]; ``axes`` the measured ones (boolean (3,)).
    omega_b : ndarray (m, 3)
        The raw gyro held at each velocity [rad/s].
    lever_b, w_ie_n : ndarray (3,)
    cov : ndarray (3, 3)
        Covariance of ``a_n`` [m^2/s^4].
    """
    axes = np.asarray(axes, bool).copy()
    C = np.asarray(C, float).copy()
    a_n, lever_b, w_ie_n = (np.asarray(x, float).copy() for x in (a_n, lever_b, w_ie_n))
    omega_b = np.asarray(omega_b, float).copy()
    with_lever = bool(lever_b.any())
    keys = [int(k) for nk in node_keys for k in (nk if with_lever else nk[1:2])]
    per = 3 if with_lever else 1
    S = np.eye(3)[axes]
    J_pose, J_bias = np.zeros((3, 6)), np.zeros((3, 6))

    def error(this, values: gtsam.Values, H: list | None) -> np.ndarray:
        e = -a_n
        for j in range(len(C)):
            if not with_lever:
                e = e + C[j] * values.atVector(keys[j])
                if H is not None:
                    H[j] = C[j] * S
                continue
            kx, kv, kb = keys[per * j : per * j + 3]
            R = values.atPose3(kx).rotation().matrix()
            w_b = omega_b[j] - values.atConstantBias(kb).gyroscope()
            term, d_xi, d_bg = velocity_error_jacobians(R, w_b, lever_b, w_ie_n)
            e = e + C[j] * (values.atVector(kv) + term)
            if H is not None:
                J_pose[:, X_ROT], J_bias[:, B_GYRO] = d_xi, d_bg
                H[per * j], H[per * j + 1], H[per * j + 2] = (
                    C[j] * J_pose[axes],
                    C[j] * S,
                    C[j] * J_bias[axes],
                )
        return e[axes]

    return gtsam.CustomFactor(_noise(cov, axes), keys, error)
