r"""The GNSS-acceleration factor: a ``gtsam.CustomFactor`` on a pose X_k and an IMU bias B_k.

Error (NED, m/s^2)::

    e = R(X_k) (f~_b - b_a) + g^n - a~^n

with ``a~^n`` the least-squares GNSS acceleration of :mod:`gnssacc.estimators.aids.accel_model`
(same window,
same noise propagation as the EKF) and ``f~_b`` the specific force at the node time.

Jacobians, from the EKF's H_a blocks (one implementation,
:func:`gnssacc.estimators.aids.accel_model.H_a_blocks`)
-------------------------------------------------------------------------------------------------
GTSAM perturbs a pose on the right, ``R = R_hat Exp(xi)`` (``xi`` body-frame rotation, first three
of the Pose3 tangent), and a bias additively, ``b = b_hat + db`` (accelerometer first). The EKF
uses ``R_hat = (I + [phi x]) R`` (phi in n, estimate minus truth) and a residual bias with
``f_hat = f + b_a``. For the same small error: ``xi = -R_hat^T phi`` and ``db_a = b_a``. Hence

    de/dxi   = H_phi R_hat       (= -R_hat [f x])
    de/db_a  = -H_ba             (= -R_hat)

where ``(H_phi, H_ba) = H_a_blocks(R_hat, f)``; the translation and gyro-bias columns are zero.
Equivalently ``H_phi = (de/dxi) R_hat^T`` and ``H_ba = -(de/db_a)``: the EKF's H_a, mapped
through the two attitude-error conventions (tests check both directions and finite differences).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew
from gnssacc.estimators.aids.accel_model import H_a_blocks, predicted_acceleration
from gnssacc.estimators.layout import B_ACC, X_ROT


def smoother_jacobians_from_H_a(R_nb: np.ndarray, f_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of the factor error w.r.t. the Pose3 tangent (3x6) and the bias tangent (3x6).

    Parameters
    ----------
    R_nb : ndarray (3, 3)
        Body-to-NED rotation of the pose.
    f_b : ndarray (3,)
        Bias-corrected specific force [m/s^2].
    """
    H_phi, H_ba = H_a_blocks(R_nb, f_b)
    J_pose = np.zeros((3, 6))
    J_pose[:, X_ROT] = H_phi @ R_nb
    J_bias = np.zeros((3, 6))
    J_bias[:, B_ACC] = -H_ba
    return J_pose, J_bias


def accel_error(
    pose: gtsam.Pose3,
    bias: gtsam.imuBias.ConstantBias,
    f_b: np.ndarray,
    a_n: np.ndarray,
    g_n: np.ndarray,
) -> np.ndarray:
    """Factor error ``R (f_b - b_a) + g_n - a_n`` [m/s^2]."""
    R_nb = pose.rotation().matrix()
    return predicted_acceleration(R_nb, f_b - bias.accelerometer(), g_n) - a_n


def gnss_accel_factor(
    pose_key: int,
    bias_key: int,
    f_b: np.ndarray,
    a_n: np.ndarray,
    g_n: np.ndarray,
    cov: np.ndarray,
    axes: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """Build the factor.

    Parameters
    ----------
    pose_key, bias_key : int
        Keys of the Pose3 (body in the local NED frame) and the imuBias.ConstantBias.
    f_b : ndarray (3,)
        Measured specific force at the node time, body frame [m/s^2].
    a_n : ndarray (3,)
        GNSS-derived acceleration, NED [m/s^2].
    g_n : ndarray (3,)
        Gravity in NED at the node [m/s^2].
    cov : ndarray (3, 3)
        Covariance of ``a_n`` [m^2/s^4].
    axes : ndarray (3,) of bool, optional
        The axes measured (an acceleration fitted to horizontal-only velocities: north and
        east); the error and its Jacobians keep those rows. Default: all three.
    """
    if axes is not None and not np.all(axes):
        return _some_axes(pose_key, bias_key, f_b, a_n, g_n, cov, np.asarray(axes, bool))
    f_b = np.asarray(f_b, float).copy()
    g_minus_a = np.asarray(g_n, float) - np.asarray(a_n, float)
    pose_key, bias_key = int(pose_key), int(bias_key)
    # Jacobian buffers reused by every call: GTSAM copies H out before the next call, and the
    # zero translation / gyro-bias columns never change.
    J_pose, J_bias = np.zeros((3, 6)), np.zeros((3, 6))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        # iSAM2 calls this a few times per factor (insertion, relinearisations, marginalisation):
        # one lookup per variable and no temporaries beyond H_a_blocks'.
        R_nb = values.atPose3(pose_key).rotation().matrix()
        f_n = R_nb @ (f_b - values.atConstantBias(bias_key).accelerometer())
        if H is not None:
            # smoother_jacobians_from_H_a's numbers, H_a_blocks' (-[f_n x], R_nb) written out
            # with the product f_n formed once.
            np.matmul(-skew(f_n), R_nb, out=J_pose[:, X_ROT])
            np.negative(R_nb, out=J_bias[:, B_ACC])
            H[0], H[1] = J_pose, J_bias
        return f_n + g_minus_a  # predicted_acceleration(R_nb, f_corr, g_n) - a_n

    # The LS window's acceleration errors are uncorrelated across axes (diagonal covariance): a
    # Diagonal model whitens with three divisions instead of a 3x3 triangular solve.
    cov = np.asarray(cov, float)
    noise = (
        gtsam.noiseModel.Diagonal.Variances(np.diag(cov))
        if np.count_nonzero(cov - np.diag(np.diag(cov))) == 0
        else gtsam.noiseModel.Gaussian.Covariance(cov)
    )
    return gtsam.CustomFactor(noise, [pose_key, bias_key], error)


def _some_axes(pose_key, bias_key, f_b, a_n, g_n, cov, axes) -> gtsam.CustomFactor:
    """:func:`gnss_accel_factor` on the measured ``axes`` only (the same error and Jacobians)."""
    keys = [int(pose_key), int(bias_key)]
    f_b = np.asarray(f_b, float).copy()
    g_minus_a = np.asarray(g_n, float) - np.asarray(a_n, float)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        R_nb = values.atPose3(keys[0]).rotation().matrix()
        f_corr = f_b - values.atConstantBias(keys[1]).accelerometer()
        if H is not None:
            J_pose, J_bias = smoother_jacobians_from_H_a(R_nb, f_corr)
            H[0], H[1] = J_pose[axes], J_bias[axes]
        return (R_nb @ f_corr + g_minus_a)[axes]

    c = np.asarray(cov, float)[np.ix_(axes, axes)]
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(c), keys, error)
