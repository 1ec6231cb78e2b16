r"""The zero-rate reading of a stationary epoch as a factor on a node's pose X and IMU bias B.

A vehicle at rest turns with the earth only: the mean raw gyro reading over a block is the bias
plus the earth rate in body axes,

    e = omega_mean - R^T omega_ie^n - b_g

(``b_g`` the gyro half of B). The earth rate in body axes needs the attitude, the yaw above all:
a prior on the bias alone at the predicted attitude's ``omega_mean - R_pred^T omega_ie^n`` pins the
bias as if that yaw were known, and through the start's bias-yaw correlation it then tells the yaw
the data never told (docs/consistency.md). Here the attitude is a variable of the factor. GTSAM
perturbs the pose on the right, ``R = R_hat Exp(xi)``, so ``R^T w = R_hat^T w + [R_hat^T w x] xi``
to first order, and

    de/dxi  = -[w_b x]     (w_b = R_hat^T omega_ie^n)
    de/db_g = -I

with zero translation and accelerometer-bias columns. This is the EKF's zero-rate ``H`` of
:func:`gnssacc.estimators.aids.zupt.zero_rate` through the conventions' map ``xi = -R^T phi``,
``db = -db_EKF`` (the tests check it against finite differences).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew
from gnssacc.estimators.layout import B_GYRO, X_ROT


def zero_rate_error(
    pose: gtsam.Pose3, b_g: np.ndarray, omega_mean_b: np.ndarray, w_ie_n: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``e`` [rad/s, body] and its Jacobians w.r.t. the Pose3 tangent (3 x 6) and the bias tangent
    (3 x 6, accelerometer first) (module docstring)."""
    w_b = pose.rotation().matrix().T @ w_ie_n
    J_pose, J_bias = np.zeros((3, 6)), np.zeros((3, 6))
    J_pose[:, X_ROT] = -skew(w_b)
    J_bias[:, B_GYRO] = -np.eye(3)
    return omega_mean_b - w_b - b_g, J_pose, J_bias


def zero_rate_factor(
    pose_key: int, bias_key: int, omega_mean_b: np.ndarray, var_b: np.ndarray, w_ie_n: np.ndarray
) -> gtsam.CustomFactor:
    """The zero-rate reading ``omega_mean_b`` [rad/s, body] (variance of that mean ``var_b``
    [(rad/s)^2] per axis) with the earth rate ``w_ie_n`` [rad/s, local NED] (module docstring)."""
    omega_mean_b, w_ie_n = (np.asarray(a, float).copy() for a in (omega_mean_b, w_ie_n))
    keys = [int(pose_key), int(bias_key)]
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.sqrt(np.asarray(var_b, float)))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        e, J_pose, J_bias = zero_rate_error(
            values.atPose3(keys[0]),
            values.atConstantBias(keys[1]).gyroscope(),
            omega_mean_b,
            w_ie_n,
        )
        if H is not None:
            H[0], H[1] = J_pose, J_bias
        return e

    return gtsam.CustomFactor(noise, keys, error)
