"""The discrete process noise of the EKF's covariance propagation (``mechanization.Propagator``)
against the Van Loan discretisation of the continuous error model ``dx/dt = F dx + G w``.

A still IMU (specific force cancelling normal gravity, gyro reading the earth rate, both in body
axes of a tilted, yawed platform) keeps the nominal state, and so ``F``, exactly constant: the
covariance propagated from zero over ``T`` must then equal ``Q_d(T) = int_0^T e^{F s} G Qc G^T
e^{F^T s} ds``, which Van Loan's matrix exponential gives exactly. The kernel's per-sample
``Q = G Qc G^T dt`` with ``Phi = I + F dt`` is a first-order rule: its error falls as ``dt``, so
halving the IMU interval must halve it, and the Richardson extrapolation ``2 P(dt/2) - P(dt)``
must agree to second order.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import expm

from gnssacc.core.earth import earth_rate_n, normal_gravity
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.estimators.layout import (
    ATT,
    BA,
    BG,
    GNSS_ERROR,
    NAV,
    N_NAV,
    VEL,
    MarkovBlock,
    StateLayout,
)
from gnssacc.estimators.mechanization import Propagator, system_matrix

LAT, LON, H = np.radians(52.0), np.radians(4.4), 30.0
R_NB = euler_to_dcm(0.2, -0.15, 2.3)
# Per-axis PSDs with different values on each axis, so that R diag(q) R^T is not isotropic.
Q_A = np.array([1.0, 2.0, 4.0]) * 1e-4  # (m/s^2)^2/s
Q_G = np.array([3.0, 1.0, 2.0]) * 1e-7  # rad^2/s
Q_BA = np.array([2.0, 1.0, 3.0]) * 1e-8  # (m/s^2)^2/s^3 ... per s
Q_BG = np.array([1.0, 3.0, 2.0]) * 1e-12  # (rad/s)^2/s
GM_TAU, GM_SIGMA = np.array([60.0, 30.0, 10.0]), np.array([2.0, 1.5, 3.0])
T = 4.0


def _still_imu(rate_hz: float):
    n = int(round(T * rate_hz)) + 1
    t = np.linspace(0.0, T, n)
    f_b = R_NB.T @ np.array([0.0, 0.0, -normal_gravity(LAT, H)])
    w_b = R_NB.T @ earth_rate_n(LAT)
    return t, np.tile(f_b, (n, 1)), np.tile(w_b, (n, 1)), f_b


def _kernel_q(rate_hz: float, n_states: int, order: int) -> np.ndarray:
    t, f, w, _ = _still_imu(rate_hz)
    z3, seg = np.zeros(3), np.zeros(0, np.int64)
    blocks = [MarkovBlock(GNSS_ERROR, GM_TAU, GM_SIGMA)] if n_states > N_NAV else []
    gm = dict(layout=StateLayout.build(blocks))
    prop = Propagator(
        t, f, w, Q_A, Q_G, Q_BA, Q_BG, (seg, seg, np.zeros((0, 3)), np.zeros((0, 3))), order, **gm
    )
    s = SimpleNamespace(
        pos=np.array([LAT, LON, H]),
        v_n=z3.copy(),
        R_nb=R_NB.copy(),
        b_a=z3.copy(),
        b_g=z3.copy(),
        P=np.zeros((n_states, n_states)),
    )
    prop.advance(s, 1, 0.0, T)
    # The nominal state did not move, so F was the same at every sample.
    np.testing.assert_allclose(s.R_nb, R_NB, atol=1e-12)
    assert np.max(np.abs(s.v_n)) < 1e-9
    return s.P


def _van_loan(n_states: int) -> np.ndarray:
    """``Q_d(T)`` from ``expm([[-F, G Qc G^T], [0, F^T]] T)`` (Van Loan 1978)."""
    _, _, _, f_b = _still_imu(100.0)
    F = np.zeros((n_states, n_states))
    F[NAV, NAV] = system_matrix(np.array([LAT, LON, H]), np.zeros(3), R_NB, f_b)
    GQG = np.zeros((n_states, n_states))
    GQG[VEL, VEL] = R_NB @ np.diag(Q_A) @ R_NB.T
    GQG[ATT, ATT] = R_NB @ np.diag(Q_G) @ R_NB.T
    GQG[BA, BA] = np.diag(Q_BA)
    GQG[BG, BG] = np.diag(Q_BG)
    if n_states > 15:  # first-order Gauss-Markov: dx/dt = -x / tau + w, PSD 2 sigma^2 / tau
        F[15:, 15:] = -np.diag(1.0 / GM_TAU)
        GQG[15:, 15:] = np.diag(2.0 * GM_SIGMA**2 / GM_TAU)
    z = np.zeros_like(F)
    E = expm(np.block([[-F, GQG], [z, F.T]]) * T)
    Phi = E[n_states:, n_states:].T
    return Phi @ E[:n_states, n_states:]


def _rel(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Entry-wise error relative to the reference's sigmas (a correlation-scale error)."""
    s = np.sqrt(np.diag(Q))
    return np.abs(P - Q) / np.outer(s, s)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("n_states", [15, 18])
def test_propagated_noise_converges_to_van_loan(n_states, order):
    Q = _van_loan(n_states)
    P1, P2 = _kernel_q(100.0, n_states, order), _kernel_q(200.0, n_states, order)
    e1, e2 = _rel(P1, Q).max(), _rel(P2, Q).max()
    # A first-order rule over N = 400 steps: the error is O(1/N), here below 1 % of the sigmas;
    # halving dt halves it (ratio 2 +- 10 %), and Richardson's 2 P(dt/2) - P(dt) is second order.
    assert e1 < 1e-2, e1
    assert 1.8 < e1 / e2 < 2.2, (e1, e2)
    assert _rel(2.0 * P2 - P1, Q).max() < 0.05 * e2
    # The diagonal is right to the first-order rule's error (each variance within 1 %).
    np.testing.assert_allclose(np.diag(P2), np.diag(Q), rtol=1e-2)
