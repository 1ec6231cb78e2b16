"""Tests of the ground-vehicle simulator (gnssacc.sources.sim).

The central check is an independent strapdown integrator (plain numpy, written here, not in the
package) that must reproduce the truth from the perfect IMU: it proves that the simulated IMU
is consistent with the WGS-84 model of gnssacc.core.earth and with the sample convention "sample k
is the average over (t[k-1], t[k]]".
"""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.core.config import G0, load_config
from gnssacc.core.earth import earth_rate_n, gravity_n, radii, transport_rate_n
from gnssacc.core.errors import InputError
from gnssacc.core.rotations import dcm_to_euler, euler_to_dcm, rotvec_to_dcm, wrap_angle
from gnssacc.sources import sim
from gnssacc.core.units import DEG


# ----------------------------------------------------------------------------------------------
# An independent strapdown integrator
# ----------------------------------------------------------------------------------------------


def strapdown(t, f_b, omega_ib_b, lat, lon, h, v_n, R_nb):
    """Integrate IMU samples in NED from the state at ``t[0]``.

    Sample k is held over (t[k-1], t[k]]: rotation-vector attitude update net of the
    navigation-frame rotation, specific force rotated with the mid-interval attitude,
    trapezoidal position update.

    Returns
    -------
    lat, lon, h : ndarray, shape (N,)
    v_n : ndarray, shape (N, 3)
    R_nb : ndarray, shape (N, 3, 3)
    """
    n = len(t)
    out_llh = np.empty((n, 3))
    out_v = np.empty((n, 3))
    out_R = np.empty((n, 3, 3))
    v_n = np.array(v_n, float)
    R_nb = np.array(R_nb, float)
    out_llh[0], out_v[0], out_R[0] = (lat, lon, h), v_n, R_nb
    for k in range(1, n):
        dt = t[k] - t[k - 1]
        w_ie = earth_rate_n(lat)
        w_en = transport_rate_n(lat, h, v_n)
        w_in = w_ie + w_en
        R_half = rotvec_to_dcm(-0.5 * w_in * dt) @ R_nb @ rotvec_to_dcm(0.5 * omega_ib_b[k] * dt)
        R_new = rotvec_to_dcm(-w_in * dt) @ R_nb @ rotvec_to_dcm(omega_ib_b[k] * dt)
        # Gravity and Coriolis at the predicted mid-interval velocity.
        a_n = R_half @ f_b[k] + gravity_n(lat, h)
        v_mid = v_n + 0.5 * dt * (a_n - np.cross(2.0 * w_ie + w_en, v_n))
        v_new = v_n + dt * (a_n - np.cross(2.0 * w_ie + w_en, v_mid))
        v_avg = 0.5 * (v_n + v_new)
        h_new = h - v_avg[2] * dt
        h_avg = 0.5 * (h + h_new)
        R_M, _ = radii(lat)
        lat_new = lat + v_avg[0] / (R_M + h_avg) * dt
        lat_avg = 0.5 * (lat + lat_new)
        _, R_N = radii(lat_avg)
        lon = lon + v_avg[1] / ((R_N + h_avg) * np.cos(lat_avg)) * dt
        lat, h, v_n, R_nb = lat_new, h_new, v_new, R_new
        out_llh[k], out_v[k], out_R[k] = (lat, lon, h), v_n, R_nb
    return out_llh[:, 0], out_llh[:, 1], out_llh[:, 2], out_v, out_R


def roundtrip(scenario, duration_s, rate_hz=100.0):
    """Integrate a perfect-IMU run; return (truth, integrated lat, lon, h, v_n, R_nb, origin)."""
    run = sim.simulate(scenario, duration_s, imu_grade="perfect", imu_rate_hz=rate_hz, noise="none")
    truth = sim.dense_truth(scenario, duration_s, rate_hz)
    np.testing.assert_array_equal(truth.t, run.imu.t)
    k0 = 0
    out = strapdown(
        run.imu.t,
        run.imu.f_b,
        run.imu.omega_ib_b,
        truth.lat[k0],
        truth.lon[k0],
        truth.h[k0],
        truth.v_n[k0],
        truth.R_nb[k0],
    )
    return truth, out, run.origin


def ned_error(origin, truth, lat, lon, h):
    return origin.to_ned(lat, lon, h) - origin.to_ned(truth.lat, truth.lon, truth.h)


# ----------------------------------------------------------------------------------------------
# Round trips
# ----------------------------------------------------------------------------------------------


def test_static_strapdown_roundtrip_within_1mm():
    truth, (lat, lon, h, v_n, R_nb), origin = roundtrip("static", 60.0)
    err = ned_error(origin, truth, lat, lon, h)
    assert np.max(np.linalg.norm(err, axis=1)) < 1e-3
    assert np.max(np.abs(v_n)) < 1e-4


def test_car_strapdown_roundtrip():
    truth, (lat, lon, h, v_n, R_nb), origin = roundtrip("car", 60.0)
    # The first minute of "car" has a stop, an acceleration to 15 m/s, a turn, a hill.
    assert truth.speed.max() > 14.0 and np.ptp(truth.rpy[:, 1]) > 0.05
    err = ned_error(origin, truth, lat, lon, h)
    assert np.max(np.linalg.norm(err, axis=1)) < 0.5
    # Much tighter than required (the simulator achieves ~0.2 mm): a one-sample shift of the
    # convention or instantaneous instead of averaged samples give 0.1-0.2 m and 0.07-0.14 deg.
    assert np.max(np.linalg.norm(err, axis=1)) < 0.01
    assert np.max(np.linalg.norm(v_n - truth.v_n, axis=1)) < 1e-3
    roll, pitch, yaw = dcm_to_euler(R_nb)
    assert np.max(np.abs(wrap_angle(yaw - truth.rpy[:, 2]))) < 0.01 * DEG
    assert np.max(np.abs(wrap_angle(yaw - truth.rpy[:, 2]))) < 1e-4 * DEG
    assert np.max(np.abs(pitch - truth.rpy[:, 1])) < 0.01 * DEG
    assert np.max(np.abs(roll - truth.rpy[:, 0])) < 0.01 * DEG


def test_turns_roundtrip_at_other_rate():
    # A different IMU rate and scenario: the convention does not depend on 100 Hz.
    truth, (lat, lon, h, v_n, R_nb), origin = roundtrip("turns", 30.0, rate_hz=50.0)
    err = ned_error(origin, truth, lat, lon, h)
    assert np.max(np.linalg.norm(err, axis=1)) < 0.5
    _, _, yaw = dcm_to_euler(R_nb)
    assert np.max(np.abs(wrap_angle(yaw - truth.rpy[:, 2]))) < 0.01 * DEG


@pytest.mark.parametrize("name, t0, t1", [("ugv-slow", 95.0, 140.0), ("car-city", 245.0, 280.0)])
def test_reversing_strapdown_roundtrip(name, t0, t1):
    # Windows with stops, reversing, a turn while reversing and (ugv-slow) a stop before it;
    # the integrator starts from the truth at t0.
    rate = 50.0
    run = sim.simulate(name, t1, imu_grade="perfect", imu_rate_hz=rate, noise="none")
    truth = sim.dense_truth(name, t1, rate)
    assert any(t0 < a and b < t1 for a, b in sim.reversing_spans(run.sim.segments))
    k0 = int(round(t0 * rate))
    tr = sim.TruthSamples(*(getattr(truth, f)[k0:] for f in sim.TruthSamples.__dataclass_fields__))
    assert tr.speed.min() < -0.9
    lat, lon, h, v_n, R_nb = strapdown(
        run.imu.t[k0:],
        run.imu.f_b[k0:],
        run.imu.omega_ib_b[k0:],
        tr.lat[0],
        tr.lon[0],
        tr.h[0],
        tr.v_n[0],
        tr.R_nb[0],
    )
    # The simulator achieves ~0.05 mm, 3e-6 m/s, 1e-7 deg here.
    err = ned_error(run.origin, tr, lat, lon, h)
    assert np.max(np.linalg.norm(err, axis=1)) < 1e-3
    assert np.max(np.linalg.norm(v_n - tr.v_n, axis=1)) < 1e-4
    _, _, yaw = dcm_to_euler(R_nb)
    assert np.max(np.abs(wrap_angle(yaw - tr.rpy[:, 2]))) < 1e-5 * DEG


# ----------------------------------------------------------------------------------------------
# IMU signals
# ----------------------------------------------------------------------------------------------


def test_stationary_imu_closed_form():
    yaw = 75.0
    run = sim.simulate(
        "static", 5.0, imu_grade="perfect", initial_yaw_deg=yaw, origin_llh_deg=(47.0, 8.0, 400.0)
    )
    lat, h = 47.0 * DEG, 400.0
    R_bn = euler_to_dcm(0.0, 0.0, yaw * DEG).T
    f_expected = -R_bn @ gravity_n(lat, h)
    w_expected = R_bn @ earth_rate_n(lat)
    np.testing.assert_allclose(
        run.imu.f_b, np.tile(f_expected, (len(run.imu), 1)), rtol=0, atol=1e-10
    )
    np.testing.assert_allclose(
        run.imu.omega_ib_b, np.tile(w_expected, (len(run.imu), 1)), rtol=0, atol=1e-13
    )


def test_interval_averages_match_instantaneous_signals():
    # The interval average of a smooth signal equals its mid-interval value to O(dt^2): checks
    # the analytic f_b / omega_ib_b of dense_truth against the averaged IMU.
    run = sim.simulate("car", 120.0, imu_grade="perfect")
    traj = sim.build_trajectory("car", 120.0, 100.0)
    mid = traj.at(run.imu.t - 0.005)
    assert np.max(np.abs(run.imu.f_b - mid.f_b)) < 2e-3
    assert np.max(np.abs(run.imu.omega_ib_b - mid.omega_ib_b)) < 1e-4


def test_first_imu_sample_is_truth_start_and_rate():
    run = sim.simulate("ugv", 20.0, imu_rate_hz=200.0, gnss_rate_hz=5.0, t_start_s=1000.0)
    assert run.imu.t[0] == run.truth.t[0] == run.gnss.t[0] == 1000.0
    np.testing.assert_allclose(np.diff(run.imu.t), 1.0 / 200.0, atol=1e-9)
    np.testing.assert_allclose(np.diff(run.gnss.t), 1.0 / 5.0, atol=1e-9)
    assert len(run.imu) == 4001 and len(run.gnss) == 101
    assert run.imu.t[-1] == pytest.approx(1020.0)
    # GNSS epochs coincide with IMU times exactly.
    assert np.all(np.isin(run.gnss.t, run.imu.t))


# ----------------------------------------------------------------------------------------------
# Scenarios
# ----------------------------------------------------------------------------------------------


def test_ugv_speed_bounds_and_stops():
    tr = sim.dense_truth("ugv", 300.0, 10.0)
    assert tr.speed.max() <= 3.0 + 1e-9 and tr.speed.max() > 2.9
    assert tr.speed.min() >= -1e-12
    stopped = tr.speed == 0.0
    # Several separate stops, at least one of 5 s.
    starts = np.flatnonzero(np.diff(stopped.astype(int)) == 1)
    assert len(starts) >= 2
    assert stopped.sum() / 10.0 > 15.0
    assert np.ptp(tr.h) > 1.0  # a hill


def test_car_speed_bounds():
    tr = sim.dense_truth("car", 300.0, 10.0)
    assert 19.0 < tr.speed.max() <= 20.0 + 1e-9
    assert np.any(tr.speed == 0.0)
    assert np.ptp(tr.h) > 5.0


@pytest.mark.parametrize("name", list(sim.SCENARIOS))
def test_attitude_follows_velocity(name):
    tr = sim.dense_truth(name, 300.0, 5.0)
    assert tr.t[-1] == pytest.approx(300.0)
    moving = np.abs(tr.speed) > 0.1
    # Body x is the direction of travel, reversed when reversing (negative speed).
    x_dir = tr.v_n[moving] / tr.speed[moving, None]
    vh = np.hypot(x_dir[:, 0], x_dir[:, 1])
    np.testing.assert_allclose(tr.rpy[:, 0], 0.0)
    np.testing.assert_allclose(tr.rpy[moving, 1], np.arctan2(-x_dir[:, 2], vh), atol=1e-12)
    yaw_v = np.arctan2(x_dir[:, 1], x_dir[:, 0])
    assert np.all(np.abs(wrap_angle(tr.rpy[moving, 2] - yaw_v)) < 1e-12)
    # v_n is body-x forward: no side slip.
    v_b = np.einsum("kji,kj->ki", tr.R_nb, tr.v_n)
    np.testing.assert_allclose(v_b[:, 1:], 0.0, atol=1e-12)


def test_straight_and_turns_shapes():
    st = sim.dense_truth("straight", 60.0, 1.0, initial_yaw_deg=-45.0)
    np.testing.assert_allclose(st.speed, 10.0)
    np.testing.assert_allclose(st.rpy[:, 2], -45.0 * DEG, atol=1e-12)
    tu = sim.dense_truth("turns", 200.0, 10.0, initial_yaw_deg=0.0)
    assert np.max(np.abs(tu.omega_ib_b[:, 2])) > 0.3  # 10 m/s on 30 m: 0.33 rad/s
    # After one figure of eight (10 s straight + two full circles) the heading is back at 0.
    cycle = sim.make_scenario("turns", 1.0).t_end
    k = int(round(cycle * 10.0))
    assert abs(wrap_angle(tu.rpy[k, 2])) < 1e-9


def test_origin_and_initial_yaw():
    run = sim.simulate(
        "straight", 10.0, origin_llh_deg=(-33.9, 151.2, 20.0), initial_yaw_deg=120.0, noise="none"
    )
    assert run.truth.lat[0] == pytest.approx(-33.9 * DEG, abs=1e-15)
    assert run.truth.lon[0] == pytest.approx(151.2 * DEG, abs=1e-15)
    assert run.truth.h[0] == pytest.approx(20.0, abs=1e-9)
    assert run.truth.rpy[0, 2] == pytest.approx(120.0 * DEG)
    p = run.origin.to_ned(run.truth.lat, run.truth.lon, run.truth.h)
    assert np.linalg.norm(p[-1, :2]) == pytest.approx(100.0, rel=1e-5)
    assert np.degrees(np.arctan2(p[-1, 1], p[-1, 0])) == pytest.approx(120.0, abs=1e-3)


# ----------------------------------------------------------------------------------------------
# IMU errors
# ----------------------------------------------------------------------------------------------

#: Switches off every error source a filter does not model (vibration, scale factor, cross-axis,
#: drift), leaving a realistic grade's filter-visible errors.
UNMODELLED_OFF = {k: 0.0 for k in sim.UNMODELLED_KEYS}


@pytest.mark.parametrize(
    "grade, overrides",
    [
        ("consumer-basic", None),
        ("industrial-basic", None),
        ("tactical-basic", None),
        ("consumer", UNMODELLED_OFF),
        ("industrial", UNMODELLED_OFF),
    ],
)
def test_imu_noise_statistics_match_grade(grade, overrides):
    # The realistic grades' white noise and Gauss-Markov bias follow grade_config too.
    dt = 0.01
    run = sim.simulate("static", 300.0, imu_grade=grade, seed=3, imu_overrides=overrides)
    perfect = sim.simulate("static", 300.0, imu_grade="perfect", seed=3)
    p = sim.grade_config(grade)
    white_a = run.imu.f_b - perfect.imu.f_b - run.sim.true_bias_a
    white_g = run.imu.omega_ib_b - perfect.imu.omega_ib_b - run.sim.true_bias_g
    sig_a = p["accel_vrw_mps_rth"] / 60.0 / np.sqrt(dt)
    sig_g = p["gyro_arw_deg_rth"] * DEG / 60.0 / np.sqrt(dt)
    np.testing.assert_allclose(white_a.std(axis=0), sig_a, rtol=0.1)
    np.testing.assert_allclose(white_g.std(axis=0), sig_g, rtol=0.1)
    # Gauss-Markov bias: its innovations have std sqrt(1 - a^2) * BI.
    a = np.exp(-dt / p["bias_correlation_time_s"])
    bi_g = p["gyro_bias_instability_deg_h"] * DEG / 3600.0
    bi_a = p["accel_bias_instability_mg"] * 1e-3 * G0
    for bias, bi in ((run.sim.true_bias_g, bi_g), (run.sim.true_bias_a, bi_a)):
        innov = bias[1:] - a * bias[:-1]
        np.testing.assert_allclose(innov.std(axis=0), np.sqrt(1 - a * a) * bi, rtol=0.1)


@pytest.mark.parametrize("grade", ["consumer-basic", "consumer"])
def test_turn_on_bias_is_drawn_with_grade_sigma(grade):
    # Across seeds, the initial bias spread follows sqrt(sigma0^2 + BI^2) (the drift starts at 0).
    p = sim.grade_config(grade)
    runs = [
        sim.simulate("static", 1.0, imu_grade=grade, seed=s, imu_rate_hz=20.0, gnss_rate_hz=1.0)
        for s in range(200)
    ]
    b0 = np.array([r.sim.true_bias_g[0] for r in runs])
    expected = (
        np.hypot(p["gyro_bias_sigma0_deg_h"], p["gyro_bias_instability_deg_h"]) * DEG / 3600.0
    )
    np.testing.assert_allclose(b0.std(), expected, rtol=0.1)
    on = np.array([r.sim.imu_error_draws["gyro_turn_on_bias"] for r in runs])
    np.testing.assert_allclose(on.std(), p["gyro_bias_sigma0_deg_h"] * DEG / 3600.0, rtol=0.1)


def test_gauss_markov_is_stationary_with_short_tau():
    rng = np.random.default_rng(0)
    x = sim.gauss_markov(200_000, 0.01, 0.5, np.array([1.0, 2.0, 3.0]), rng)
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(x.std(axis=0), [1.0, 2.0, 3.0], rtol=0.05)
    a = np.exp(-0.01 / 0.5)
    lag1 = np.mean(x[1:] * x[:-1], axis=0) / np.mean(x * x, axis=0)
    np.testing.assert_allclose(lag1, a, atol=0.01)


def test_perfect_grade_has_zero_bias_and_overrides_apply():
    run = sim.simulate("static", 10.0, imu_grade="perfect")
    assert not np.any(run.sim.true_bias_a) and not np.any(run.sim.true_bias_g)
    over = sim.simulate(
        "static", 10.0, imu_grade="perfect", imu_overrides={"gyro_arw_deg_rth": 1.0}
    )
    assert np.any(over.imu.omega_ib_b != run.imu.omega_ib_b)
    np.testing.assert_array_equal(over.imu.f_b, run.imu.f_b)
    assert over.sim.imu_params["gyro_arw_deg_rth"] == 1.0


def test_grade_config_builds_filter_config():
    for grade in sim.IMU_GRADES:
        values = sim.grade_config(grade)
        # every filter key but the turn error and the triad's misalignment, which the simulator
        # draws as its own unmodelled cross-axis and scale-factor errors (a grade's filter
        # setting is the user's choice)
        allowances = {"gyro_turn_error_ppm", "accel_misalignment_ppm"}
        assert set(values) == set(load_config()["imu"]) - allowances
        if grade == "perfect":  # zero white noise: no filter configuration (one clear error)
            with pytest.raises(InputError, match="gyro_arw_deg_rth"):
                load_config(overrides={"imu": values})
            continue
        cfg = load_config(overrides={"imu": values})
        assert {k: cfg["imu"][k] for k in values} == values
    cfg = load_config(overrides={"imu": sim.grade_config("industrial")})
    np.testing.assert_allclose(cfg.gyro_psd, (0.2 * DEG / 60.0) ** 2)
    np.testing.assert_allclose(cfg.accel_bias_sigma0, 5e-3 * G0)
    with pytest.raises(InputError):
        sim.grade_config("navigation")
    with pytest.raises(InputError):
        sim.grade_config("industrial", {"gyro_arw": 1.0})


# ----------------------------------------------------------------------------------------------
# Seeds, GNSS, the run object
# ----------------------------------------------------------------------------------------------


def test_seed_reproducibility():
    a = sim.simulate("ugv", 30.0, imu_grade="consumer", seed=7)
    b = sim.simulate("ugv", 30.0, imu_grade="consumer", seed=7)
    c = sim.simulate("ugv", 30.0, imu_grade="consumer", seed=8)
    np.testing.assert_array_equal(a.imu.f_b, b.imu.f_b)
    np.testing.assert_array_equal(a.imu.omega_ib_b, b.imu.omega_ib_b)
    np.testing.assert_array_equal(a.gnss.lat, b.gnss.lat)
    np.testing.assert_array_equal(a.sim.true_bias_g, b.sim.true_bias_g)
    assert np.all(a.imu.f_b != c.imu.f_b)
    assert np.all(a.gnss.lat != c.gnss.lat)
    np.testing.assert_array_equal(a.truth.lat, c.truth.lat)  # truth does not depend on the seed


def test_gnss_white_noise_statistics():
    run = sim.simulate(
        "car",
        600.0,
        imu_grade="perfect",
        imu_rate_hz=20.0,
        gnss_rate_hz=10.0,
        noise="white",
        seed=11,
        truth_rate_hz=10.0,  # the truth at the fixes' epochs (the default is the IMU rate)
    )
    assert np.array_equal(run.gnss.t, run.truth.t)
    err = ned_error(run.origin, run.truth, run.gnss.lat, run.gnss.lon, run.gnss.h)
    n = len(err)
    sigma = np.array([3.0, 3.0, 5.0])
    np.testing.assert_allclose(err.std(axis=0), sigma, rtol=0.06)
    assert np.all(np.abs(err.mean(axis=0)) < 4.0 * sigma / np.sqrt(n))
    np.testing.assert_allclose(run.gnss.sigma_ned, np.tile(sigma, (n, 1)))
    # White: no correlation between consecutive fixes.
    lag1 = np.mean(err[1:] * err[:-1], axis=0) / err.var(axis=0)
    assert np.all(np.abs(lag1) < 4.0 / np.sqrt(n))


def test_lever_arm_moves_fixes_to_antenna():
    lever = np.array([1.5, -0.4, -1.2])
    run = sim.simulate("car", 120.0, gnss_rate_hz=2.0, noise="none", lever_arm_b=lever)
    traj = sim.build_trajectory("car", 120.0, 100.0)
    tr = traj.at(run.gnss.t)
    expected = run.origin.to_ned(tr.lat, tr.lon, tr.h) + tr.R_nb @ lever
    got = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
    assert np.max(np.abs(got - expected)) < 1e-6


def test_truth_rate_and_init():
    run = sim.simulate("car", 60.0, truth_rate_hz=10.0, give_init=True)
    assert len(run.truth.t) == 601 and len(run.gnss) == 61
    init = run.init
    assert init.t == run.imu.t[0]
    assert (init.lat, init.lon, init.h) == (run.truth.lat[0], run.truth.lon[0], run.truth.h[0])
    np.testing.assert_array_equal(init.rpy, run.truth.rpy[0])
    assert np.all(init.sigma_pos_m > 0) and np.all(init.sigma_att_rad > 0)
    assert sim.simulate("car", 10.0).init is None


@pytest.mark.parametrize("name", list(sim.SCENARIOS))
def test_run_validates_and_records_arguments(name):
    run = sim.simulate(name, 40.0, noise="gm", seed=5).validate()
    assert run.name == f"sim-{name}" and run.where == f"simulator({name}, seed=5)"
    for key in (
        "scenario",
        "duration_s",
        "imu_grade",
        "imu_rate_hz",
        "gnss_rate_hz",
        "noise",
        "seed",
        "origin_llh_deg",
        "initial_yaw_deg",
        "lever_arm_b",
        "give_init",
        "imu_overrides",
    ):
        assert key in run.meta
    assert run.sim.true_bias_a.shape == (len(run.imu), 3)
    assert run.sim.segments[0]["t0"] == 0.0
    assert run.duration_s == pytest.approx(40.0)


def test_bad_arguments_raise_input_error():
    with pytest.raises(InputError, match="scenario"):
        sim.simulate("boat", 10.0)
    with pytest.raises(InputError, match="grade"):
        sim.simulate("car", 10.0, imu_grade="navigation")
    with pytest.raises(InputError, match="noise"):
        sim.simulate("car", 10.0, noise="pink")
    with pytest.raises(InputError):
        sim.simulate("car", -1.0)


def test_custom_scenario_builder():
    s = sim.Scenario("custom").hold(2.0).speed_to(5.0, 4.0).turn(90.0, radius_m=10.0).hill(3.0, 6.0)
    s.speed_to(0.0, 4.0)
    traj = sim.build_trajectory(s, s.t_end, 50.0, initial_yaw_deg=0.0)
    end = traj.at([s.t_end])
    assert end.speed[0] == 0.0
    assert end.rpy[0, 2] == pytest.approx(np.pi / 2)
    assert end.h[0] == pytest.approx(50.0, abs=1e-6)  # the hill comes back down
    with pytest.raises(InputError):
        sim.Scenario("x").turn(90.0, radius_m=10.0)  # a radius needs speed
