"""The window-consistent GNSS-acceleration factor (smoother-accw) and the factor-graph identity
of gnssacc.analysis.aiding_theory."""

import gtsam
import numpy as np
import pytest
from gnssacc.factors import window_accel_error, window_accel_factor
from gtsam.symbol_shorthand import X

from gnssacc.analysis.aiding_theory import FgChain, fg_departure, fg_draw, fg_posterior
from gnssacc.analysis.metrics import gnss_score, score
from gnssacc.core.config import load_config
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.estimators.aids.accel_model import acceleration_row
from gnssacc.estimators.layout import NODE_B, NODE_V, NODE_X, POS
from gnssacc.prepare.passes import run_smoother
from gnssacc.sources.sim import grade_config, simulate

POSES = [
    gtsam.Pose3(
        gtsam.Rot3(euler_to_dcm(0.1 * j, -0.2, 2.5 - 0.3 * j)), np.array([10.0 + 8 * j, -4.0, 1.0])
    )
    for j in range(3)
]
B_ROW = acceleration_row(np.array([0.0, 1.0, 2.2]))
A_N = np.array([0.3, -0.1, 0.05])


def _linearised(lever):
    """GTSAM's own linearisation of the factor (identity noise: unwhitened) and its error."""
    factor = window_accel_factor([X(j) for j in range(3)], B_ROW, A_N, lever, np.eye(3))
    values = gtsam.Values()
    for j, p in enumerate(POSES):
        values.insert(X(j), p)
    A, b = factor.linearize(values).jacobian()
    return A, -b, factor.unwhitenedError(values)


@pytest.mark.parametrize("lever", [np.zeros(3), np.array([0.8, -0.3, -1.2])])
def test_window_factor_jacobians_by_finite_differences_on_the_manifold(lever):
    A, err, raw = _linearised(lever)
    np.testing.assert_allclose(err, window_accel_error(POSES, B_ROW, lever, A_N), atol=1e-12)
    np.testing.assert_allclose(raw, err, atol=1e-12)
    eps = 1e-6
    for j in range(3):
        for k in range(6):
            d = np.zeros(6)
            d[k] = eps
            plus, minus = list(POSES), list(POSES)
            plus[j], minus[j] = POSES[j].retract(d), POSES[j].retract(-d)
            num = (
                window_accel_error(plus, B_ROW, lever, A_N)
                - window_accel_error(minus, B_ROW, lever, A_N)
            ) / (2 * eps)
            np.testing.assert_allclose(A[:, 6 * j + k], num, atol=1e-6)
    if not np.any(lever):
        assert np.all(
            A[:, [0, 1, 2, 6, 7, 8, 12, 13, 14]] == 0
        )  # no rotation dependence without a lever arm


def test_window_factor_is_zero_on_noise_free_fixes_of_any_motion():
    lever = np.array([0.8, -0.3, -1.2])
    p_ant = np.array([p.translation() + p.rotation().matrix() @ lever for p in POSES])
    assert np.allclose(window_accel_error(POSES, B_ROW, lever, B_ROW @ p_ant), 0.0, atol=1e-12)


def test_smoother_accw_runs_end_to_end_on_a_simulated_run():
    lever = (0.5, 0.2, -1.0)
    cfg = load_config(
        overrides={"imu": grade_config("industrial"), "gnss": {"lever_arm_b_m": list(lever)}}
    )
    run = simulate(
        "car", duration_s=120.0, imu_grade="industrial", noise="white", seed=0, lever_arm_b=lever
    )
    sols = run_smoother(run, cfg, "smoother-accw")
    ref = run_smoother(run, cfg, "smoother")["smoother"]
    sol = sols["smoother-accw"]
    assert set(sols) == {"smoother-accw", "smoother-accw-online"}
    assert sol.stats["n_acc_factors"] > 100
    assert np.all(np.isfinite(sol.sigma)) and np.all(sol.sigma[:, POS] > 0)
    prmse = score(run, sol).prmse_m
    assert prmse < gnss_score(run).prmse_m / 2 and prmse < 1.3 * score(run, ref).prmse_m
    # 3 m fixes at 1 Hz give 7 m/s^2 accelerations: little (double-counted) information, so the
    # sigmas stay close to position-only (not exactly below them: a different linearisation point).
    assert 0.8 < np.median(sol.sigma[:, 0]) / np.median(ref.sigma[:, 0]) < 1.02


def test_smoother_accw_recorded_covariances_equal_isam2_joint_marginals(monkeypatch):
    import gnssacc.estimators.smoother_graph as G

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("car", duration_s=40.0, imu_grade="industrial", noise="white", seed=4)
    worst, calls = [0.0], [0]
    orig = G.WindowSmoother.covariances

    def checked(self, nodes):
        covs = orig(self, nodes)
        for i, cov in zip(nodes, covs):
            keys = self.keys(i)
            ref = self.isam.getISAM2().jointMarginalCovariance(keys).fullMatrix()
            for sl in (NODE_X, NODE_V, NODE_B):  # the blocks it records
                C = cov[sl, sl]
                d = np.sqrt(np.diag(ref[sl, sl]))
                worst[0] = max(worst[0], float(np.max(np.abs(C - ref[sl, sl]) / np.outer(d, d))))
            calls[0] += 1
        return covs

    monkeypatch.setattr(G.WindowSmoother, "covariances", checked)
    sols = run_smoother(run, cfg, "smoother-accw")
    # every node online and fixed-lag; the last node is both at the end (one query)
    assert calls[0] == 2 * sols["smoother-accw"].stats["n_nodes"] - 1 and worst[0] < 1e-6, worst


CHAIN = FgChain(n=20, dt=1.0, q=(100 * 3.0) ** 2, r=3.0, P0=np.diag([100.0, 9.0, 1.0]))


@pytest.mark.parametrize("q", [1e-2, 1.0, CHAIN.q])
def test_correlated_joint_measurement_equals_position_only(q):
    m = FgChain(CHAIN.n, CHAIN.dt, q, CHAIN.r, CHAIN.P0)
    _, z = fg_draw(m, np.random.default_rng(1))
    mean_a, cov_a = fg_posterior(m, z, "position")
    mean_c, cov_c = fg_posterior(m, z, "joint")
    mean_b, cov_b = fg_posterior(m, z, "paper")
    scale = np.sqrt(np.outer(np.diag(cov_a), np.diag(cov_a)))
    np.testing.assert_allclose(mean_c, mean_a, atol=1e-9 * max(1.0, np.abs(mean_a).max()))
    np.testing.assert_allclose(cov_c / scale, cov_a / scale, atol=1e-9)
    assert np.abs(mean_b - mean_a).max() > 1e-3 and np.all(np.diag(cov_b) < np.diag(cov_a))


def _mc_nees(m, variant, draws, rng):
    """Mean NEES per dof over draws: all 3n states, and the n positions."""
    ip = np.arange(0, 3 * m.n, 3)
    full, pos = [], []
    for _ in range(draws):
        x, z = fg_draw(m, rng)
        mean, cov = fg_posterior(m, z, variant)
        e = (mean - x).ravel()
        full.append(e @ np.linalg.solve(cov, e) / e.size)
        pos.append(e[ip] @ np.linalg.solve(cov[np.ix_(ip, ip)], e[ip]) / m.n)
    return float(np.mean(full)), float(np.mean(pos))


def test_paper_factor_is_overconfident_over_monte_carlo_draws():
    rng = np.random.default_rng(7)
    a_full, a_pos = _mc_nees(CHAIN, "position", 250, rng)
    b_full, b_pos = _mc_nees(CHAIN, "paper", 250, rng)
    assert 0.8 < a_full < 1.2 and 0.8 < a_pos < 1.2, (a_full, a_pos)
    assert b_pos > 1.5 and b_full > 1.15, (b_full, b_pos)


def test_departure_closed_form_matches_monte_carlo_and_grows_with_process_noise():
    rows = {(r["ratio"], r["variant"]): r for r in fg_departure(ratios=(0.3, 100.0), n=CHAIN.n)}
    for ratio in (0.3, 100.0):
        a = rows[(ratio, "position")]
        assert abs(a["nees_per_dof"] - 1) < 1e-9 and abs(a["kl_from_position"]) < 1e-9
        assert np.allclose(a["var_ratio_pva"], 1.0, atol=1e-9)
    small, big = rows[(0.3, "paper")], rows[(100.0, "paper")]
    assert 0 < small["kl_from_position"] < big["kl_from_position"]
    assert np.all(big["var_ratio_pva"] < 1.0) and big["var_ratio_pva"][0] < 0.7
    _, b_pos = _mc_nees(CHAIN, "paper", 250, np.random.default_rng(3))
    assert abs(b_pos - big["nees_pos_per_dof"]) < 0.15, (b_pos, big["nees_pos_per_dof"])
