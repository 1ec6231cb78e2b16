"""The compiled Kalman update (``gnssacc.estimators.kalman.joseph_update``: Joseph form, NIS gate,
Cholesky inverse) against a plain scipy update on random SPD cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import cho_factor, cho_solve, solve_triangular

from gnssacc.estimators.kalman import joseph_update


def _spd(rng: np.random.Generator, n: int, scale: np.ndarray) -> np.ndarray:
    """A random SPD matrix with standard deviations ``scale`` and random correlations."""
    L = rng.standard_normal((n, n + 2))
    C = L @ L.T
    d = 1.0 / np.sqrt(np.diag(C))
    return (C * d[:, None] * d[None, :]) * scale[:, None] * scale[None, :]


def _case(seed: int, n: int, m: int):
    """P (n x n), H (m x n), R (m x m), dz (m): states of very different scales (metres to rad/s),
    as in the 15/18-state filter."""
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.uniform(-5, 1, n)
    P = _spd(rng, n, scale)
    H = rng.standard_normal((m, n)) * (rng.random((m, n)) < 0.5)  # sparse, like the filter's rows
    H[:, :m] += np.eye(m)  # never rank-deficient
    R = _spd(rng, m, 10.0 ** rng.uniform(-2, 0.5, m))
    S = H @ P @ H.T + R
    dz = np.linalg.cholesky(S) @ rng.standard_normal(m)
    return P, H, R, dz


def _oracle(P, H, R, dz):
    """The textbook update with scipy: gain by Cholesky solve, Joseph covariance."""
    S = H @ P @ H.T + R
    c = cho_factor(S, lower=True)
    K = cho_solve(c, H @ P).T  # K = P H^T S^-1 (S, P symmetric)
    A = np.eye(P.shape[0]) - K @ H
    P_new = A @ P @ A.T + K @ R @ K.T
    L = np.linalg.cholesky(S)
    return dict(
        dx=K @ dz,
        P=P_new,
        nis=float(dz @ cho_solve(c, dz)),
        logdet=np.linalg.slogdet(S)[1],
        wz=solve_triangular(L, dz, lower=True),
    )


CASES = [
    (seed, n, m)
    for seed, (n, m) in enumerate([(15, 3), (15, 1), (18, 3), (15, 6), (18, 6), (9, 2)] * 3)
]


@pytest.mark.parametrize("seed, n, m", CASES)
def test_update_equals_scipy_on_random_spd_cases(seed, n, m):
    P, H, R, dz = _case(seed, n, m)
    ref = _oracle(P, H, R, dz)
    P_k = P.copy()
    dx, nis, logdet, used, wz = joseph_update(P_k, H, R, dz, 0.0)
    assert used
    scale = np.sqrt(np.diag(P))
    # Relative to each state's prior sigma (the states span six decades).
    np.testing.assert_allclose(dx / scale, ref["dx"] / scale, atol=1e-10)
    np.testing.assert_allclose(
        P_k / np.outer(scale, scale), ref["P"] / np.outer(scale, scale), atol=1e-10
    )
    assert nis == pytest.approx(ref["nis"], rel=1e-10)
    assert logdet == pytest.approx(ref["logdet"], rel=1e-10, abs=1e-10)
    np.testing.assert_allclose(wz, ref["wz"], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(P_k, P_k.T)


@pytest.mark.parametrize("seed", range(4))
def test_posterior_information_is_prior_plus_measurement_information(seed):
    """An identity independent of any gain formula: ``P+^-1 = P^-1 + H^T R^-1 H`` (optimal gain)."""
    P, H, R, dz = _case(100 + seed, 15, 3)
    P_k = P.copy()
    joseph_update(P_k, H, R, dz, 0.0)
    info = np.linalg.inv(P) + H.T @ np.linalg.solve(R, H)
    scale = np.sqrt(np.diag(P))
    np.testing.assert_allclose(
        np.linalg.inv(info) / np.outer(scale, scale), P_k / np.outer(scale, scale), atol=1e-8
    )


@pytest.mark.parametrize("seed", range(6))
def test_gate_rejects_exactly_above_its_threshold(seed):
    """Gate a hair below the innovation's NIS: rejected, P untouched, dx zero, NIS still reported;
    a hair above: applied, as with no gate."""
    P, H, R, dz = _case(200 + seed, 15, 3)
    nis_ref = _oracle(P, H, R, dz)["nis"]
    P_rej = P.copy()
    dx, nis, _, used, _ = joseph_update(P_rej, H, R, dz, nis_ref * (1.0 - 1e-9))
    assert not used and np.all(dx == 0.0) and np.array_equal(P_rej, P)
    assert nis == pytest.approx(nis_ref, rel=1e-10)
    P_ok, P_free = P.copy(), P.copy()
    dx_ok, _, _, used_ok, _ = joseph_update(P_ok, H, R, dz, nis_ref * (1.0 + 1e-9))
    dx_free, _, _, _, _ = joseph_update(P_free, H, R, dz, 0.0)
    assert used_ok
    np.testing.assert_array_equal(dx_ok, dx_free)
    np.testing.assert_array_equal(P_ok, P_free)


def test_a_non_positive_definite_innovation_covariance_is_refused():
    """``S`` indefinite (a negative R larger than H P H^T): no update, an infinite NIS, P untouched."""
    P, H, R, dz = _case(300, 15, 3)
    R_bad = R - 2.0 * np.eye(3) * np.max(np.linalg.eigvalsh(H @ P @ H.T + R))
    P_k = P.copy()
    dx, nis, _, used, _ = joseph_update(P_k, H, R_bad, dz, 0.0)
    assert not used and np.isinf(nis) and np.all(dx == 0.0) and np.array_equal(P_k, P)


def test_nis_is_chi_square_over_draws_consistent_with_the_model():
    """2000 innovations drawn from N(0, S): the mean NIS per dof is 1 within a chi-square band at a
    false-failure rate of 1e-3 (two-sided), and the whitened innovation has unit covariance."""
    from scipy.stats import chi2

    rng = np.random.default_rng(400)
    P, H, R, _ = _case(400, 15, 3)
    S = H @ P @ H.T + R
    n, m = 2000, 3
    nis, wz = np.empty(n), np.empty((n, m))
    for i in range(n):
        dz = np.linalg.cholesky(S) @ rng.standard_normal(m)
        _, nis[i], _, _, wz[i] = joseph_update(P.copy(), H, R, dz, 0.0)
    lo, hi = chi2.ppf([5e-4, 1 - 5e-4], n * m)
    assert lo < nis.sum() < hi
    # Each entry of the whitened sample covariance has sd ~ 1/sqrt(n) ~ 0.022 (0.032 on the
    # diagonal); 0.12 is above 3.7 sd for each of the six distinct entries.
    np.testing.assert_allclose(wz.T @ wz / n, np.eye(m), atol=0.12)


@pytest.mark.parametrize("seed, consider", [(300, 8), (301, 0), (302, 14)])
def test_a_consider_state_is_held_while_the_others_get_the_optimal_update(seed, consider):
    """Schmidt's consider state (``consider``): its estimate and variance stay as they were, the
    other states get the optimal update (the scipy oracle's rows), and the stated covariance is
    that of the errors the held gain leaves (sampled: prior draws, measurement noise)."""
    P, H, R, dz = _case(seed, 15, 3)
    ref = _oracle(P, H, R, dz)
    P_k = P.copy()
    dx, _, _, used, _ = joseph_update(P_k, H, R, dz, 0.0, consider)
    assert used and dx[consider] == 0.0
    assert P_k[consider, consider] == pytest.approx(P[consider, consider], rel=1e-12)
    s = np.delete(np.arange(15), consider)
    scale = np.sqrt(np.diag(P))
    np.testing.assert_allclose(dx[s] / scale[s], ref["dx"][s] / scale[s], atol=1e-10)
    np.testing.assert_allclose(
        (P_k / np.outer(scale, scale))[np.ix_(s, s)],
        (ref["P"] / np.outer(scale, scale))[np.ix_(s, s)],
        atol=1e-10,
    )
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(np.zeros(15), P, size=100_000)
    v = rng.multivariate_normal(np.zeros(3), R, size=len(x))
    K = np.zeros((15, 3))
    for j in range(3):  # the held gain, recovered column by column from the update itself
        e = np.zeros(3)
        e[j] = 1.0
        K[:, j] = joseph_update(P.copy(), H, R, e, 0.0, consider)[0]
    err = (x - (x @ H.T + v) @ K.T) / scale  # the error left after the update
    np.testing.assert_allclose(np.cov(err.T), P_k / np.outer(scale, scale), atol=0.02)
