r"""GNSS-derived acceleration (Versano & Klein, Sec. III) and its measurement Jacobian H_a.

This is the one implementation of the H_a blocks, and the least-squares acceleration of
:mod:`gnssacc.core.gnss_fit` (re-exported here) is the one fit; the EKF update and the smoother's
acceleration factor both call them.

Least squares
-------------
For a window of ``m`` fixes at times ``t_j`` with ``dt_j = t_j - t_0`` the motion model
``p(t_j) = p_0 + v_0 dt_j + a dt_j^2 / 2`` gives the design matrix ``A = [1, dt_j, dt_j^2/2]``
(paper eq. A) and ``B = row_3[(A^T A)^{-1} A^T]`` (paper eq. acc); per axis ``a~ = B p``. For
three uniformly spaced fixes ``B = [1, -2, 1] / dt^2``, the second difference.

Noise: fixes are independent with diagonal NED covariances ``Sigma_j``, so
``Sigma_a = sum_j B_j^2 Sigma_j`` (exact for independent fixes). Correlated (e.g. Gauss-Markov)
GNSS errors largely cancel in ``B p`` (``sum_j B_j = 0``), so this propagated covariance is
conservative for them; a fixed sigma can be configured instead.

Measurement model and attitude-error convention
-----------------------------------------------
The EKF's error state is ``dx = [dp, dv, phi, b_a, b_g]`` = estimate minus truth, with the
attitude error ``phi`` resolved in n and defined by ``R_nb_est = (I + [phi x]) R_nb_true``, and
``b_a`` the residual accelerometer bias, ``f_est = f_true + b_a``. The innovation is predicted
minus measured, ``dz = a_pred - a~`` (the paper's ``dz_a = R a^b - a~^n``), with
``a_pred = R_nb_est f_est + g^n``. To first order

    a_pred - a_true = -[(R_nb f) x] phi + R_nb b_a,

so ``H_a = [0, 0, -[(R_nb f) x], R_nb, 0]`` and ``-[(R_nb f) x] = -R_nb [f x] R_nb^T``.

The paper prints ``H_a = [0, 0, R_nb [f x], -R_nb, 0]``. That is exactly ``-1`` times ours once
``phi`` is resolved in the body frame (``phi_b = R_nb^T phi``): the paper's form is the
Jacobian of the measured-minus-predicted residual w.r.t. a body-frame estimate-minus-truth
attitude error. Both give the same Kalman correction; :func:`paper_H_a_blocks` returns the
printed form and the tests check the mapping.

Window-consistent prediction (``ekf-accw``)
-------------------------------------------
``a~ = B p`` is not the acceleration at one epoch: ``B`` annihilates constants and linear
functions, so Taylor's formula with integral remainder gives the Peano-kernel identity

    B p = int_{t_0}^{t_{m-1}} K(s) p''(s) ds,    K(s) = sum_j B_j (t_j - s)_+,

with ``int K = 1`` (``B`` is exact on ``t^2 / 2``) and ``K = 0`` outside the window. For three
uniform fixes ``K`` is the triangle ``(s - t_0) / dt^2`` rising to ``1 / dt`` at the middle fix and
falling to zero at ``t_2``. The paper compares ``a~`` with ``R_nb f + g`` at ``t_{m-1}`` alone; on
noise-free data that model error is of the order of the acceleration's change over the window.
The window-consistent prediction applies the same operator to what the INS says:

    a_pred = int K(s) (R_nb(s) (f(s) - b_a) + g) ds = R_nb(t_k) F_b + g^n,
    F_b = int K(s) R_{b_k b_s} (f(s) - b_a) ds,      M = int K(s) R_{b_k b_s} ds,

``t_k = t_{m-1}`` the GNSS epoch of the update and ``R_{b_k b_s}`` the body rotation from ``s`` to
``t_k`` integrated from the bias-corrected gyros. IMU sample ``i`` holds over
``(t_{i-1}, t_i]``, so it enters with weight ``w_i = int K`` over that interval (clipped to the
window), exact because ``K`` is piecewise linear (:func:`peano_weights`), and with the rotation at
the interval's midpoint (:func:`gnssacc.estimators.mechanization.kernel_force_integrals`).
Neglected, as in
the paper's model: the earth rate in the relative rotation (7.3e-5 rad/s, < 2e-4 rad over a
2 s window), the transport rate and Coriolis acceleration (``2 omega_ie x v`` < 5e-3 m/s^2 at
30 m/s), the change of ``g^n`` over the window, and the IMU noise over the window. The attitude
and accelerometer-bias errors are taken constant over the window (seconds); the gyro-bias error
turns the relative rotation, ``R^est_{b_k b_s} = (I - [(Gamma(s) b_g) x]) R_{b_k b_s}`` with
``Gamma(s) = int_s^{t_k} R_{b_k b_tau} d tau``. With ``u(s) = R_{b_k b_s} (f(s) - b_a)``:

    a_pred - a_true = -[(R_nb F_b) x] phi + R_nb M b_a + R_nb (int K [u x] Gamma ds) b_g,

so ``H_w = [0, 0, -[(R_nb F_b) x], R_nb M, R_nb G]``, ``G = int K [u x] Gamma ds``: the paper's
``H_a`` with ``f`` replaced by the kernel average (``M = I``, ``G = 0`` for a window of zero
length). The noise is the paper's ``Sigma_a`` (or the configured fixed sigma).

Correlations (all variants)
---------------------------
``a~`` is a deterministic linear function of fixes the filter also uses as position updates.
Both ``ekf-acc`` and ``ekf-accw`` treat it as an independent measurement, so the same fix noise
is counted twice. An exact treatment (stochastic cloning with the fix noises carried as states,
:mod:`gnssacc.analysis.aiding_theory`) reproduces the position-only filter in the linear-Gaussian
case:
the acceleration then carries no information of its own.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from ...checks.quality import touches_segments
from ...core.earth import gravity_n
from ...core.gnss_fit import (  # noqa: F401
    acceleration_row,
    design_matrix,
    ls_acceleration,
    window_accelerations,
)
from ...core.rotations import euler_to_dcm, skew
from ..layout import ATT, BA, N_NAV
from ..mechanization import kernel_force_integrals


@dataclass
class AccelMeasurement:
    """One GNSS-derived acceleration, valid at the newest fix of its window.

    Attributes
    ----------
    t : float
        Time of the newest fix [s] (the epoch at which the update is applied).
    a_n : ndarray, shape (3,)
        Acceleration in NED [m/s^2].
    cov : ndarray, shape (3, 3)
        Covariance [m^2/s^4].
    t_window : ndarray, shape (m,) or None
        The fix times used (``None`` for an acceleration fitted to velocities).
    axes : ndarray (3,) of bool, or None
        The axes measured (``None``: all three).
    """

    t: float
    a_n: np.ndarray
    cov: np.ndarray
    t_window: np.ndarray | None
    axes: np.ndarray | None = None


class AccelWindow:
    """Sliding buffer of the last ``m`` fixes producing GNSS-derived accelerations.

    A measurement is produced only once the buffer holds ``m`` fixes (the paper's rule); the
    buffer is cleared when two consecutive fixes are more than ``max_gap_s`` apart (an outage),
    so no estimate spans a gap.

    Parameters
    ----------
    m : int
        Window length in fixes (>= 3).
    max_gap_s : float
        Largest allowed interval between consecutive fixes [s].
    sigma_override : ndarray, shape (3,), optional
        Fixed 1-sigma N, E, D [m/s^2] replacing the propagated covariance.
    """

    def __init__(
        self, m: int = 3, max_gap_s: float = 2.5, sigma_override: np.ndarray | None = None
    ):
        if m < 3:
            raise ValueError("the acceleration window needs at least 3 fixes")
        self.m, self.max_gap_s = int(m), float(max_gap_s)
        self.sigma_override = None if sigma_override is None else np.asarray(sigma_override, float)
        self._buf: deque = deque(maxlen=self.m)
        self.resets = 0

    def push(self, t: float, p_n: np.ndarray, sigma_ned: np.ndarray) -> AccelMeasurement | None:
        """Add a fix; return a measurement when the window is full, else ``None``."""
        if self._buf and t - self._buf[-1][0] > self.max_gap_s:
            self._buf.clear()
            self.resets += 1
        self._buf.append((float(t), np.asarray(p_n, float), np.asarray(sigma_ned, float)))
        if len(self._buf) < self.m:
            return None
        ts = np.fromiter((b[0] for b in self._buf), float, self.m)
        ps = np.stack([b[1] for b in self._buf])
        ss = np.stack([b[2] for b in self._buf])
        a_n, cov = ls_acceleration(ts, ps, ss)
        if self.sigma_override is not None:
            cov = np.diag(self.sigma_override**2)
        return AccelMeasurement(float(t), a_n, cov, ts)


def measured_specific_force(
    imu, t: float, avg_s: float, seg_i0: np.ndarray, seg_i1: np.ndarray
) -> np.ndarray | None:
    """The specific force [m/s^2, body] an acceleration update at ``t`` compares with ``a~``.

    The paper's choice, the sample holding at ``t`` (``avg_s = 0``), or its mean over
    ``[t - avg_s, t]``. ``None`` when any of those samples lies in a suspect IMU segment
    ``[seg_i0, seg_i1)`` (fabricated or damaged data): the update is then skipped. Both the EKF
    update and the smoother's factor take their specific force from here.
    """
    k0, k1 = imu.sample_range(t, avg_s)
    if touches_segments(k0, k1, seg_i0, seg_i1):
        return None
    return imu.f_b[k0:k1].mean(axis=0)


def peano_kernel(t_fix: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The Peano kernel ``K(s) = sum_j B_j (t_j - s)_+`` [1/s] of the window ``t_fix`` [s] at times
    ``s`` [s] (see the module docstring): ``B p = int K p'' ds``; zero outside the window."""
    t_fix = np.asarray(t_fix, float)
    B = acceleration_row(t_fix)
    s = np.asarray(s, float)
    K = np.maximum(t_fix - s[..., None], 0.0) @ B
    return np.where((s >= t_fix[0]) & (s <= t_fix[-1]), K, 0.0)


def peano_weights(t_fix: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``int_lo^hi K(s) ds`` for intervals ``[lo_i, hi_i]`` inside the window ``t_fix`` [s].

    ``K`` is piecewise linear with the antiderivative ``-sum_j B_j (t_j - s)_+^2 / 2``, so this is
    exact; times are referred to ``t_fix[0]`` to keep the squares small. Dimensionless; they sum
    to 1 over intervals that tile the window.
    """
    t_fix = np.asarray(t_fix, float)
    B = acceleration_row(t_fix)
    tj = t_fix - t_fix[0]
    lo = np.asarray(lo, float)[:, None] - t_fix[0]
    hi = np.asarray(hi, float)[:, None] - t_fix[0]
    return 0.5 * ((np.maximum(tj - lo, 0.0) ** 2 - np.maximum(tj - hi, 0.0) ** 2) @ B)


def window_samples(
    t_imu: np.ndarray, t_fix: np.ndarray, weights=None
) -> tuple[int, int, np.ndarray, np.ndarray] | None:
    """The IMU samples covering the window ``[t_fix[0], t_fix[-1]]`` and their kernel weights.

    Parameters
    ----------
    t_imu : ndarray (N,)
        IMU sample times [s]; sample ``i`` holds over ``(t_imu[i-1], t_imu[i]]``.
    t_fix : ndarray (m,)
        The window's fix times [s].

    Returns
    -------
    k0, k1 : int
        Samples ``k0 .. k1 - 1`` overlap the window.
    h : ndarray (k1 - k0,)
        Length of each sample's overlap with the window [s].
    w : ndarray (k1 - k0,)
        ``int K`` over each overlap (``weights(t_fix, lo, hi)``, default :func:`peano_weights`:
        the positions' kernel).

    ``None`` when the IMU does not cover the window.
    """
    t0, t1 = float(t_fix[0]), float(t_fix[-1])
    k0 = int(np.searchsorted(t_imu, t0, side="right"))
    k1 = int(np.searchsorted(t_imu, t1, side="left")) + 1
    if k0 < 1 or k1 > len(t_imu):
        return None
    lo = np.maximum(t_imu[k0 - 1 : k1 - 1], t0)
    hi = np.minimum(t_imu[k0:k1], t1)
    return k0, k1, hi - lo, (weights or peano_weights)(t_fix, lo, hi)


def predicted_acceleration(R_nb: np.ndarray, f_b: np.ndarray, g_n: np.ndarray) -> np.ndarray:
    """Acceleration in n predicted by the INS, ``a^n = R_nb f_b + g^n`` [m/s^2]."""
    return R_nb @ f_b + g_n


def H_a_blocks(R_nb: np.ndarray, f_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero blocks of H_a under the EKF's convention (see module docstring).

    Parameters
    ----------
    R_nb : ndarray, shape (3, 3)
        Estimated body-to-NED rotation.
    f_b : ndarray, shape (3,)
        Bias-corrected specific force, body frame [m/s^2].

    Returns
    -------
    d_phi : ndarray, shape (3, 3)
        ``d a_pred / d phi = -[(R_nb f_b) x]`` [m/s^2/rad].
    d_ba : ndarray, shape (3, 3)
        ``d a_pred / d b_a = R_nb``.
    """
    return -skew(R_nb @ f_b), R_nb.copy()


def H_a(R_nb: np.ndarray, f_b: np.ndarray) -> np.ndarray:
    """Full 3x15 acceleration measurement matrix ``[0, 0, d_phi, d_ba, 0]``."""
    d_phi, d_ba = H_a_blocks(R_nb, f_b)
    H = np.zeros((3, N_NAV))
    H[:, ATT] = d_phi
    H[:, BA] = d_ba
    return H


def H_w_blocks(
    R_nb: np.ndarray, F_b: np.ndarray, M: np.ndarray, G: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Non-zero blocks of the window-consistent Jacobian ``H_w`` (see module docstring).

    Parameters
    ----------
    R_nb : ndarray (3, 3)
        Estimated body-to-NED rotation at the update epoch ``t_k``.
    F_b, M, G : ndarray (3,), (3, 3), (3, 3)
        Kernel integrals ``int K u``, ``int K R_{b_k b_s}``, ``int K [u x] Gamma`` (body frame at
        ``t_k``; [m/s^2], [-], [m/s]) from
        :func:`gnssacc.estimators.mechanization.kernel_force_integrals`.

    Returns
    -------
    d_phi, d_ba, d_bg : ndarray (3, 3)
        ``-[(R_nb F_b) x]`` [m/s^2/rad], ``R_nb M`` [-], ``R_nb G`` [m/s].
    """
    return -skew(R_nb @ F_b), R_nb @ M, R_nb @ G


def paper_H_a_blocks(R_nb: np.ndarray, f_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The blocks as printed in the paper, ``(R_nb [f x], -R_nb)``.

    They equal ``-(H_a_blocks)`` with the attitude block acting on a body-frame error
    ``phi_b = R_nb^T phi``: ``paper_dphi @ R_nb^T == -d_phi`` and ``paper_dba == -d_ba``.
    """
    return R_nb @ skew(f_b), -R_nb


def model_errors(
    run, m: int = 3, max_gap_s: float = 2.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a~ - a_pred`` at the true state for every full window of a run with truth at its fixes.

    Parameters
    ----------
    run : gnssacc.core.recording.RecordedRun
        With ``run.truth`` (attitude) at the GNSS epochs, e.g. a simulated run; on noise-free
        fixes and a perfect IMU the result is the model error alone.
    m, max_gap_s : int, float
        Window length and largest fix interval [s], as :class:`AccelWindow`.

    Returns
    -------
    t : ndarray (K,)
        The windows' update epochs [s].
    paper, window : ndarray (K, 3)
        Errors [m/s^2, NED] of the paper's one-epoch prediction ``R_nb f(t_k) + g`` and of the
        window-consistent one ``R_nb F_b + g`` (true attitude, zero biases).
    """
    g, tr = run.gnss, run.truth
    if tr is None or tr.rpy is None or len(tr.t) != len(g.t) or not np.allclose(tr.t, g.t):
        raise ValueError("model_errors needs the truth's attitude at the GNSS epochs")
    full, a_meas, _ = window_accelerations(
        g.t, run.origin.to_ned(g.lat, g.lon, g.h), g.sigma_ned, m, max_gap_s
    )
    z3, no = np.zeros(3), np.zeros(0, np.int64)
    rows = []
    for j in np.flatnonzero(full):
        win = window_samples(run.imu.t, g.t[j - m + 1 : j + 1])
        if win is None:
            continue
        k0, k1, h, w = win
        R, g_n = euler_to_dcm(*tr.rpy[j]), gravity_n(tr.lat[j], tr.h[j])
        F, _, _ = kernel_force_integrals(
            run.imu.f_b[k0:k1], run.imu.omega_ib_b[k0:k1], h, w, z3, z3
        )
        f = measured_specific_force(run.imu, g.t[j], 0.0, no, no)
        assert f is not None  # no suspect segments given
        rows.append(
            (
                g.t[j],
                predicted_acceleration(R, f, g_n) - a_meas[j],
                predicted_acceleration(R, F, g_n) - a_meas[j],
            )
        )
    return (
        np.array([r[0] for r in rows]),
        np.array([r[1] for r in rows]).reshape(-1, 3),
        np.array([r[2] for r in rows]).reshape(-1, 3),
    )
