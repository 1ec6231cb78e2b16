r"""Factors for time-correlated GNSS errors: a first-order Gauss-Markov error ``g`` (NED, metres)
per fix, as in the EKF's three extra states (:mod:`gnssacc.estimators.measurements`).

* :func:`gnss_position_gm_factor` on (X_k, G_k): the fix is the antenna plus its correlated
  error, ``e = t + R l_b + g - p_fix`` with white noise ``Sigma``. Jacobians on GTSAM's Pose3
  tangent (rotation ``xi``, translation ``tau``; ``R -> R Exp(xi)``, ``t -> t + R tau``):
  ``de/dxi = -R [l_b x]``, ``de/dtau = R``, ``de/dg = I``.
* :func:`gauss_markov_factor` on (G_{k-1}, G_k): ``e = g_k - a g_{k-1}``, ``a = exp(-dt/tau)``,
  with 1-sigma ``sigma sqrt(1 - a^2)`` per axis (the exact discretisation of the process).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew
from gnssacc.estimators.layout import X_ROT, X_TRANS


def gnss_position_gm_factor(
    pose_key: int,
    gm_key: int,
    p_fix: np.ndarray,
    lever_b: np.ndarray,
    sigma_ned: np.ndarray,
    cov_ned: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """A fix ``p_fix`` [m, local NED] of the antenna at ``lever_b`` [m, body] with white 1-sigma
    ``sigma_ned`` [m] (or the full white covariance ``cov_ned`` [m^2] when given) and the
    Gauss-Markov error held by ``gm_key`` (a Vector3)."""
    p_fix, lever_b = np.asarray(p_fix, float).copy(), np.asarray(lever_b, float).copy()
    keys = (pose_key, gm_key)
    # Jacobian buffers reused by every call (GTSAM copies H out before the next call; iSAM2
    # linearises this factor dozens of times in a 10 Hz window).
    J_pose, J_g, minus_L = np.zeros((3, 6)), np.eye(3), -skew(lever_b)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        pose = values.atPose3(keys[0])
        R = pose.rotation().matrix()
        if H is not None:
            np.matmul(R, minus_L, out=J_pose[:, X_ROT])
            J_pose[:, X_TRANS] = R
            H[0], H[1] = J_pose, J_g
        return pose.translation() + R @ lever_b + values.atVector(keys[1]) - p_fix

    noise = (
        gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigma_ned, float))
        if cov_ned is None
        else gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov_ned, float))
    )
    return gtsam.CustomFactor(noise, list(keys), error)


def gauss_markov_factor(
    prev_key: int, key: int, dt: float, tau_s: np.ndarray, sigma_m: np.ndarray
) -> gtsam.LinearContainerFactor:
    """The Gauss-Markov transition over ``dt`` [s] (correlation time ``tau_s`` [s], stationary
    1-sigma ``sigma_m`` [m], per N, E, D axis; or per entry of any vector variable with one entry
    each, e.g. the odometry scale factor's).

    The error is linear in the two Vector3 variables, so it is GTSAM's own linear factor
    (a ``JacobianFactor`` held by a ``LinearContainerFactor`` linearised at zero: the error at any
    values is exactly ``g_k - a g_{k-1}``), with no Python callback in iSAM2's updates.
    """
    a = np.atleast_1d(np.exp(-dt / np.asarray(tau_s, float)))
    sig = np.maximum(np.asarray(sigma_m, float) * np.sqrt(1.0 - a * a), 1e-9)
    zero = np.zeros(len(a))  # the linearisation point: zero errors
    linear = gtsam.JacobianFactor(
        prev_key,
        -np.diag(a),
        key,
        np.eye(len(a)),
        zero,
        gtsam.noiseModel.Diagonal.Sigmas(np.atleast_1d(sig)),
    )
    at = gtsam.Values()
    at.insert(prev_key, zero)
    at.insert(key, zero)
    return gtsam.LinearContainerFactor(linear, at)
