"""The GTSAM fixed-lag smoother and the GNSS-acceleration factor."""

import gtsam
import numpy as np
import pytest
from gnssacc.factors import accel_error, gnss_accel_factor, smoother_jacobians_from_H_a
from gtsam.symbol_shorthand import B, X
from stat_bounds import CALIBRATION, nis_band, paired_not_worse

from gnssacc.analysis.metrics import gnss_score, score
from gnssacc.core.config import load_config
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.prepare.passes import run_ekf
from gnssacc.estimators.aids.accel_model import H_a_blocks, paper_H_a_blocks
from gnssacc.estimators.smoother_graph import MIN_NODE_DT, node_times
from gnssacc.prepare.passes import run_smoother
from gnssacc.pipeline import with_outages
from gnssacc.sources.sim import grade_config, simulate
from gnssacc.estimators.layout import B_ACC, B_GYRO, POS, VEL, X_ROT, X_TRANS

POSE = gtsam.Pose3(gtsam.Rot3(euler_to_dcm(0.1, -0.2, 2.5)), np.array([10.0, -4.0, 1.0]))
BIAS = gtsam.imuBias.ConstantBias(np.array([0.05, -0.02, 0.1]), np.array([1e-3, -2e-3, 5e-4]))
F_B = np.array([1.2, -0.4, -9.6])
A_N = np.array([0.3, -0.1, 0.05])
G_N = np.array([0.0, 0.0, 9.81])


def _factor_jacobians(pose, bias):
    """Jacobians as GTSAM itself linearises the factor (identity noise, so unwhitened)."""
    factor = gnss_accel_factor(X(0), B(0), F_B, A_N, G_N, np.eye(3))
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(B(0), bias)
    lin = factor.linearize(values)
    A, b = lin.jacobian()
    return A[:, 0:6], A[:, 6:12], -b


def test_factor_jacobians_by_finite_differences_on_the_manifold():
    J_pose, J_bias, err = _factor_jacobians(POSE, BIAS)
    np.testing.assert_allclose(err, accel_error(POSE, BIAS, F_B, A_N, G_N), atol=1e-12)
    eps = 1e-6
    for k in range(6):
        d = np.zeros(6)
        d[k] = eps
        num = (
            accel_error(POSE.retract(d), BIAS, F_B, A_N, G_N)
            - accel_error(POSE.retract(-d), BIAS, F_B, A_N, G_N)
        ) / (2 * eps)
        np.testing.assert_allclose(J_pose[:, k], num, atol=1e-6)
        num_b = (
            accel_error(POSE, BIAS.retract(d), F_B, A_N, G_N)
            - accel_error(POSE, BIAS.retract(-d), F_B, A_N, G_N)
        ) / (2 * eps)
        np.testing.assert_allclose(J_bias[:, k], num_b, atol=1e-6)
    assert np.all(J_pose[:, X_TRANS] == 0) and np.all(J_bias[:, B_GYRO] == 0)


def test_factor_jacobians_equal_the_ekf_H_a_under_the_convention_mapping():
    R = POSE.rotation().matrix()
    f = F_B - BIAS.accelerometer()
    J_pose, J_bias, _ = _factor_jacobians(POSE, BIAS)
    H_phi, H_ba = H_a_blocks(R, f)
    # xi = -R^T phi (right perturbation vs. n-frame estimate-minus-truth), db_a = b_a residual:
    np.testing.assert_allclose(J_pose[:, X_ROT] @ R.T, H_phi, atol=1e-12)
    np.testing.assert_allclose(-J_bias[:, B_ACC], H_ba, atol=1e-12)
    # and with the paper's printed form (body-frame phi, measured-minus-predicted): J_xi = -(paper).
    p_phi, p_ba = paper_H_a_blocks(R, f)
    np.testing.assert_allclose(J_pose[:, X_ROT], -p_phi, atol=1e-12)
    np.testing.assert_allclose(J_bias[:, B_ACC], p_ba, atol=1e-12)
    np.testing.assert_allclose(smoother_jacobians_from_H_a(R, f)[0], J_pose, atol=1e-12)


@pytest.mark.parametrize("rate", [0.05, 0.3, 40.0])  # half-angles below and above 1e-3 rad
def test_half_interval_rotations_are_the_exponential_and_scipys(rate):
    """The compiled rotations are ``Exp(omega dt / 2)`` (Rodrigues' formula, independently) and
    the numbers scipy's ``Rotation`` gave the preintegration before them (its Taylor branch below
    1e-3 rad, ``sin`` above); the specific force they turn, as scipy turned it."""
    from scipy.spatial.transform import Rotation

    from gnssacc.core.rotations import rotvec_to_dcm
    from gnssacc.estimators.mechanization import half_interval_rotations
    from gnssacc.estimators.smoother_graph import mid_interval_force

    rng = np.random.default_rng(3)
    omega = rate * rng.normal(size=(50, 3))
    dt = rng.uniform(0.004, 0.012, 50)
    R = half_interval_rotations(omega, dt)
    for k in range(50):
        np.testing.assert_allclose(R[k], rotvec_to_dcm(0.5 * omega[k] * dt[k]), atol=2e-16)
    ref = Rotation.from_rotvec(0.5 * omega * dt[:, None])
    np.testing.assert_allclose(R, ref.as_matrix(), rtol=0.0, atol=1e-16)
    f = rng.normal(size=(50, 3)) * 10.0
    np.testing.assert_allclose(mid_interval_force(f, omega, dt), ref.apply(f), rtol=0, atol=1e-14)
    one = Rotation.from_rotvec(0.5 * omega[:1] * dt[:1, None]).apply(f[:1])  # scipy's own path
    np.testing.assert_array_equal(mid_interval_force(f[:1], omega[:1], dt[:1]), one)


def test_turning_the_samples_does_not_import_scipy_spatial():
    """The smoother turns its samples (one and several) without ``scipy.spatial``, which a run
    would otherwise import for it (0.1-0.4 s with ``scipy.sparse`` and ``scipy.special``; issue
    35); a fresh interpreter, so that no other test's import counts."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "import gnssacc.estimators.smoother\n"
        "from gnssacc.estimators.smoother_graph import mid_interval_force\n"
        "for n in (1, 2):\n"
        "    mid_interval_force(np.ones((n, 3)), np.ones((n, 3)), np.full(n, 0.01))\n"
        "print('scipy.spatial' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False"]


def test_bias_inserted_by_name_reads_back():
    from gnssacc.estimators.smoother_graph import insert_bias

    values = gtsam.Values()
    insert_bias(values, B(4), BIAS)
    assert values.atConstantBias(B(4)).equals(BIAS, 0.0)
    with pytest.raises(RuntimeError):  # a key already there, as a positional insert refuses it
        insert_bias(values, B(4), BIAS)


def test_preintegration_reproduces_a_perfect_imu_in_turns():
    """Each IMU sample is the interval's mean specific force in the body frame at the interval's
    middle (the simulator's and the EKF mechanization's convention). GTSAM rotates a sample with the
    attitude at the interval's start, which on a 30 m circle at 10 m/s (100 Hz) made a spurious
    along-track acceleration v omega^2 dt / 2 = 5.5 mm/s^2: 5.5 mm/s of velocity error per second
    between nodes, a bias the smoother's marginals did not cover. Over one second from the true
    state, the predicted velocity is now right to the terms the smoother's tangent-plane model
    leaves out (earth curvature v^2 / R ~ 2e-5 m/s^2)."""
    from gnssacc.core.earth import earth_rate_n, normal_gravity
    from gnssacc.estimators.settings import SmootherSettings
    from gnssacc.estimators.smoother_graph import ImuModel, preintegrate

    run = simulate("turns", 40.0, imu_grade="perfect", noise="none", seed=0, truth_rate_hz=100.0)
    tr, imu, o = run.truth, run.imu, run.origin
    model = ImuModel(
        SmootherSettings.from_config(load_config()),
        normal_gravity(o.lat0, o.h0),
        earth_rate_n(o.lat0),
    )
    bias = gtsam.imuBias.ConstantBias()
    dt_all = np.diff(imu.t, prepend=imu.t[0])
    for t0 in (15.0, 31.0):  # the left circle, the right circle
        i0, i1 = (int(np.argmin(np.abs(tr.t - t))) for t in (t0, t0 + 1.0))
        j0 = int(np.searchsorted(imu.t, t0, side="right"))
        k1 = int(np.searchsorted(imu.t, t0 + 1.0, side="left")) + 1
        pim = preintegrate(imu, model, bias, t0, t0 + 1.0, j0, k1, (None, None), dt_all)
        start = gtsam.NavState(
            gtsam.Pose3(
                gtsam.Rot3(euler_to_dcm(*tr.rpy[i0])), o.to_ned(tr.lat[i0], tr.lon[i0], tr.h[i0])
            ),
            tr.v_n[i0],
        )
        nav = pim.predict(start, bias)
        assert np.linalg.norm(nav.velocity() - tr.v_n[i1]) < 1e-4, nav.velocity() - tr.v_n[i1]
        assert np.linalg.norm(nav.position() - o.to_ned(tr.lat[i1], tr.lon[i1], tr.h[i1])) < 5e-4


def test_node_times_merge_duplicates_and_fill_gaps():
    gnss_t = np.array([1.0, 2.0, 2.0 + MIN_NODE_DT / 2, 3.0, 10.0, 10.0, 11.0])
    t = node_times(0.5, 14.0, gnss_t, max_spacing=1.0)
    assert np.all(np.diff(t) >= MIN_NODE_DT)
    assert np.all(np.diff(t) <= 1.0 + 1e-9)
    for tg in (1.0, 2.0, 3.0, 10.0, 11.0):
        assert np.min(np.abs(t - tg)) < 1e-12
    assert t[0] == 0.5 and t[-1] == 14.0


@pytest.fixture(scope="module")
def sim_results():
    cfg = load_config(overrides={"imu": grade_config("industrial")})
    out = []
    for seed in (0, 1):
        run = simulate("car", duration_s=240.0, imu_grade="industrial", noise="white", seed=seed)
        sols = run_smoother(run, cfg, "smoother")
        sols.update(run_smoother(run, cfg, "smoother-acc"))
        sols["ekf"] = run_ekf(run, cfg, "ekf")
        out.append((run, sols))
    return out


def test_smoother_beats_ekf_on_simulated_runs(sim_results):
    for run, sols in sim_results:
        ekf = score(run, sols["ekf"]).prmse_m
        fixed = score(run, sols["smoother"]).prmse_m
        online = score(run, sols["smoother-online"]).prmse_m
        assert fixed < 0.9 * ekf, (fixed, ekf)
        assert online < 1.15 * ekf, (online, ekf)
        assert fixed < gnss_score(run).prmse_m / 2
        assert sols["smoother-acc"].stats["n_acc_factors"] > 200


def test_smoothing_claims_less_uncertainty_than_the_online_estimate(sim_results):
    """Whether the marginals are right is tested where a band can be derived, with the smoother's
    model equal to the truth over 100 runs (test_consistency_mc.py); here only that the fixed-lag
    estimate, which has seen a lag more of fixes, states a smaller sigma than the online one."""
    for _, sols in sim_results:
        assert np.median(sols["smoother"].sigma[:-20, 0]) < np.median(
            sols["smoother-online"].sigma[:-20, 0]
        )


def test_ill_posed_updates_are_recovered_and_counted():
    """Cholesky with a stiff bias random walk is the ill-posed case that crashes GTSAM's own
    KITTI GPS example; the run must finish, count it and stay accurate."""
    base = grade_config("tactical")
    cfg_qr = load_config(overrides={"imu": base})
    cfg_chol = load_config(overrides={"imu": base, "smoother": {"factorization": "CHOLESKY"}})
    run = simulate("car", duration_s=120.0, imu_grade="tactical", noise="white", seed=3)
    ref = run_smoother(run, cfg_qr, "smoother")["smoother"]
    sol = run_smoother(run, cfg_chol, "smoother")["smoother"]
    assert sol.stats["n_ill_posed_recovered"] >= 1 and sol.stats["factorization_switched_to_qr"]
    assert score(run, sol).prmse_m < 1.2 * score(run, ref).prmse_m
    assert np.all(np.isfinite(sol.sigma))


@pytest.mark.parametrize("method, dropped", [("smoother", 0), ("smoother-accw", 2)])
def test_injected_failure_mid_run_is_recovered(monkeypatch, method, dropped):
    """Two ill-posed updates are recovered by a restart; a restart keeps nodes i-1 and i only, so
    ``smoother-accw`` drops (and counts) its window factor on node i-2 each time. The abandoned
    window's nodes keep its smoothed estimates: 1.08-1.23x the uninterrupted PRMSE at lags 10
    and 20 s (seeds 2, 3), where their online estimates gave 1.18-1.61x."""
    import gnssacc.estimators.smoother_graph as S

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("car", duration_s=90.0, imu_grade="industrial", noise="white", seed=2)
    ref = run_smoother(run, cfg, method)[method]
    calls = {"n": 0}
    real_update = S.WindowSmoother.update

    def flaky(self, graph, values, stamps):
        calls["n"] += 1
        if calls["n"] in (20, 50):
            raise RuntimeError("Indeterminant linear system detected while working near variable x")
        return real_update(self, graph, values, stamps)

    monkeypatch.setattr(S.WindowSmoother, "update", flaky)
    sol = run_smoother(run, cfg, method)[method]
    assert sol.stats["n_ill_posed_recovered"] == 2
    assert sol.stats.get("n_factors_dropped_at_restart", 0) == dropped
    assert len(sol) == len(ref) and np.all(np.isfinite(sol.sigma))
    assert score(run, sol).prmse_m < 1.35 * score(run, ref).prmse_m


def test_long_outage_and_imu_gap_do_not_break_the_graph():
    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("car", duration_s=200.0, imu_grade="industrial", noise="white", seed=4)
    # A 2 s hole in the IMU inside a 60 s GNSS outage: nodes there have neither GNSS nor IMU
    # samples of their own (the sample closing the hole is held over it).
    t0 = run.t_start
    keep = ~((run.imu.t > t0 + 100.0) & (run.imu.t < t0 + 102.0))
    run = run.__class__(**{**run.__dict__, "imu": run.imu.select(keep)})
    run = with_outages(run, "80:60", None)
    sols = run_smoother(run, cfg, "smoother")
    fixed = sols["smoother"]
    assert np.all(np.isfinite(fixed.sigma)) and np.all(np.isfinite(fixed.lat))
    in_gap = (fixed.t - t0 > 80) & (fixed.t - t0 < 140)
    assert in_gap.sum() >= 55  # fill nodes at <= 1 s spacing
    # Uncertainty grows through the outage and collapses after it.
    assert fixed.sigma[in_gap, 0].max() > 3 * fixed.sigma[~in_gap, 0].min()
    sc = score(run, fixed)
    assert sc.prmse_m < 200.0 and np.isfinite(sc.prmse_outage_m)


def test_kitti_integration():
    from gnssacc.pipeline import load_source

    # The IMU-and-GNSS model (no non-holonomic constraint), where these ratios were measured.
    cfg = load_config("kitti", overrides={"nhc": {"enabled": False}})
    # Seed 7: the kitti preset was tuned on seeds 0-2. Over seeds 0, 3-6, 8, 9 the fixed-lag PRMSE
    # was 0.47-0.59 of the EKF's (sd 0.04) and the online one 0.99-1.02: the bounds 0.75 and 1.15
    # are four standard deviations or more away, not just inside what was measured.
    run = load_source("kitti", cfg, noise="white", seed=7)
    ekf = score(run, run_ekf(run, cfg, "ekf")).prmse_m
    sols = run_smoother(run, cfg, "smoother-acc")
    fixed, online = (
        score(run, sols["smoother-acc"]).prmse_m,
        score(run, sols["smoother-acc-online"]).prmse_m,
    )
    assert fixed < 0.75 * ekf, (fixed, ekf)
    assert online < 1.15 * ekf, (online, ekf)
    assert sols["smoother-acc"].stats["n_acc_factors"] > 400


def test_imu_still_cruise_in_an_outage_gets_no_zero_velocity_factor():
    """KITTI with a 10 s outage from 90 s: the car cruises IMU-still there. The stationary
    detector refuses the stretch by the fixes around the outage, carried to it by the IMU (step
    4b). Without that step (``link_reach_s = 0``) it keeps it, unchecked, and a zero-velocity
    factor on a car at ~10 m/s dragged the smoother 100 m off (online) with a 1 m sigma: the
    velocity predicted for the node rejects it, as the EKF's gate does."""
    import gnssacc

    # IMU-only through the outage (no non-holonomic constraint), as the ratios below were measured.
    common = dict(methods=["ekf", "smoother"], tune="none", outage="90:10", seed=7)
    no_nhc = {"nhc": {"enabled": False}}
    res = gnssacc.process("kitti", **common, config=no_nhc)
    t0, refused = res.run.imu.t[0], res.prepared.stationary.rejected
    assert any(
        "carried by the IMU" in r["why"] and 90.0 <= r["t_start"] - t0 and r["t_end"] - t0 <= 100.0
        for r in refused
    ), refused
    assert res.solutions["smoother"].stats["n_zupt_factors"] == 0
    res = gnssacc.process("kitti", **common, config={**no_nhc, "stationary": {"link_reach_s": 0}})
    stats = res.solutions["smoother"].stats
    assert stats["n_zupt_gated"] >= 1
    prmse = res.prmse()
    assert (
        prmse["smoother"] < 0.75 * prmse["ekf"] and prmse["smoother-online"] < 1.15 * prmse["ekf"]
    ), prmse
    for m in ("smoother", "smoother-online"):
        # The residual chi-square of a fix the estimate has used has fewer than 3 dof (here about
        # 3 (1 - (sigma_est / sigma_fix)^2) ~ 2.4); 1 dof per fix gives a band wider than the true
        # one at 1e-3, then widened by the preset's claimed calibration.
        st = res.metrics["methods"][m]["stats"]
        lo, hi = nis_band(res.solutions[m].stats["n_pos_updates"], 1, None, CALIBRATION)
        assert lo < st["nis_pos_mean"] < hi, (m, lo, st["nis_pos_mean"], hi)


def test_true_stops_keep_their_zero_velocity_factors():
    """A slow UGV that stops (fixes checking the stops): the gate lets the stops through."""
    import gnssacc

    run = simulate("ugv-slow", duration_s=240.0, imu_grade="consumer", noise="white", seed=2)
    res = gnssacc.process(run, methods=["smoother"], tune="none")
    stats = res.solutions["smoother"].stats
    assert (
        stats["n_zupt_factors"] > 10 and stats["n_zupt_gated"] <= 0.05 * stats["n_zupt_factors"]
    ), stats


def _gm_exact_model_errors(seeds=range(12)):
    """``ekf-gm`` and ``smoother-gm`` on a slow UGV whose models match the data: the IMU has only
    the kinds of error the estimators model (``industrial-basic``: white noise, turn-on bias, bias
    drift; no vibration, scale-factor or cross-axis error), with its own parameters under
    ``tune="none"``, and the fixes the Gauss-Markov error the ``-gm`` methods model (the ``gm``
    profile's own parameters). Per seed and method: position and
    velocity RMSE [m, m/s] over the output epochs after the first 10 s."""
    import gnssacc
    from gnssacc.analysis.observability import state_errors

    rms = lambda e: float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    out = []
    for seed in seeds:
        run = simulate("ugv", duration_s=180.0, imu_grade="industrial-basic", noise="gm", seed=seed)
        res = gnssacc.process(run, methods=["ekf-gm", "smoother-gm"], tune="none")
        row = {}
        for m, sol in res.solutions.items():
            e = state_errors(res.run, sol)[sol.t >= sol.t[0] + 10.0]
            row[m] = (rms(e[:, POS]), rms(e[:, VEL]))
        out.append(row)
    return out


@pytest.mark.slow
def test_fixed_lag_smoother_is_no_worse_than_the_ekf_under_gauss_markov_fixes():
    """Same models and tuning: the fixed-lag estimate uses 10 s more fixes than the filter, so on
    average it is at least as good, and the online estimate is the filter's. Under fixes whose
    error is correlated for 60 s the gain in position is small (the window's fixes share most of
    their error; seeds 12-35: -6.9 %, better on all 24), in velocity large (ratio 0.33-0.59).

    Bounds at a false-failure rate of 1e-3 each, on seeds 40-51 (used for nothing else), from the
    paired per-seed differences (one-sided Student t with 11 dof): position not significantly
    worse than the EKF's; velocity error at most 0.7 of the EKF's at the upper confidence bound;
    online within 2 % of the EKF (a stated equivalence margin: the two differ only in
    linearisation) at the confidence bound."""
    rows = _gm_exact_model_errors(range(40, 52))
    fixed, online, ekf = (
        np.array([r[m][0] for r in rows]) for m in ("smoother-gm", "smoother-gm-online", "ekf-gm")
    )
    mean, bound = paired_not_worse(fixed, ekf)
    assert mean < bound, (fixed, ekf)
    v_ratio = np.array([r["smoother-gm"][1] / r["ekf-gm"][1] for r in rows])
    mean, bound = paired_not_worse(v_ratio, np.full_like(v_ratio, 0.7))
    assert mean + bound < 0.0, v_ratio
    mean, bound = paired_not_worse(online, ekf)
    assert abs(mean) + bound < 0.02, (online, ekf)
