"""The paper's least-squares acceleration (A, B), its noise, and H_a / H_p by finite differences."""

import numpy as np
import pytest

from gnssacc.core.earth import radii
from gnssacc.core.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.estimators.state import FilterState
from gnssacc.estimators.aids.accel_model import (
    AccelWindow,
    H_a,
    H_a_blocks,
    acceleration_row,
    design_matrix,
    ls_acceleration,
    paper_H_a_blocks,
    predicted_acceleration,
)
from gnssacc.estimators.aids.gnss_position import position
from gnssacc.estimators.layout import ATT, POS


@pytest.mark.parametrize("dt", [1.0, 0.2, 0.1])
def test_B_uniform_three_fixes_is_second_difference(dt):
    t = 100.0 + dt * np.arange(3)
    np.testing.assert_allclose(acceleration_row(t), np.array([1.0, -2.0, 1.0]) / dt**2, rtol=1e-10)


def test_B_irregular_three_fixes_closed_form():
    t = np.array([10.0, 10.7, 12.1])
    h1, h2 = t[1] - t[0], t[2] - t[1]
    expected = 2.0 / (t[2] - t[0]) * np.array([1 / h1, -(1 / h1 + 1 / h2), 1 / h2])
    np.testing.assert_allclose(acceleration_row(t), expected, rtol=1e-10)


@pytest.mark.parametrize(
    "t",
    [
        np.arange(5) * 1.0,
        np.array([0.0, 0.9, 2.2, 2.9, 4.3, 5.0]),
        1e5 + np.array([0.0, 0.1, 0.2, 0.35]),
    ],
)
def test_B_is_exact_on_quadratics_for_any_m(t):
    B = acceleration_row(t)
    A = design_matrix(t)
    np.testing.assert_allclose(A[:, 0] @ B, 0.0, atol=1e-9 / (t[-1] - t[0]) ** 2)
    np.testing.assert_allclose(A[:, 1] @ B, 0.0, atol=1e-9 / (t[-1] - t[0]))
    np.testing.assert_allclose(A[:, 2] @ B, 1.0, rtol=1e-9)
    # Agrees with a generic least-squares solver.
    p = 3.0 + 2.0 * (t - t[0]) - 0.7 * (t - t[0]) ** 2
    assert B @ p == pytest.approx(np.linalg.lstsq(A, p, rcond=None)[0][2], rel=1e-9)
    assert B @ p == pytest.approx(-1.4, rel=1e-9)


def test_acceleration_covariance_matches_monte_carlo():
    rng = np.random.default_rng(0)
    t = np.array([0.0, 1.0, 2.1, 3.0])
    sig = np.array([[3.0, 3.0, 5.0], [2.0, 2.5, 4.0], [3.0, 3.0, 5.0], [1.0, 1.0, 2.0]])
    _, cov = ls_acceleration(t, np.zeros((4, 3)), sig)
    draws = np.array(
        [ls_acceleration(t, rng.standard_normal((4, 3)) * sig, sig)[0] for _ in range(20000)]
    )
    np.testing.assert_allclose(np.var(draws, axis=0), np.diag(cov), rtol=0.05)
    # Uniform 1 Hz, 3 fixes, sigma 3 m: sigma_a = 3 * sqrt(6).
    _, cov3 = ls_acceleration(np.arange(3.0), np.zeros((3, 3)), np.full((3, 3), 3.0))
    assert np.sqrt(cov3[0, 0]) == pytest.approx(3.0 * np.sqrt(6.0))


def test_window_fills_then_slides_and_resets_on_gaps():
    w = AccelWindow(m=3, max_gap_s=1.5)
    p = lambda t: np.array([0.5 * 0.3 * t**2, 2.0 * t, 0.0])
    s = np.ones(3)
    assert w.push(0.0, p(0.0), s) is None
    assert w.push(1.0, p(1.0), s) is None
    meas = w.push(2.0, p(2.0), s)
    np.testing.assert_allclose(meas.a_n, [0.3, 0.0, 0.0], atol=1e-12)
    assert meas.t == 2.0 and len(meas.t_window) == 3
    assert w.push(3.0, p(3.0), s) is not None
    # A 4 s gap empties the buffer: two more fixes give nothing, the third gives a measurement.
    assert w.push(7.0, p(7.0), s) is None
    assert w.push(8.0, p(8.0), s) is None
    assert w.push(9.0, p(9.0), s) is not None
    assert w.resets == 1
    fixed = AccelWindow(3, 1.5, sigma_override=np.array([0.5, 0.5, 1.0]))
    for t in (0.0, 1.0):
        fixed.push(t, p(t), s)
    np.testing.assert_allclose(fixed.push(2.0, p(2.0), s).cov, np.diag([0.25, 0.25, 1.0]))


def _a_pred_of_error(R_true, f_true, dphi, dba):
    """Predicted acceleration when the estimate carries errors dphi (n frame) and dba."""
    R_est = rotvec_to_dcm(dphi) @ R_true
    return predicted_acceleration(R_est, f_true + dba, np.zeros(3))


def test_H_a_by_finite_differences_against_the_nonlinear_model():
    R_true = euler_to_dcm(0.1, -0.2, 2.5)
    f_true = np.array([1.2, -0.4, -9.6])
    d_phi, d_ba = H_a_blocks(R_true, f_true)
    eps = 1e-6
    for i in range(3):
        e = np.zeros(3)
        e[i] = eps
        num_phi = (
            _a_pred_of_error(R_true, f_true, e, 0 * e) - _a_pred_of_error(R_true, f_true, -e, 0 * e)
        ) / (2 * eps)
        num_ba = (
            _a_pred_of_error(R_true, f_true, 0 * e, e) - _a_pred_of_error(R_true, f_true, 0 * e, -e)
        ) / (2 * eps)
        np.testing.assert_allclose(d_phi[:, i], num_phi, atol=1e-7)
        np.testing.assert_allclose(d_ba[:, i], num_ba, atol=1e-7)
    H = H_a(R_true, f_true)
    assert np.all(H[:, :6] == 0) and np.all(H[:, 12:] == 0)
    # For realistic errors the linearisation residual is bounded by the second-order terms
    # |phi|^2 |f| / 2 + |phi| |b_a| of the exact model.
    dphi, dba = np.radians([1.0, -0.5, 2.0]), np.array([0.5, -0.3, 0.2])
    lin = d_phi @ dphi + d_ba @ dba
    full = _a_pred_of_error(R_true, f_true, dphi, dba) - R_true @ f_true
    n_phi = np.linalg.norm(dphi)
    assert np.linalg.norm(full - lin) <= n_phi**2 * np.linalg.norm(
        f_true
    ) / 2 + n_phi * np.linalg.norm(dba)


def test_paper_H_a_maps_onto_ours():
    R = euler_to_dcm(-0.3, 0.25, -1.0)
    f = np.array([0.3, 2.0, -9.0])
    d_phi, d_ba = H_a_blocks(R, f)
    p_phi, p_ba = paper_H_a_blocks(R, f)
    # Paper: measured-minus-predicted w.r.t. a body-frame error phi_b = R^T phi.
    np.testing.assert_allclose(p_phi @ R.T, -d_phi, atol=1e-12)
    np.testing.assert_allclose(p_ba, -d_ba, atol=1e-12)


def test_H_p_with_lever_arm_by_finite_differences():
    lat, lon, h = np.radians(49.0), np.radians(8.4), 120.0
    R = euler_to_dcm(0.05, -0.02, 1.3)
    lever = np.array([1.2, -0.4, -1.5])
    R_M, R_N = radii(lat)

    def dz(err):
        s = FilterState(
            np.array(
                [lat + err[0] / (R_M + h), lon + err[1] / ((R_N + h) * np.cos(lat)), h - err[2]]
            ),
            np.zeros(3),
            rotvec_to_dcm(err[ATT]) @ R,
            np.zeros(3),
            np.zeros(3),
            np.eye(15),
        )
        # The measurement is the true antenna position (zero error).
        ant_n = R @ lever
        m_lat = lat + ant_n[0] / (R_M + h)
        m_lon = lon + ant_n[1] / ((R_N + h) * np.cos(lat))
        m = position(s, m_lat, m_lon, h - ant_n[2], np.ones(3), lever)
        return m.dz, m.H

    _, H = dz(np.zeros(15))
    eps = np.array([0.1] * 3 + [0.0] * 3 + [1e-5] * 3 + [0.0] * 6)
    for j in [0, 1, 2, 6, 7, 8]:
        e = np.zeros(15)
        e[j] = eps[j]
        num = (dz(e)[0] - dz(-e)[0]) / (2 * eps[j])
        np.testing.assert_allclose(H[:, j], num, atol=2e-6)
    np.testing.assert_allclose(H[:, POS], np.eye(3))
    np.testing.assert_allclose(dz(np.zeros(15))[0], 0.0, atol=1e-6)


@pytest.mark.parametrize("override", [None, np.array([0.1, 0.2, 0.3])])
def test_window_accelerations_equal_the_sliding_window(override):
    """The vectorised accelerations (the smoother's) equal AccelWindow's, gaps and resets included."""
    from gnssacc.estimators.aids.accel_model import AccelWindow, window_accelerations

    rng = np.random.default_rng(5)
    t = np.cumsum(rng.choice([0.2, 1.0, 1.0, 3.0], size=80))  # 3 s steps exceed the gap
    p = rng.normal(size=(80, 3)) * 5 + t[:, None] ** 2
    sig = rng.uniform(0.5, 3.0, size=(80, 3))
    full, a_n, var = window_accelerations(t, p, sig, 4, 2.5, override)
    w = AccelWindow(4, 2.5, override)
    n_full = 0
    for j in range(80):
        meas = w.push(t[j], p[j], sig[j])
        assert full[j] == (meas is not None)
        if meas is not None:
            n_full += 1
            np.testing.assert_allclose(a_n[j], meas.a_n, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(np.diag(var[j]), meas.cov, rtol=1e-12, atol=1e-15)
    assert 10 < n_full < 70 and w.resets > 3
