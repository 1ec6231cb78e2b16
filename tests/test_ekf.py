"""Mechanization and EKF against simulated runs with known truth, and the KITTI integration test."""

from types import SimpleNamespace

import numpy as np
import pytest
from stat_bounds import CALIBRATION, gnss_prmse_band, nis_band

from gnssacc.analysis.metrics import gnss_score, score
from gnssacc.core import earth
from gnssacc.core.config import load_config
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.estimators import mechanization as mech
from gnssacc.prepare.passes import run_ekf
from gnssacc.sources.sim import grade_config, simulate


def _free_inertial(run, duration_s, b_a=np.zeros(3), b_g=np.zeros(3)):  # noqa: B008 (never mutated)
    """Integrate the run's IMU from the true initial state, no updates; return NED drift [m]."""
    tr = run.truth
    pos = np.array([tr.lat[0], tr.lon[0], tr.h[0]])
    v_n = tr.v_n[0].copy()
    R_nb = euler_to_dcm(*tr.rpy[0])
    imu = run.imu
    z3, no_seg = np.zeros(3), np.zeros(0, np.int64)
    prop = mech.Propagator(
        imu.t,
        imu.f_b + b_a,
        imu.omega_ib_b + b_g,
        z3,
        z3,
        z3,
        z3,
        (no_seg, no_seg, np.zeros((0, 3)), np.zeros((0, 3))),
    )
    t0 = imu.t[0]
    state = SimpleNamespace(pos=pos, v_n=v_n, R_nb=R_nb, b_a=z3.copy(), b_g=z3.copy(), P=np.eye(15))
    prop.advance(state, 1, t0, t0 + duration_s, with_cov=False)
    pos = state.pos
    k = int(np.argmin(np.abs(tr.t - (t0 + duration_s))))
    frame = earth.LocalTangentFrame(tr.lat[k], tr.lon[k], tr.h[k])
    return frame.to_ned(*pos)


def test_stationary_perfect_imu_stays_put():
    run = simulate("static", duration_s=65.0, imu_grade="perfect", noise="none", seed=0)
    drift = _free_inertial(run, 60.0)
    assert np.linalg.norm(drift) < 1e-3  # 1 mm over 60 s


def test_stationary_biased_imu_drifts_as_theory_says():
    run = simulate(
        "static", duration_s=65.0, imu_grade="perfect", noise="none", seed=0, initial_yaw_deg=0.0
    )
    t = 60.0
    # Accelerometer bias along body x (= north at yaw 0): dp_N = b t^2 / 2 (Schuler term < 0.1 %).
    b = 1e-3 * 9.80665
    drift = _free_inertial(run, t, b_a=np.array([b, 0.0, 0.0]))
    assert drift[0] == pytest.approx(0.5 * b * t**2, rel=5e-3)
    assert abs(drift[1]) < 0.01 * abs(drift[0])
    # Gyro bias about body x tilts the platform: east error g b t^3 / 6.
    bg = np.radians(10.0) / 3600.0
    drift = _free_inertial(run, t, b_g=np.array([bg, 0.0, 0.0]))
    g = earth.normal_gravity(run.truth.lat[0], run.truth.h[0])
    assert drift[1] == pytest.approx(g * bg * t**3 / 6.0, rel=0.02)


def test_moving_perfect_imu_follows_truth():
    run = simulate("car", duration_s=125.0, imu_grade="perfect", noise="none", seed=0)
    assert np.linalg.norm(_free_inertial(run, 120.0)) < 0.05


@pytest.mark.parametrize("method", ["ekf", "ekf-acc", "ekf-accw"])
def test_ekf_on_simulated_car_beats_gnss(method):
    """A realistic industrial IMU (vibration, scale-factor and cross-axis errors the filter does not
    model), self-initialised: the filter halves the raw fixes' error. Over seeds 0-2 and 10-15 the
    PRMSE ratio was 0.34-0.43 (sd 0.025), so the bound 0.7 is ten standard deviations away: it
    fails on a broken filter, not on a new random stream. Consistency is asserted where it can be
    bounded, with the filter's model equal to the truth, in test_consistency_mc.py (a time-averaged
    NEES of a few runs with unmodelled errors has no distribution to draw a band from)."""
    cfg = load_config(overrides={"imu": grade_config("industrial")})
    gains = []
    for seed in (10, 11, 12):
        run = simulate("car", duration_s=300.0, imu_grade="industrial", noise="white", seed=seed)
        sol = run_ekf(run, cfg, method)
        gains.append(score(run, sol).prmse_m / gnss_score(run).prmse_m)
        assert sol.stats["n_pos_updates"] > 250
        if method != "ekf":
            assert sol.stats["n_acc_updates"] > 250
    assert max(gains) < 0.7, gains


def test_ekf_estimates_the_heading_and_biases_of_a_simulated_ugv():
    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("ugv", duration_s=400.0, imu_grade="industrial", noise="white", seed=5)
    sol = run_ekf(run, cfg, "ekf-acc")
    sc = score(run, sol)
    assert sc.prmse_m < gnss_score(run).prmse_m
    yaw_sigma_deg = np.degrees(sol.sigma[-1, 8])
    assert sc.rpy_rmse_deg[2] < 10.0 and yaw_sigma_deg < 10.0
    # The final z-gyro bias estimate is within 3 sigma of the truth.
    b_true = run.sim.true_bias_g[-1, 2]
    assert abs(sol.b_g[-1, 2] - b_true) < 3 * sol.sigma[-1, 14] + 1e-6


def test_suspect_spans_get_inflated_noise():
    """Interpolated IMU stretches increase the attitude sigma versus the same run unflagged."""
    from gnssacc.checks.quality import QualityReport, Span, check_imu

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("turns", duration_s=120.0, imu_grade="industrial", noise="white", seed=1)
    clean = check_imu(run.imu, cfg)
    assert not clean.spans
    i0, i1 = 5000, 5150
    flagged = QualityReport(
        [Span("interpolated", run.imu.t[i0], run.imu.t[i1 - 1], i0, i1, "all", "test")],
        len(run.imu),
        0.01,
        0.01,
    )
    t_out = np.array([run.imu.t[i1]])
    a = run_ekf(run, cfg, "ekf", quality=clean, output_times=t_out)
    b = run_ekf(run, cfg, "ekf", quality=flagged, output_times=t_out)
    assert b.sigma[0, 8] > 2 * a.sigma[0, 8]


def test_kitti_integration():
    """KITTI with the kitti preset, on a GNSS noise seed the preset was not tuned on (it was tuned
    on seeds 0-2, bench/tune_kitti_nis.py)."""
    from gnssacc.pipeline import load_source

    cfg = load_config("kitti")
    run = load_source("kitti", cfg, noise="white", seed=7)
    raw = gnss_score(run)
    # The raw fixes' error is what the white profile (3/3/5 m) says, within its sampling band at a
    # false-failure rate of 1e-3 (a test of the noise generator, not a pinned draw).
    lo, hi = gnss_prmse_band(np.array([3.0, 3.0, 5.0]), raw.n_epochs)
    assert lo < raw.prmse_m < hi, (lo, raw.prmse_m, hi)
    for method in ("ekf", "ekf-acc"):
        sol = run_ekf(run, cfg, method)
        sc = score(run, sol)
        # Seeds 0-9: 0.46-0.52 of the raw error; 0.7 is far outside that scatter.
        assert sc.prmse_m < 0.7 * raw.prmse_m, (method, sc.prmse_m)
        assert sc.n_epochs > 460
        # NIS: the chi-square band of its updates (lag-1 autocorrelation counted), widened by the
        # preset's claimed calibration (stat_bounds.CALIBRATION).
        st = sol.stats
        lo, hi = nis_band(st["n_pos_updates"], 3, st["acf1_pos"], CALIBRATION)
        assert lo < st["nis_pos_mean"] < hi, (lo, st["nis_pos_mean"], hi)


def test_self_initialisation_of_a_slow_ugv_with_correlated_gnss_noise():
    """UGV speeds (<= 3 m/s) with Gauss-Markov GNSS noise: the yaw bank's start yaw is honest."""
    from gnssacc.prepare.stationary import detect_stationary
    from gnssacc.prepare.yawbank import select_yaw

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    z = []
    for seed in range(8):
        run = simulate("ugv", duration_s=120.0, imu_grade="industrial", noise="gm", seed=seed)
        ini = select_yaw(
            run, cfg, detect_stationary(run.imu, run.gnss, run.origin), filter_pass=run_ekf
        ).init
        assert ini.t == run.t_start
        err = (ini.rpy[2] - run.truth.rpy[0, 2] + np.pi) % (2 * np.pi) - np.pi
        z.append(err / ini.sigma_att_rad[2])
    assert np.max(np.abs(z)) < 3.0 and np.sqrt(np.mean(np.square(z))) < 1.5, z


def test_yaw_bank_is_not_misled_by_an_imu_still_cruise_inside_an_outage():
    """A steady climb inside a GNSS outage looks still to the IMU: its stationary spans are unchecked
    by the fixes. Scored ungated in the yaw bank, their zero-velocity updates condemned the true yaw
    (the hypothesis that knows its velocity best) and chose one 120 deg off: 183 m PRMSE, 290 m in
    the outages. The bank scores only the spans the fixes confirmed."""
    from gnssacc.api import process, simulate

    run = simulate("car", 300.0, imu_grade="industrial", seed=0)
    res = process(run, methods=["ekf"], outage_every="60:20", tune="none")
    assert any(not s.gnss_checked for s in res.ident.stationary.spans)  # the trap is there
    init = res.ident.init
    err = np.degrees(abs((init.rpy[2] - run.truth.rpy[0, 2] + np.pi) % (2 * np.pi) - np.pi))
    assert err < 3.0 * np.degrees(init.sigma_att_rad[2]), err
    m = res.metrics["methods"]["ekf"]
    assert m["prmse_outage_m"] < 20.0 and m["prmse_m"] < 10.0, m
