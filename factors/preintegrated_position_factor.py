r"""A GNSS fix between two smoother nodes, on the earlier node: its state carried to the fix's time
by the IMU preintegrated from the node to the fix (a ``gtsam.CustomFactor`` on ``(X_i, V_i, B_i)``).

With fixes faster than the nodes (``[smoother] min_node_spacing_s``), the fixes between two nodes
keep their information without nodes of their own. Error (local NED, metres)::

    e = p_f + R_f l_b - p_fix,      (R_f, p_f, v_f) = pim.predict((R_i, p_i, v_i), b_i)

``pim.predict`` is GTSAM's own prediction of a ``PreintegratedCombinedMeasurements`` (gravity,
the earth rate as Coriolis, the first-order correction for the bias ``b_i`` against the bias
the samples were integrated with), with its Jacobians ``J_s`` on the node's ``NavState`` tangent
(rotation, position and velocity increments in the body frame) and ``J_b`` on the bias. The
error's Jacobian on the predicted state's tangent is ``D = [-R_f [l_b x], R_f, 0]``, so::

    de/d(xi, tau) = (D J_s)[:, 0:6]             (Pose3 tangent: R Exp(xi), t + R tau)
    de/dv_n       = (D J_s)[:, 6:9] R_i^T       (the velocity variable is a NED vector)
    de/db         = D J_b

With the Gauss-Markov GNSS error (``-gm`` methods, and runs the tuner finds time-correlated
fixes in), the fix's error is the node's ``g_i`` carried to the fix, ``e += a g_i`` with
``a = exp(-dt/tau)`` per axis (``de/dg = diag(a)``), and the process noise over ``dt``,
``sigma^2 (1 - a^2)``, joins the fix's variance.

Noise: the fix's covariance plus the preintegration's over the interval, ``J_p C J_p^T`` with
``J_p = [-R_f [l_b x], R_f]`` on the preintegrated rotation and position (``R_f`` at the
estimate the factor is made at). Two such factors from one node share the IMU noise (and the
Gauss-Markov process noise) of their common span, and the next node's factors share it too: the
correlation is left out (over a fraction of a second it is a small part of a fix's variance,
which the configuration's ``min_node_spacing_s`` keeps small).
"""
from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew


def preintegrated_position_factor(keys: tuple, pim: gtsam.PreintegratedCombinedMeasurements, p_fix: np.ndarray,
                                  lever_b: np.ndarray, cov_fix: np.ndarray, R_f: np.ndarray,
                                  gm: tuple | None = None) -> gtsam.CustomFactor:
    """Build the factor.

    Parameters
    ----------
    keys : tuple of int
        ``(X_i, V_i, B_i)``: the earlier node's Pose3, NED velocity (Vector3) and IMU bias, and
        with ``gm`` its GNSS error ``G_i`` (Vector3) fourth.
    pim : gtsam.PreintegratedCombinedMeasurements
        The IMU preintegrated from the node's time to the fix's.
    p_fix : ndarray (3,)
        The fix [m, local NED].
    lever_b : ndarray (3,)
        Antenna position in the body frame (FRD) [m].
    cov_fix : ndarray (3, 3)
        The fix's covariance [m^2].
    R_f : ndarray (3, 3)
        Attitude predicted at the fix's time (for the noise of the preintegration).
    gm : tuple, optional
        ``(tau_s, sigma_m)`` of the Gauss-Markov GNSS error (per N, E, D axis, arrays (3,)).
    """
    keys = [int(k) for k in keys]
    a = np.exp(-pim.deltaTij() / np.asarray(gm[0], float)) if gm is not None else None
    p_fix, lever_b = np.asarray(p_fix, float).copy(), np.asarray(lever_b, float).copy()
    L = skew(lever_b)
    # Jacobian buffers reused by every call (GTSAM copies H out before the next call).
    J_s, J_b, D = np.zeros((9, 9), order="F"), np.zeros((9, 6), order="F"), np.zeros((3, 9))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        pose = values.atPose3(keys[0])
        state = gtsam.NavState(pose, values.atVector(keys[1]))
        bias = values.atConstantBias(keys[2])
        pred = pim.predict(state, bias, J_s, J_b) if H is not None else pim.predict(state, bias)
        R = pred.attitude().matrix()
        if H is not None:
            np.matmul(-R, L, out=D[:, 0:3])
            D[:, 3:6] = R
            A = D @ J_s
            H[0], H[1], H[2] = A[:, 0:6], A[:, 6:9] @ pose.rotation().matrix().T, D @ J_b
            if a is not None:
                H[3] = J_g
        e = pred.position() + R @ lever_b - p_fix
        return e if a is None else e + a * values.atVector(keys[3])

    J_p = np.hstack([-R_f @ L, R_f])
    cov = np.asarray(cov_fix, float) + J_p @ np.asarray(pim.preintMeasCov())[0:6, 0:6] @ J_p.T
    if a is not None:
        J_g = np.diag(a)
        cov = cov + np.diag(np.asarray(gm[1], float) ** 2 * (1.0 - a * a))
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(cov), keys, error)
