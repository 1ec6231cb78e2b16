"""The window-consistent acceleration prediction (``ekf-accw``): Peano kernel against closed forms
and quadrature, kernel integrals against an exact rotation, H_w by finite differences, the model
error on noise-free simulated data, and the filter end to end."""

import numpy as np
import pytest
from scipy.integrate import quad
from stat_bounds import CALIBRATION, nis_band

from gnssacc.core.config import load_config
from gnssacc.core.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.estimators.state import FilterState
from gnssacc.prepare.passes import run_ekf
from gnssacc.estimators.aids.accel_model import (
    acceleration_row,
    model_errors,
    peano_kernel,
    window_samples,
)
from gnssacc.estimators.aids.gnss_accel import window_acceleration
from gnssacc.estimators.mechanization import kernel_force_integrals
from gnssacc.sources.sim import grade_config, simulate
from gnssacc.estimators.layout import ATT, BA, BG

WINDOWS = [
    100.0 + np.arange(3.0),
    5.0 + 0.2 * np.arange(3.0),
    np.array([10.0, 10.7, 12.1]),
    np.array([0.0, 0.9, 2.2, 2.9, 4.3]),
]


@pytest.mark.parametrize("dt", [1.0, 0.2])
def test_kernel_of_three_uniform_fixes_is_the_triangle(dt):
    t = 3.0 + dt * np.arange(3)
    s = np.linspace(t[0] - 0.5, t[2] + 0.5, 401)
    tri = np.where((s >= t[0]) & (s <= t[2]), (dt - np.abs(s - t[1])) / dt**2, 0.0)
    np.testing.assert_allclose(peano_kernel(t, s), tri, atol=1e-12 / dt**2)


@pytest.mark.parametrize("t", WINDOWS)
def test_kernel_integrates_to_one_and_reproduces_B(t):
    """int K = 1, and B p = int K p'' for a cubic and a sinusoid (quadrature, kinks at the fixes)."""
    K = lambda s: float(peano_kernel(t, s))
    pieces = lambda f: sum(
        quad(f, a, b, epsabs=1e-13, epsrel=1e-13)[0] for a, b in zip(t[:-1], t[1:])
    )
    assert pieces(K) == pytest.approx(1.0, abs=1e-12)
    B = acceleration_row(t)
    for p, pdd in [
        (lambda x: 0.3 * x**3 - 2.0 * x**2 + x, lambda x: 1.8 * x - 4.0),
        (lambda x: 5.0 * np.sin(1.3 * x + 0.4), lambda x: -5.0 * 1.69 * np.sin(1.3 * x + 0.4)),
    ]:
        assert B @ p(t) == pytest.approx(pieces(lambda s: K(s) * pdd(s)), abs=1e-9)  # noqa: B023 (called within the iteration)


@pytest.mark.parametrize("t", WINDOWS)
def test_sample_weights_are_exact_for_piecewise_constant_acceleration(t):
    """Samples holding over (t[i-1], t[i]] with constant acceleration a_i: B p = sum_i w_i a_i exactly,
    p integrated in closed form; the weights tile the window (sum 1) and cover it (nothing outside)."""
    rng = np.random.default_rng(1)
    t_imu = np.sort(
        np.concatenate([[t[0] - 0.35], rng.uniform(t[0] - 0.3, t[-1] + 0.3, 57), [t[-1] + 0.5]])
    )
    a = rng.normal(0.0, 2.0, len(t_imu))  # a[i] holds over (t_imu[i-1], t_imu[i]]
    k0, k1, h, w = window_samples(t_imu, t)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    assert h.sum() == pytest.approx(t[-1] - t[0], abs=1e-12)

    def p(x):
        # Exact double integral of the piecewise-constant acceleration from t_imu[0].
        vel, total = 0.0, 0.0
        for i in range(1, len(t_imu)):
            dt = min(x, t_imu[i]) - t_imu[i - 1]
            if dt <= 0:
                break
            total += vel * dt + 0.5 * a[i] * dt * dt
            vel += a[i] * dt
        return total

    assert acceleration_row(t) @ np.array([p(x) for x in t]) == pytest.approx(
        w @ a[k0:k1], abs=1e-10
    )
    assert window_samples(t_imu[t_imu > t[0]], t) is None  # the IMU starts inside the window
    assert window_samples(t_imu[t_imu < t[-1]], t) is None  # or ends inside it


def test_kernel_integrals_against_a_constant_rotation():
    """Constant body rate and body specific force: R_{b_k b_s} = Exp(-omega (t_k - s)), so
    F = int K Exp(-omega (t_k - s)) ds f, by quadrature (midpoint rule per 100 Hz sample: 1e-5)."""
    t = np.array([0.0, 1.0, 2.0])
    t_imu = np.arange(-0.5, 2.6, 0.01)
    omega = np.array([0.1, -0.2, 0.6])
    f = np.array([1.5, -0.5, -9.8])
    k0, k1, h, w = window_samples(t_imu, t)
    n = k1 - k0
    F, M, _ = kernel_force_integrals(
        np.tile(f, (n, 1)), np.tile(omega, (n, 1)), h, w, np.zeros(3), np.zeros(3)
    )
    M_ref = np.zeros((3, 3))
    for r in range(3):
        for c in range(3):
            g = lambda s: float(peano_kernel(t, s)) * rotvec_to_dcm(-omega * (t[-1] - s))[r, c]  # noqa: B023 (called within the iteration)
            M_ref[r, c] = quad(g, 0.0, 1.0)[0] + quad(g, 1.0, 2.0)[0]
    np.testing.assert_allclose(M, M_ref, atol=2e-5)
    np.testing.assert_allclose(F, M_ref @ f, atol=2e-4)


def _window_dz(R_nb, b_a_hat, b_g_hat, f_raw, w_raw, h, w, a_meas, g_n):
    s = FilterState(np.array([0.8, 0.1, 50.0]), np.zeros(3), R_nb, b_a_hat, b_g_hat, np.eye(15))
    F, M, G = kernel_force_integrals(f_raw, w_raw, h, w, b_a_hat, b_g_hat)
    return window_acceleration(s, a_meas, np.eye(3), F, M, G, g_n)


def test_H_w_by_finite_differences():
    """dz(error) - dz(0) against H_w for every error-state component: phi in n (R_est = Exp(phi) R),
    bias residuals (b_hat = b - db); position and velocity blocks are zero."""
    rng = np.random.default_rng(3)
    t = np.array([0.0, 0.9, 2.1])
    t_imu = np.arange(-0.2, 2.3, 0.01)
    k0, k1, h, w = window_samples(t_imu, t)
    n = k1 - k0
    f_raw = np.array([0.8, -0.3, -9.7]) + rng.normal(0, 0.5, (n, 3))
    w_raw = np.array([0.05, -0.1, 0.4]) + rng.normal(0, 0.1, (n, 3))
    R = euler_to_dcm(0.1, -0.15, 2.2)
    b_a, b_g = np.array([0.05, -0.02, 0.1]), np.array([1e-3, -2e-3, 5e-4])
    g_n = np.array([0.0, 0.0, 9.8])
    args = (f_raw, w_raw, h, w, np.array([0.3, -0.2, 0.1]), g_n)
    m0 = _window_dz(R, b_a, b_g, *args)
    assert np.all(m0.H[:, :6] == 0.0)
    eps = 1e-6
    for j in range(6, 15):
        e = np.zeros(15)
        e[j] = eps
        dz = [
            _window_dz(rotvec_to_dcm(x[ATT]) @ R, b_a - x[BA], b_g - x[BG], *args).dz
            for x in (e, -e)
        ]
        num = (dz[0] - dz[1]) / (2 * eps)
        # phi and b_a blocks are exact; the b_g block integrates Gamma by the midpoint rule per
        # sample and drops J_r(omega h): relative error O((omega h)^2), 1e-5 at 100 Hz here.
        rel = 1e-8 if j < 12 else 1e-4
        np.testing.assert_allclose(m0.H[:, j], num, atol=rel * np.abs(num).max())
    # The gyro-bias block is the smallest but not negligible over 2 s: ~ |f| T^2 / 2.
    assert 1.0 < np.abs(m0.H[:, BG]).max() < 30.0


def test_window_model_error_is_far_below_the_paper_model_on_noise_free_data():
    run = simulate("car", 300.0, imu_grade="perfect", noise="none")
    _, e_paper, e_window = model_errors(run)
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e * e, axis=1))))
    paper, window = rms(e_paper), rms(e_window)
    assert len(e_paper) > 290
    print(
        f"model error RMS on noise-free fixes, perfect IMU: paper {paper:.4f} m/s^2, window {window:.4f} m/s^2"
    )
    assert window < 0.2 * paper
    assert window < 0.01


# The fixed sigma equal to the propagated one of 1 Hz fixes with 3/3/5 m noise, sqrt(6) x.
@pytest.mark.parametrize("sigma", [None, [7.35, 7.35, 12.25]])
def test_ekf_accw_runs_end_to_end_with_finite_nis(sigma):
    """On a simulated car run (industrial IMU, white 3 m fixes): every window gives an update, NIS
    finite and of order one, better than the raw fixes; a fixed [accel] sigma_mps2 is used as given."""
    over = {"imu": grade_config("industrial")}
    if sigma is not None:
        over["accel"] = {"sigma_mps2": sigma}
    cfg = load_config(overrides=over)
    run = simulate("car", duration_s=200.0, imu_grade="industrial", noise="white", seed=2)
    sol = run_ekf(run, cfg, "ekf-accw", record_innovations=True)
    st = sol.stats
    assert st["n_acc_updates"] >= st["n_pos_updates"] - 5
    assert np.all(np.isfinite(st["nis_acc"])) and np.isfinite(st["nis_pos_mean"])
    # Chi-square bands of the updates (their autocorrelation counted: overlapping windows make the
    # acceleration innovations' lag-1 autocorrelation about -2/3), widened by the stated calibration
    # of a datasheet model on an IMU with unmodelled errors; seed 2 chose nothing.
    for kind in ("acc", "pos"):
        lo, hi = nis_band(st[f"n_{kind}_updates"], 3, st[f"acf1_{kind}"], CALIBRATION)
        assert lo < st[f"nis_{kind}_mean"] < hi, (kind, lo, st[f"nis_{kind}_mean"], hi)
    from gnssacc.analysis.metrics import gnss_score, score

    assert score(run, sol).prmse_m < gnss_score(run).prmse_m


def test_windows_touching_a_suspect_imu_span_are_skipped():
    """A window whose IMU samples touch a flagged span gives no update; the others still do."""
    from gnssacc.checks.quality import QualityReport, Span, touches_segments

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("car", duration_s=120.0, imu_grade="industrial", noise="white", seed=1)
    i0, i1 = 5000, 5150
    flagged = QualityReport(
        [Span("interpolated", run.imu.t[i0], run.imu.t[i1 - 1], i0, i1, "all", "test")],
        len(run.imu),
        0.01,
        0.01,
    )
    sol = run_ekf(run, cfg, "ekf-accw", quality=flagged)
    t = run.gnss.t
    seg0, seg1 = np.array([i0]), np.array([i1])
    expected = sum(
        touches_segments(*window_samples(run.imu.t, t[j - 2 : j + 1])[:2], seg0, seg1)
        for j in range(2, len(t))
        if t[j] >= sol.stats["t_init"]
    )
    assert expected >= 2
    assert sol.stats["n_acc_skipped_suspect_imu"] == expected


def test_H_w_reduces_to_the_paper_H_a_without_rotation():
    """No rotation over the window and a constant specific force: F_b = f, M = I, and H_w's
    attitude and accelerometer-bias blocks are the paper's H_a (same sign convention)."""
    from gnssacc.estimators.aids.accel_model import H_a_blocks, H_w_blocks

    t_imu = np.arange(-0.1, 2.2, 0.01)
    k0, k1, h, w = window_samples(t_imu, np.array([0.0, 1.0, 2.0]))
    n = k1 - k0
    f = np.array([0.7, -0.2, -9.8])
    b_a = np.array([0.01, 0.02, -0.03])
    F, M, G = kernel_force_integrals(np.tile(f, (n, 1)), np.zeros((n, 3)), h, w, b_a, np.zeros(3))
    np.testing.assert_allclose(F, f - b_a, atol=1e-12)
    np.testing.assert_allclose(M, np.eye(3), atol=1e-12)
    R = euler_to_dcm(0.2, 0.1, -1.0)
    for blk_w, blk_a in zip(H_w_blocks(R, F, M, G)[:2], H_a_blocks(R, f - b_a)):
        np.testing.assert_allclose(blk_w, blk_a, atol=1e-12)
