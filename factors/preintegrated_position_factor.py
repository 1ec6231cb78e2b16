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
fixes in), the fix's error is the process's value at the fix given its values at the two nodes
around it, ``g_i`` at ``s = 0`` and ``g_j`` at ``s = T`` (the Gauss-Markov bridge, per axis, with
``phi(t) = exp(-t/tau)``)::

    e += A g_i + K g_j,   K = phi(T - s) (1 - phi(s)^2) / (1 - phi(T)^2),   A = phi(s) - K phi(T)

and the bridge's variance ``sigma^2 (1 - phi(s)^2) (1 - K phi(T - s))`` joins the fix's. (The
error carried from ``g_i`` alone would leave the wander between the nodes as white noise, and a
smooth wander of fixes more precise than it reads as acceleration: on a static VN-310 log it
tilted the estimate by 2 deg.)

Noise: the fix's covariance plus the preintegration's over the interval, ``J_p C J_p^T`` with
``J_p = [-R_f [l_b x], R_f]`` on the preintegrated rotation and position (``R_f`` at the
estimate the factor is made at). Two such factors from one node share the IMU noise (and their
bridges' deviations) over their common span, and the IMU factor to the next node shares the IMU
noise too: the correlation is left out (over a fraction of a second it is a small part of a
fix's variance, which the configuration's ``min_node_spacing_s`` keeps small).
"""

from __future__ import annotations

import gtsam
import numpy as np

from gnssacc.core.rotations import skew
from gnssacc.estimators.layout import NAVSTATE_POSE, NAVSTATE_VEL, X_ROT, X_TRANS


def preintegrated_position_factor(
    keys: tuple,
    pim: gtsam.PreintegratedCombinedMeasurements,
    p_fix: np.ndarray,
    lever_b: np.ndarray,
    cov_fix: np.ndarray,
    R_f: np.ndarray,
    gm: tuple | None = None,
) -> gtsam.CustomFactor:
    """Build the factor.

    Parameters
    ----------
    keys : tuple of int
        ``(X_i, V_i, B_i)``: the earlier node's Pose3, NED velocity (Vector3) and IMU bias; with
        ``gm`` then the GNSS errors (Vector3) of that node and of the next, ``G_i, G_j``.
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
        ``(tau_s, sigma_m, T_s)``: the Gauss-Markov GNSS error's correlation time and 1-sigma
        (per N, E, D axis, arrays (3,)) and the interval between the two nodes [s].
    """
    keys = [int(k) for k in keys]
    bridge = _bridge(pim.deltaTij(), *gm) if gm is not None else None
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
            np.matmul(-R, L, out=D[:, X_ROT])
            D[:, X_TRANS] = R
            A = D @ J_s
            H[0], H[1], H[2] = (
                A[:, NAVSTATE_POSE],
                A[:, NAVSTATE_VEL] @ pose.rotation().matrix().T,
                D @ J_b,
            )
            if bridge is not None:
                H[3], H[4] = J_gi, J_gj
        e = pred.position() + R @ lever_b - p_fix
        if bridge is None:
            return e
        return e + bridge[0] * values.atVector(keys[3]) + bridge[1] * values.atVector(keys[4])

    J_p = np.hstack([-R_f @ L, R_f])
    cov = (
        np.asarray(cov_fix, float)
        + J_p @ np.asarray(pim.preintMeasCov())[NAVSTATE_POSE, NAVSTATE_POSE] @ J_p.T
    )
    if bridge is not None:
        J_gi, J_gj = np.diag(bridge[0]), np.diag(bridge[1])
        cov = cov + np.diag(bridge[2])
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(cov), keys, error)


def _bridge(s: float, tau_s, sigma_m, T_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first-order Gauss-Markov process at ``s`` given its values at 0 and ``T_s`` [s]: the
    weights ``A``, ``K`` of the two values and the variance left [m^2], per axis (see the module
    notes)."""
    tau, sigma = np.asarray(tau_s, float), np.asarray(sigma_m, float)
    phi = lambda t: np.exp(-t / tau)  # noqa: E731
    K = phi(T_s - s) * (1.0 - phi(s) ** 2) / (1.0 - phi(T_s) ** 2)
    return phi(s) - K * phi(T_s), K, sigma**2 * (1.0 - phi(s) ** 2) * (1.0 - K * phi(T_s - s))
