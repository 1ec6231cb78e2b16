r"""Factors on the velocity of a point of the vehicle: the non-holonomic constraint and wheel
odometry (``gtsam.CustomFactor``\ s on a node's pose X, velocity V and IMU bias B, and for the
odometry its scale-factor variable K).

The velocity of the point ``l_b`` [m, body] from the IMU, relative to the earth, in the body frame:

    v_l = R^T v + (omega~ - b_g - R^T omega_ie^n) x l_b

(``omega~`` the raw gyro at the node, ``b_g`` the gyro half of B). GTSAM perturbs the pose on the
right, ``R = R_hat Exp(xi)`` (``xi`` the first three of the Pose3 tangent), the velocity and the
bias additively. With ``u = R_hat^T v`` and ``w = R_hat^T omega_ie^n``:

    dv_l/dxi  = [u x] + [l x][w x]
                (R^T a = (I - [xi x]) R_hat^T a = R_hat^T a + [R_hat^T a x] xi)
    dv_l/dv   = R_hat^T
    dv_l/db_g = [l x]                    (d(omega x l)/d omega = -[l x], omega = omega~ - b_g)

the translation and accelerometer-bias columns are zero. These are the EKF's ``H_v`` of
:func:`gnssacc.estimators.measurements.vehicle_velocity` through the conventions' map
``xi = -R^T phi``, ``db = -db_EKF`` (the tests check both against finite differences).

* :func:`nhc_factor`: ``e = [v_l,y, v_l,z]`` (zero while rolling; :mod:`gnssacc.estimators.nhc`).
* :func:`odometry_factor`: ``e = (1 + k) v_l,x - v~`` with the scale-factor error ``k`` a
  1-vector variable; ``de/dk = v_l,x``.

Without a lever arm the bias does not enter: the factors are then on (X, V) (and K) only. With
``R_vb`` (body to the vehicle's axes, a constant small misalignment) the velocity and its
Jacobians are taken in the vehicle's axes, ``R_vb v_l``.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import cross3, skew
from gnssacc.estimators.layout import B_GYRO, X_ROT


def vehicle_velocity(
    pose: gtsam.Pose3,
    v_n: np.ndarray,
    b_g: np.ndarray,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``v_l`` [m/s, body] and its Jacobians w.r.t. the Pose3 tangent (3 x 6), the velocity (3 x 3)
    and the bias tangent (3 x 6, accelerometer first) (module docstring)."""
    Rt = pose.rotation().matrix().T
    u = Rt @ v_n
    J_pose, J_bias = np.zeros((3, 6)), np.zeros((3, 6))
    if not lever_b.any():  # no lever-arm terms (iSAM2 calls this a few times per factor)
        J_pose[:, X_ROT] = skew(u)
        return u, J_pose, Rt, J_bias
    w = Rt @ w_ie_n
    L = skew(lever_b)
    J_pose[:, X_ROT] = skew(u) + L @ skew(w)
    J_bias[:, B_GYRO] = L
    return u + cross3(omega_b - b_g - w, lever_b), J_pose, Rt, J_bias


def _keys_and_bias(pose_key, vel_key, bias_key, lever_b):
    with_bias = bool(lever_b.any())  # (a float array: any() is "any != 0")
    return [int(pose_key), int(vel_key)] + ([int(bias_key)] if with_bias else []), with_bias


def _in_vehicle_axes(R_vb, v_l, J_pose, J_vel, J_bias):
    if R_vb is None:
        return v_l, J_pose, J_vel, J_bias
    return R_vb @ v_l, R_vb @ J_pose, R_vb @ J_vel, R_vb @ J_bias


def nhc_factor(
    pose_key: int,
    vel_key: int,
    bias_key: int,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    sigma_mps: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """Zero lateral and vertical velocity at ``lever_b`` [m, body] in the vehicle's axes (``R_vb``,
    body to vehicle; ``None``: the body's), 1-sigma ``sigma_mps`` [m/s] (lateral, vertical);
    ``omega_b`` the raw gyro at the node [rad/s], ``w_ie_n`` the earth rate [rad/s, local NED]."""
    lever_b = np.asarray(lever_b, float).copy()
    keys, with_bias = _keys_and_bias(pose_key, vel_key, bias_key, lever_b)
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigma_mps, float))
    if not with_bias:  # (the rate and the earth's do not enter)
        error = _plain_nhc_error(keys) if R_vb is None else _rotated_nhc_error(keys, R_vb)
        return gtsam.CustomFactor(noise, keys, error)
    omega_b, w_ie_n = (np.asarray(a, float).copy() for a in (omega_b, w_ie_n))
    zero3 = np.zeros(3)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        b_g = values.atConstantBias(keys[2]).gyroscope() if with_bias else zero3
        v_l, J_pose, J_vel, J_bias = _in_vehicle_axes(
            R_vb,
            *vehicle_velocity(
                values.atPose3(keys[0]), values.atVector(keys[1]), b_g, omega_b, lever_b, w_ie_n
            ),
        )
        if H is not None:
            H[0], H[1] = J_pose[1:3], J_vel[1:3]
            if with_bias:
                H[2] = J_bias[1:3]
        return v_l[1:3]

    return gtsam.CustomFactor(noise, keys, error)


def _plain_nhc_error(keys: list):
    """:func:`nhc_factor`'s error without a lever arm and in the body's axes: ``e = (R^T v)_{y,z}``,
    ``de/dxi = [u x]_{y,z}``, ``de/dv = (R^T)_{y,z}`` (iSAM2 calls it a few times per factor: no
    temporaries beyond the products, Jacobian buffers reused; GTSAM copies them out)."""
    J_pose = np.zeros((2, 6))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        Rt = values.atPose3(keys[0]).rotation().matrix().T
        u = Rt @ values.atVector(keys[1])
        if H is not None:
            # Rows y, z of [u x]: [[u_z, 0, -u_x], [-u_y, u_x, 0]].
            J_pose[0, 0], J_pose[0, 2], J_pose[1, 0], J_pose[1, 1] = u[2], -u[0], -u[1], u[0]
            H[0], H[1] = J_pose, Rt[1:3]
        return u[1:3]

    return error


def _rotated_nhc_error(keys: list, R_vb: np.ndarray):
    """:func:`nhc_factor`'s error without a lever arm, in the vehicle's axes ``R_vb``: ``e = (R_vb
    u)_{y,z}`` with ``u = R^T v``, ``de/dxi = (R_vb [u x])_{y,z}`` (translation columns zero),
    ``de/dv = (R_vb R^T)_{y,z}``: the products :func:`vehicle_velocity` and
    :func:`_in_vehicle_axes` form (the same numbers), without their general case's temporaries
    (iSAM2 calls it a few times per factor; GTSAM copies the Jacobians out)."""
    J_pose = np.zeros((3, 6))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        Rt = values.atPose3(keys[0]).rotation().matrix().T
        u = Rt @ values.atVector(keys[1])
        if H is not None:  # J_pose[:, X_ROT] = [u x]
            J_pose[0, 1], J_pose[0, 2], J_pose[1, 0] = -u[2], u[1], u[2]
            J_pose[1, 2], J_pose[2, 0], J_pose[2, 1] = -u[0], -u[1], u[0]
            H[0], H[1] = (R_vb @ J_pose)[1:3], (R_vb @ Rt)[1:3]
        return (R_vb @ u)[1:3]

    return error


def odometry_factor(
    pose_key: int,
    vel_key: int,
    bias_key: int,
    scale_key: int,
    v_odo: float,
    omega_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    sigma_mps: float,
    R_vb: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """Wheel odometry's forward speed ``v_odo`` [m/s] (1-sigma ``sigma_mps``) of the point
    ``lever_b``
    [m, body] along the vehicle's x axis, read with the scale-factor error held by ``scale_key`` (a
    1-vector); ``omega_b``, ``w_ie_n``, ``R_vb`` as for :func:`nhc_factor`."""
    omega_b, lever_b, w_ie_n = (np.asarray(a, float).copy() for a in (omega_b, lever_b, w_ie_n))
    keys, with_bias = _keys_and_bias(pose_key, vel_key, bias_key, lever_b)
    keys.append(int(scale_key))
    zero3 = np.zeros(3)
    v_odo = float(v_odo)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        b_g = values.atConstantBias(keys[2]).gyroscope() if with_bias else zero3
        v_l, J_pose, J_vel, J_bias = _in_vehicle_axes(
            R_vb,
            *vehicle_velocity(
                values.atPose3(keys[0]), values.atVector(keys[1]), b_g, omega_b, lever_b, w_ie_n
            ),
        )
        k = 1.0 + float(values.atVector(keys[-1])[0])
        if H is not None:
            H[0], H[1] = k * J_pose[0:1], k * J_vel[0:1]
            if with_bias:
                H[2] = k * J_bias[0:1]
            H[-1] = np.array([[v_l[0]]])
        return np.array([k * v_l[0] - v_odo])

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, float(sigma_mps)), keys, error)
