r"""A joint Gaussian prior on the first node: pose, IMU bias and (when modelled) GNSS error
together.

Separate priors cannot state that two variables are correlated, and the self-initialised start is
correlated twice over: levelling ties the tilt to the accelerometer bias, and a position taken
from the fixes carries their time-correlated error. The factor's error is

    e = [Logmap(X0_prior^-1 X) (rotation, translation), b - b0 (accelerometer, gyro), g - g0]

with the full covariance, and Jacobians ``LogmapDerivative(X0_prior^-1 X)`` on the pose (right
perturbation) and identities on the bias and the GNSS error.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.estimators.layout import PRIOR_BIAS, PRIOR_G, PRIOR_POSE


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

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        rel = pose0.between(values.atPose3(keys[0]))
        e = np.zeros(m)
        e[PRIOR_POSE] = gtsam.Pose3.Logmap(rel)
        e[PRIOR_BIAS] = values.atConstantBias(keys[1]).vector() - bias0
        if gm_key is not None:
            e[PRIOR_G] = values.atVector(keys[2]) - g0
        if H is not None:
            H[0] = np.zeros((m, 6))
            H[0][PRIOR_POSE] = gtsam.Pose3.LogmapDerivative(rel)
            H[1] = np.zeros((m, 6))
            H[1][PRIOR_BIAS] = np.eye(6)
            if gm_key is not None:
                H[2] = np.zeros((m, 3))
                H[2][PRIOR_G] = np.eye(3)
        return e

    return gtsam.CustomFactor(
        gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, float)), keys, error
    )
