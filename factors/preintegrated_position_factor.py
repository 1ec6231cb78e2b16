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
estimate the factor is made at). Two fixes folded into one node share the IMU noise over their
common span, and the IMU factor to the next node shares it too: that correlation is left out
(over a fraction of a second it is a small part of a fix's variance, which the configuration's
``min_node_spacing_s`` keeps small). Their bridges' deviations are one path of the process, and
need not be small: with a wander of 0.28 m and 4.9 s and nodes 0.5 s apart, ~6 cm at mid-interval
against fixes of 1 cm white noise. So the fixes folded between two nodes with the Gauss-Markov
error are one factor, :func:`preintegrated_positions_factor`, with the bridge's joint covariance
(:func:`bridge_covariance`); as separate factors, 20 Hz fixes counted each interval's deviation
~10 times (a simulated rover's smoother: yaw 33 deg off at a stated 3 deg, yaw NEES 77; jointly
16 deg RMS, NEES 18).
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
        e, blocks = _predicted(pim, state, bias, pose, lever_b, L, p_fix, (J_s, J_b, D), H)
        if H is not None:
            H[0], H[1], H[2] = blocks
            if bridge is not None:
                H[3], H[4] = J_gi, J_gj
        if bridge is None:
            return e
        return e + bridge[0] * values.atVector(keys[3]) + bridge[1] * values.atVector(keys[4])

    cov = np.asarray(cov_fix, float) + _imu_cov(pim, R_f, L)
    if bridge is not None:
        J_gi, J_gj = np.diag(bridge[0]), np.diag(bridge[1])
        cov = cov + np.diag(bridge[2])
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(cov), keys, error)


def _predicted(pim, state, bias, pose, lever_b, L, p_fix, buffers, H) -> tuple:
    """A fix's error (3,) on the node's state carried to it by ``pim`` and, when ``H`` is not
    ``None``, its Jacobians on the node's pose, NED velocity and bias (``buffers``: ``J_s``,
    ``J_b``, ``D``, reused)."""
    J_s, J_b, D = buffers
    pred = pim.predict(state, bias, J_s, J_b) if H is not None else pim.predict(state, bias)
    R = pred.attitude().matrix()
    blocks = None
    if H is not None:
        np.matmul(-R, L, out=D[:, X_ROT])
        D[:, X_TRANS] = R
        A = D @ J_s
        blocks = (
            A[:, NAVSTATE_POSE],
            A[:, NAVSTATE_VEL] @ pose.rotation().matrix().T,
            D @ J_b,
        )
    return pred.position() + R @ lever_b - p_fix, blocks


def _imu_cov(pim, R_f: np.ndarray, L: np.ndarray) -> np.ndarray:
    """The preintegration's noise on a fix's predicted antenna [m^2] (module notes)."""
    J_p = np.hstack([-R_f @ L, R_f])
    return J_p @ np.asarray(pim.preintMeasCov())[NAVSTATE_POSE, NAVSTATE_POSE] @ J_p.T


def preintegrated_positions_factor(
    keys: tuple,
    pims: list,
    p_fixes: np.ndarray,
    lever_b: np.ndarray,
    covs_fix: list,
    R_fs: list,
    gm: tuple,
) -> gtsam.CustomFactor:
    """All the fixes folded between two nodes, with the Gauss-Markov GNSS error, in one factor:
    their errors stacked (each :func:`preintegrated_position_factor`'s), with the bridge's joint
    covariance between them (:func:`bridge_covariance`).

    The fixes of one interval deviate from the bridge's mean by one path of the process: as
    separate factors they would count that deviation once per fix (on a slow rover with 20 Hz
    fixes, a 0.28 m, 4.9 s wander and nodes 0.5 s apart, ~6 cm a fix against 1 cm of white noise:
    the smoother's yaw drifted to 33 deg off at a stated 3 deg). The preintegration's noise the
    fixes share is still left out (module notes).

    Parameters
    ----------
    keys : tuple of int
        ``(X_i, V_i, B_i, G_i, G_j)``.
    pims : list of gtsam.PreintegratedCombinedMeasurements
        The IMU preintegrated from the node's time to each fix's.
    p_fixes : ndarray (m, 3)
        The fixes [m, local NED].
    lever_b : ndarray (3,)
    covs_fix : list of ndarray (3, 3)
        Each fix's covariance [m^2].
    R_fs : list of ndarray (3, 3)
        The attitude predicted at each fix's time.
    gm : tuple
        ``(tau_s, sigma_m, T_s)`` as for :func:`preintegrated_position_factor`.
    """
    keys = [int(k) for k in keys]
    m = len(pims)
    s = np.array([p.deltaTij() for p in pims])
    bridges = [_bridge(t, *gm) for t in s]
    J_gi = np.vstack([np.diag(b[0]) for b in bridges])
    J_gj = np.vstack([np.diag(b[1]) for b in bridges])
    w_i, w_j = J_gi.sum(axis=1), J_gj.sum(axis=1)
    p_fix = np.asarray(p_fixes, float).copy()
    lever_b = np.asarray(lever_b, float).copy()
    L = skew(lever_b)
    buffers = (np.zeros((9, 9), order="F"), np.zeros((9, 6), order="F"), np.zeros((3, 9)))

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> np.ndarray:
        pose = values.atPose3(keys[0])
        state = gtsam.NavState(pose, values.atVector(keys[1]))
        bias = values.atConstantBias(keys[2])
        rows = [
            _predicted(pims[k], state, bias, pose, lever_b, L, p_fix[k], buffers, H)
            for k in range(m)
        ]
        if H is not None:
            H[0], H[1], H[2] = (np.vstack([r[1][j] for r in rows]) for j in range(3))
            H[3], H[4] = J_gi, J_gj
        e = np.concatenate([r[0] for r in rows])
        return (
            e
            + w_i * np.tile(values.atVector(keys[3]), m)
            + w_j * np.tile(values.atVector(keys[4]), m)
        )

    cov = np.zeros((3 * m, 3 * m))
    for a in range(m):
        cov[3 * a : 3 * a + 3, 3 * a : 3 * a + 3] = np.asarray(covs_fix[a], float) + _imu_cov(
            pims[a], R_fs[a], L
        )
    cov += bridge_covariance(s, *gm)
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(cov), keys, error)


def bridge_covariance(s: np.ndarray, tau_s, sigma_m, T_s: float) -> np.ndarray:
    """The joint covariance [m^2] of the Gauss-Markov GNSS error at the times ``s`` (m,) [s] after
    a node given its values at the two nodes (0 and ``T_s``): ``(3 m, 3 m)``, fix by fix, axis by
    axis (the axes independent). Between times ``a`` and ``b``, per axis,
    ``sigma^2 (phi(|a - b|) - A_a phi(b) - K_a phi(T - b))`` with the bridge's weights ``A``, ``K``
    (:func:`_bridge`); on the diagonal the bridge's variance."""
    s = np.asarray(s, float)
    tau, sigma = np.asarray(tau_s, float), np.asarray(sigma_m, float)
    tau, sigma = np.broadcast_to(tau, (3,)), np.broadcast_to(sigma, (3,))
    m = len(s)
    out = np.zeros((3 * m, 3 * m))
    for a in range(m):
        A, K, _ = _bridge(s[a], tau, sigma, T_s)
        for b in range(m):
            c = sigma**2 * (
                np.exp(-abs(s[a] - s[b]) / tau)
                - A * np.exp(-s[b] / tau)
                - K * np.exp(-(T_s - s[b]) / tau)
            )
            out[3 * a : 3 * a + 3, 3 * b : 3 * b + 3] = np.diag(c)
    return out


def _bridge(s: float, tau_s, sigma_m, T_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first-order Gauss-Markov process at ``s`` given its values at 0 and ``T_s`` [s]: the
    weights ``A``, ``K`` of the two values and the variance left [m^2], per axis (see the module
    notes)."""
    tau, sigma = np.asarray(tau_s, float), np.asarray(sigma_m, float)
    phi = lambda t: np.exp(-t / tau)  # noqa: E731
    K = phi(T_s - s) * (1.0 - phi(s) ** 2) / (1.0 - phi(T_s) ** 2)
    return phi(s) - K * phi(T_s), K, sigma**2 * (1.0 - phi(s) ** 2) * (1.0 - K * phi(T_s - s))
