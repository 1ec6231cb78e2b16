r"""The window-consistent GNSS-acceleration factor (``smoother-accw``): a ``gtsam.CustomFactor`` on
the poses of the least-squares window's fixes.

Error (NED, m/s^2)::

    e = sum_j B_j p_ant(X_j) - a~^n,      p_ant(X) = t + R l_b

with ``B`` the least-squares row of :func:`gnssacc.estimators.aids.accel_model.acceleration_row`
for the window's
fix times and ``a~^n = sum_j B_j p_fix_j``. The operator that made the measurement from the fixes
is applied to the antenna positions the estimate predicts at the same times, so a noise-free
window gives zero error whatever the vehicle does between the fixes (the paper's factor compares
the same window average with the specific force at one epoch instead). No IMU reading enters.

Jacobians on GTSAM's Pose3 tangent (rotation ``xi`` first, then translation ``tau``;
``R -> R Exp(xi)``, ``t -> t + R tau``), the same blocks as the lever-arm GPS factor times ``B_j``::

    de/dxi_j = -B_j R_j [l_b x],     de/dtau_j = B_j R_j

The error is linear in the positions but not in the Pose3 tangent (``tau`` is body-frame), so a
linear GTSAM factor is not exact here: it is a CustomFactor (its cost is in
``bench/bench_smoother.py``).
Noise: the propagated ``sum_j B_j^2 Sigma_j`` (fixes independent) or a fixed sigma, as for the
paper's factor. It is not correlated with the position factors of the same fixes: like the
paper's factor it counts their information twice (:mod:`gnssacc.analysis.aiding_theory`). With the
Gauss-Markov GNSS-error states the factor still compares with the antenna positions alone (the
second difference of a slow error is small, but it is not modelled here).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew
from gnssacc.estimators.layout import X_ROT, X_TRANS


def window_accel_error(
    poses: list, B_row: np.ndarray, lever_b: np.ndarray, a_n: np.ndarray
) -> np.ndarray:
    """``sum_j B_j (t_j + R_j l_b) - a_n`` [m/s^2] for ``gtsam.Pose3`` ``poses`` (body in local
    NED)."""
    ant = [p.translation() + p.rotation().matrix() @ lever_b for p in poses]
    return np.asarray(B_row, float) @ np.asarray(ant) - a_n


def window_accel_factor(
    pose_keys: list, B_row: np.ndarray, a_n: np.ndarray, lever_b: np.ndarray, cov: np.ndarray
) -> gtsam.CustomFactor:
    """Build the factor.

    Parameters
    ----------
    pose_keys : list of int
        Keys of the Pose3 at the window's fix times, oldest first (m of them).
    B_row : ndarray (m,)
        Least-squares acceleration row for those times [1/s^2].
    a_n : ndarray (3,)
        GNSS-derived acceleration ``B_row @ p_fix``, NED [m/s^2].
    lever_b : ndarray (3,)
        Antenna position in the body frame (FRD) [m].
    cov : ndarray (3, 3)
        Covariance of ``a_n`` [m^2/s^4].
    """
    keys = [int(k) for k in pose_keys]
    B_row = [float(b) for b in B_row]
    a_n, lever_b = np.asarray(a_n, float).copy(), np.asarray(lever_b, float).copy()
    L = skew(lever_b)
    has_arm = bool(np.any(lever_b != 0))
    # Jacobian buffers reused by every call (GTSAM copies H out before the next call); without
    # a lever arm the rotation columns stay zero.
    J = [np.zeros((3, 6)) for _ in keys]

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        e = -a_n
        for j, (key, b) in enumerate(zip(keys, B_row, strict=True)):
            pose = values.atPose3(key)
            R = pose.rotation().matrix()
            e = e + b * (pose.translation() + R @ lever_b if has_arm else pose.translation())
            if H is not None:
                if has_arm:
                    np.multiply(R @ L, -b, out=J[j][:, X_ROT])
                np.multiply(R, b, out=J[j][:, X_TRANS])
                H[j] = J[j]
        return e

    cov = np.asarray(cov, float)
    noise = (
        gtsam.noiseModel.Diagonal.Variances(np.diag(cov))
        if np.count_nonzero(cov - np.diag(np.diag(cov))) == 0
        else gtsam.noiseModel.Gaussian.Covariance(cov)
    )
    return gtsam.CustomFactor(noise, keys, error)
