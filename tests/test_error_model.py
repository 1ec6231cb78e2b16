"""The error model F (and Phi) against finite differences of the nonlinear mechanization."""

import numpy as np
import pytest

from gnssacc.core import earth
from gnssacc.core.rotations import dcm_to_rotvec, euler_to_dcm, rotvec_to_dcm
from gnssacc.estimators.mechanization import strapdown_step, system_matrix
from gnssacc.estimators.layout import ATT, BA, BG, POS, VEL


def _error(est, true):
    """Error state (estimate minus truth) with the filter's conventions."""
    pos_e, v_e, R_e, ba_e, bg_e = est
    pos, v, R, ba, bg = true
    R_M, R_N = earth.radii(pos[0])
    dp = np.array(
        [
            (R_M + pos[2]) * (pos_e[0] - pos[0]),
            (R_N + pos[2]) * np.cos(pos[0]) * (pos_e[1] - pos[1]),
            -(pos_e[2] - pos[2]),
        ]
    )
    return np.concatenate([dp, v_e - v, dcm_to_rotvec(R_e @ R.T), ba_e - ba, bg_e - bg])


def _perturb(true, e):
    pos, v, R, ba, bg = true
    R_M, R_N = earth.radii(pos[0])
    pos_e = np.array(
        [
            pos[0] + e[0] / (R_M + pos[2]),
            pos[1] + e[1] / ((R_N + pos[2]) * np.cos(pos[0])),
            pos[2] - e[2],
        ]
    )
    return pos_e, v + e[VEL], rotvec_to_dcm(e[ATT]) @ R, ba + e[BA], bg + e[BG]


def _step(state, f_true, w_true, dt):
    pos, v, R, ba, bg = (s.copy() for s in state)
    # The estimate's sensors read the truth plus its residual biases (f_est = f + b_a).
    strapdown_step(pos, v, R, f_true + ba, w_true + bg, dt)
    return pos, v, R, ba, bg


def _central(true, est, f_b, w_b, h):
    plus = _error(_step(est, f_b, w_b, h), _step(true, f_b, w_b, h))
    minus = _error(_step(est, f_b, w_b, -h), _step(true, f_b, w_b, -h))
    return (plus - minus) / (2 * h)


def _error_rate(true, e, f_b, w_b, h):
    """Time derivative of the error by Richardson-extrapolated central differences (O(h^4))."""
    est = _perturb(true, e)
    return (4 * _central(true, est, f_b, w_b, h / 2) - _central(true, est, f_b, w_b, h)) / 3


@pytest.mark.parametrize(
    "lat_deg,v_n", [(50.0, [20.0, -15.0, 1.0]), (-33.0, [-3.0, 2.0, -0.5]), (10.0, [0.0, 0.0, 0.0])]
)
def test_F_matches_finite_differences(lat_deg, v_n):
    pos = np.array([np.radians(lat_deg), np.radians(8.0), 300.0])
    v = np.array(v_n)
    R = euler_to_dcm(0.1, -0.05, 1.0)
    true = (pos, v, R, np.zeros(3), np.zeros(3))
    f_b = np.array([0.5, -0.3, -9.7])
    w_b = np.array([0.01, -0.02, 0.1])
    eps = np.array([100.0] * 3 + [1.0] * 3 + [1e-2] * 3 + [0.1] * 3 + [1e-2] * 3)
    F_num = np.zeros((15, 15))
    for j in range(15):
        e = np.zeros(15)
        e[j] = eps[j]
        F_num[:, j] = (
            _error_rate(true, e, f_b, w_b, 0.05) - _error_rate(true, -e, f_b, w_b, 0.05)
        ) / (2 * eps[j])
    F = system_matrix(pos, v, R, f_b)
    # Block tolerances (absolute, plus 0.5 % relative). Rows of the position error are limited by
    # the double precision of latitude (~1e-9 m), which these perturbations turn into ~5e-6;
    # F_pp and F_vp neglect the ellipticity terms d(R_M, R_N, g)/d(lat), which are ~0.3 % of
    # entries that are themselves ~1e-6.
    atol = np.full((15, 15), 1e-9)
    atol[POS, 6:15] = 5e-6
    atol[POS, 0:6] = 3e-8
    atol[VEL, POS] = 2e-8
    err = np.abs(F - F_num)
    tol = atol + 5e-3 * np.abs(F_num)
    bad = np.argwhere(err > tol)
    assert bad.size == 0, "\n".join(
        f"F[{i}, {j}] = {F[i, j]:.6e}, numeric {F_num[i, j]:.6e}" for i, j in bad
    )
    # The blocks the paper names explicitly are exact.
    np.testing.assert_allclose(F[POS, VEL], np.eye(3))
    np.testing.assert_allclose(F[VEL, BA], R)
    np.testing.assert_allclose(F[ATT, BG], R)


@pytest.mark.parametrize("order", [1, 2])
def test_sparse_covariance_propagation_equals_dense(order):
    from gnssacc.estimators.mechanization import _propagate_cov

    rng = np.random.default_rng(1)
    pos = np.array([0.8, 0.1, 50.0])
    v = np.array([5.0, -2.0, 0.1])
    R = euler_to_dcm(0.05, 0.02, -2.0)
    f_b = np.array([0.3, 0.1, -9.8])
    F = system_matrix(pos, v, R, f_b)
    L = rng.standard_normal((15, 15))
    P0 = L @ L.T
    P = P0.copy()
    dt = 0.01
    z = np.zeros(3)
    _propagate_cov(P, F, np.empty((9, 15)), R, dt, z, z, z, z, order)
    Phi = np.eye(15) + F * dt + (0.5 * (F * dt) @ (F * dt) if order == 2 else 0.0)
    np.testing.assert_allclose(P, Phi @ P0 @ Phi.T, rtol=1e-12, atol=1e-12)
