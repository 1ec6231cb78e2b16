r"""A joint Gaussian prior on the first node: pose, IMU bias and (when modelled) GNSS error
together.

Separate priors cannot state that two variables are correlated, and the self-initialised start is
correlated twice over: levelling ties the tilt to the accelerometer bias, and a position taken
from the fixes carries their time-correlated error. The factor's error is

    e = [Log(R0^T R), R0^T (t - t0) (rotation, translation), b - b0 (accelerometer, gyro), g - g0]

with the full covariance: the EKF's initial error state (attitude error and NED position error)
rotated into the prior's body axes, rotation and translation decoupled as in the EKF. Not
``Logmap(X0^-1 X)``: the SE(3) logarithm's translation is ``V(w)^-1 R0^T (t - t0)``, which turns
with the rotation ``w`` by about ``-w x (t - t0) / 2``; where the prior ties the position to the
GNSS error tightly (their sum known to centimetres, each to a metre: a still start's averaged
fixes with a time-correlated error), that term makes the heading "measured" by any metre the
position moves from the prior's, and a still vehicle's fixed-lag smoother stated its unobservable
yaw to 1 deg within 5 s (from 5.9) while it drifted 12 deg. Jacobians (right perturbation of the
pose: ``R' = R Exp(dtheta)``, ``t' = t + R dt``): ``Log``'s inverse right Jacobian on the
rotation, ``R0^T R`` on the translation, identities on the bias and the GNSS error.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.estimators.layout import PRIOR_BIAS, PRIOR_G, PRIOR_POSE, X_ROT, X_TRANS


def joint_prior_factor(
    pose_key: int,
    bias_key: int,
    gm_key: int | None,
    pose0: gtsam.Pose3,
    bias0: np.ndarray,
    g0: np.ndarray | None,
    cov: np.ndarray,
) -> gtsam.CustomFactor:
    """The prior (see the module docstring).

    Parameters
    ----------
    pose_key, bias_key : int
    gm_key : int or None
        Key of the GNSS-error Vector3, or ``None`` when it is not modelled.
    pose0 : gtsam.Pose3
    bias0 : ndarray (6,)
        Accelerometer [m/s^2] and gyro [rad/s] bias prior.
    g0 : ndarray (3,) or None
        GNSS-error prior [m, NED].
    cov : ndarray (12, 12) or (15, 15)
        Covariance of ``e`` (Pose3 tangent: body rotation, body translation).
    """
    bias0 = np.asarray(bias0, float).copy()
    g0 = None if g0 is None else np.asarray(g0, float).copy()
    keys = [pose_key, bias_key] + ([gm_key] if gm_key is not None else [])
    m = PRIOR_BIAS.stop if gm_key is None else PRIOR_G.stop

    R0_T, t0 = pose0.rotation().matrix().T, pose0.translation()

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        pose = values.atPose3(keys[0])
        R = pose.rotation().matrix()
        w = gtsam.Rot3.Logmap(gtsam.Rot3(R0_T @ R))
        e = np.zeros(m)
        e[PRIOR_POSE] = np.r_[w, R0_T @ (pose.translation() - t0)]
        e[PRIOR_BIAS] = values.atConstantBias(keys[1]).vector() - bias0
        if gm_key is not None:
            e[PRIOR_G] = values.atVector(keys[2]) - g0
        if H is not None:
            H[0] = np.zeros((m, 6))
            pose_block = np.zeros((6, 6))  # rows and columns: Pose3 tangent (rotation, translation)
            pose_block[X_ROT, X_ROT] = gtsam.Rot3.LogmapDerivative(w)
            pose_block[X_TRANS, X_TRANS] = R0_T @ R
            H[0][PRIOR_POSE] = pose_block
            H[1] = np.zeros((m, 6))
            H[1][PRIOR_BIAS] = np.eye(6)
            if gm_key is not None:
                H[2] = np.zeros((m, 3))
                H[2][PRIOR_G] = np.eye(3)
        return e

    return gtsam.CustomFactor(
        gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, float)), keys, error
    )
