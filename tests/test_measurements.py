"""Jacobians of the new measurement models and factors by finite differences, and the Gauss-Markov
covariance propagation against its closed form."""

from __future__ import annotations

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest
from gnssacc.factors import gauss_markov_factor, gnss_position_gm_factor
from gtsam.symbol_shorthand import G, X

from gnssacc.core.earth import earth_rate_n, radii
from gnssacc.core.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.estimators.aids import gnss_position, zupt
from gnssacc.estimators.layout import (
    ATT,
    BA,
    BG,
    BIASES,
    GNSS_ERROR,
    POS,
    VEL,
    MarkovBlock,
    StateLayout,
)
from gnssacc.estimators.mechanization import Propagator

LAT, LON, H = np.radians(47.3), np.radians(8.5), 420.0
R_TRUE = euler_to_dcm(0.04, -0.03, 2.1)
B_TRUE = np.array([3e-4, -2e-4, 5e-4])  # gyro bias [rad/s]
W_IE = earth_rate_n(LAT)


def _state(err: np.ndarray, n: int = 15, gm_true=np.zeros(3)):  # noqa: B008 (never mutated)
    """The estimate that is ``err`` (estimate minus truth, order [dp, dv, phi, b_a, b_g (, x_g)]) off the truth."""
    R_M, R_N = radii(LAT)
    pos = np.array([LAT + err[0] / (R_M + H), LON + err[1] / ((R_N + H) * np.cos(LAT)), H - err[2]])
    gm = gm_true + (err[15:18] if n > 15 else 0.0)
    return SimpleNamespace(
        pos=pos,
        v_n=err[VEL].copy(),
        R_nb=rotvec_to_dcm(err[ATT]) @ R_TRUE,
        b_a=np.zeros(3),
        b_g=B_TRUE - err[BG],
        gm=gm,
        P=np.eye(n),
        layout=StateLayout.build(
            [MarkovBlock(GNSS_ERROR, np.ones(3), np.ones(3))] if n > 15 else []
        ),
    )


def _check(dz, H, n, steps, atol):
    for j, eps in steps.items():
        e = np.zeros(n)
        e[j] = eps
        num = (dz(e) - dz(-e)) / (2 * eps)
        np.testing.assert_allclose(H[:, j], num, atol=atol, err_msg=f"column {j}")
    np.testing.assert_allclose(dz(np.zeros(n)), 0.0, atol=1e-9)


def test_zero_rate_jacobian_by_finite_differences():
    omega_mean = R_TRUE.T @ W_IE + B_TRUE  # what a still gyro reads
    dz = lambda e: zupt.zero_rate(_state(e), omega_mean, np.ones(3), W_IE).dz  # noqa: E731
    H = zupt.zero_rate(_state(np.zeros(15)), omega_mean, np.ones(3), W_IE).H
    _check(dz, H, 15, {**{j: 1e-4 for j in range(6, 9)}, **{j: 1e-6 for j in range(12, 15)}}, 1e-9)
    # Nothing else enters.
    assert np.all(H[:, 0:6] == 0) and np.all(H[:, BA] == 0)


def test_zero_velocity_jacobian_by_finite_differences():
    dz = lambda e: zupt.zero_velocity(_state(e), 0.02).dz  # noqa: E731
    H = zupt.zero_velocity(_state(np.zeros(15)), 0.02).H
    _check(dz, H, 15, {j: 1e-3 for j in range(3, 6)}, 1e-12)


def test_position_jacobian_with_gauss_markov_states():
    gm_true = np.array([1.5, -0.7, 2.2])
    lever = np.array([0.8, -0.3, -1.1])
    R_M, R_N = radii(LAT)
    ant = R_TRUE @ lever + gm_true  # the fix: antenna plus its correlated error
    fix = (LAT + ant[0] / (R_M + H), LON + ant[1] / ((R_N + H) * np.cos(LAT)), H - ant[2])

    def dz(e):
        return gnss_position.position(_state(e, 18, gm_true), *fix, np.ones(3), lever).dz

    H_ = gnss_position.position(_state(np.zeros(18), 18, gm_true), *fix, np.ones(3), lever).H
    _check(
        dz,
        H_,
        18,
        {
            **{j: 0.05 for j in range(3)},
            **{j: 1e-5 for j in range(6, 9)},
            **{j: 0.05 for j in range(15, 18)},
        },
        2e-5,
    )
    np.testing.assert_allclose(H_[:, 15:18], np.eye(3))


@pytest.mark.parametrize("n", [15, 18])
def test_position_jacobian_has_no_velocity_or_bias_columns(n):
    """A fix sees position, attitude (through the lever arm) and the GNSS error only: H_p's
    velocity and bias columns are exactly zero (finite differences cannot show an exact zero)."""
    lever = np.array([0.8, -0.3, -1.1])
    H_ = gnss_position.position(_state(np.zeros(n), n), LAT, LON, H, np.ones(3), lever).H
    assert H_.shape == (3, n)
    assert np.all(H_[:, VEL] == 0.0) and np.all(H_[:, BIASES] == 0.0)
    assert np.all(np.any(H_[:, POS] != 0.0, axis=0)) and np.all(np.any(H_[:, ATT] != 0.0, axis=0))


POSE = gtsam.Pose3(gtsam.Rot3(euler_to_dcm(0.1, -0.05, 0.9)), np.array([10.0, -4.0, 2.0]))


def _linearised(factor, values, dims):
    A, b = factor.linearize(values).jacobian()
    # Noise is whitened in linearize(): undo it with the factor's own sqrt-information.
    L = np.linalg.cholesky(np.linalg.inv(factor.noiseModel().covariance()))
    return np.linalg.solve(L.T, A), np.split(np.arange(sum(dims)), np.cumsum(dims)[:-1])


def test_gnss_gauss_markov_factor_jacobians_on_the_manifold():
    lever, g, p_fix = (
        np.array([0.5, 0.2, -1.0]),
        np.array([0.3, -1.2, 0.8]),
        np.array([9.0, -3.0, 1.5]),
    )
    f = gnss_position_gm_factor(X(0), G(0), p_fix, lever, np.array([0.5, 0.6, 0.9]))
    err = lambda pose, gg: pose.translation() + pose.rotation().matrix() @ lever + gg - p_fix  # noqa: E731
    values = gtsam.Values()
    values.insert(X(0), POSE)
    values.insert(G(0), g)
    A, cols = _linearised(f, values, (6, 3))
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        num = (err(POSE.retract(d), g) - err(POSE.retract(-d), g)) / 2e-6
        np.testing.assert_allclose(A[:, cols[0][k]], num, atol=1e-6)
    np.testing.assert_allclose(A[:, cols[1]], np.eye(3), atol=1e-12)


def test_gnss_gauss_markov_factor_residual_by_hand():
    """Yaw 90 deg (body x points east): R l_b = (-l_y, l_x, l_z) = (-0.5, 1.0, -0.2); the predicted fix
    is t + R l_b + g = (10 - 0.5 + 0.3, 20 + 1.0 - 0.4, -3 - 0.2 + 0.5) = (9.8, 20.6, -2.7)."""
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([10.0, 20.0, -3.0]))
    lever, g, p_fix, sigma = (
        np.array([1.0, 0.5, -0.2]),
        np.array([0.3, -0.4, 0.5]),
        np.array([9.0, 21.0, -2.0]),
        np.array([0.5, 0.4, 1.0]),
    )
    f = gnss_position_gm_factor(X(0), G(0), p_fix, lever, sigma)
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(G(0), g)
    e = np.array([0.8, -0.4, -0.7])
    np.testing.assert_allclose(f.unwhitenedError(values), e, atol=1e-12)
    np.testing.assert_allclose(f.whitenedError(values), e / sigma, atol=1e-12)
    assert f.error(values) == pytest.approx(0.5 * np.sum((e / sigma) ** 2), rel=1e-12)


def test_gauss_markov_transition_factor_is_the_exact_discretisation():
    tau, sigma, dt = np.array([60.0, 60.0, 30.0]), np.array([2.5, 2.5, 4.0]), 0.7
    f = gauss_markov_factor(G(0), G(1), dt, tau, sigma)
    a = np.exp(-dt / tau)
    sig = sigma * np.sqrt(1 - a**2)
    g0, g1 = np.array([1.0, 2.0, 3.0]), np.array([0.5, 1.0, 1.0])
    values = gtsam.Values()
    values.insert(G(0), g0)
    values.insert(G(1), g1)
    # Error at any values: half the squared whitened residual g1 - a g0 (the factor is exact, not
    # a linearisation around its own point).
    assert f.error(values) == pytest.approx(0.5 * np.sum(((g1 - a * g0) / sig) ** 2), rel=1e-12)
    A, b = f.linearize(values).jacobian()  # whitened
    np.testing.assert_allclose(A[:, :3] * sig[:, None], -np.diag(a), atol=1e-12)
    np.testing.assert_allclose(A[:, 3:] * sig[:, None], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(-b * sig, g1 - a * g0, atol=1e-12)


def test_gauss_markov_covariance_propagation_matches_its_closed_form():
    # A still IMU with no noise: the navigation block stays put, the GNSS error block follows
    # P(t) = a^2 P0 + sigma^2 (1 - a^2), a = exp(-t / tau), and its cross terms decay by a.
    n = 1001
    t = np.linspace(0.0, 10.0, n)
    f = np.tile([0.0, 0.0, -9.81], (n, 1))
    z3, seg = np.zeros(3), np.zeros(0, np.int64)
    tau, sigma = np.array([60.0, 30.0, 10.0]), np.array([2.0, 3.0, 4.0])
    prop = Propagator(
        t,
        f,
        np.zeros((n, 3)),
        z3,
        z3,
        z3,
        z3,
        (seg, seg, np.zeros((0, 3)), np.zeros((0, 3))),
        layout=StateLayout.build([MarkovBlock(GNSS_ERROR, tau, sigma)]),
    )
    P = np.eye(18)
    P[0:3, 15:18] = P[15:18, 0:3] = -0.5 * np.eye(3)
    s = SimpleNamespace(
        pos=np.array([LAT, LON, H]),
        v_n=z3.copy(),
        R_nb=np.eye(3),
        b_a=z3.copy(),
        b_g=z3.copy(),
        P=P,
    )
    prop.advance(s, 1, 0.0, 10.0)
    a = np.exp(-10.0 / tau)
    np.testing.assert_allclose(np.diag(s.P)[15:18], a**2 + sigma**2 * (1 - a**2), rtol=1e-9)
    np.testing.assert_allclose(np.diag(s.P[POS, 15:18]), -0.5 * a, rtol=1e-3)
    np.testing.assert_allclose(s.P, s.P.T, atol=1e-12)
