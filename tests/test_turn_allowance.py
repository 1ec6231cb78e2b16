"""The default gyro turn allowance follows the recording's own gyro noise
(``[imu] gyro_turn_error_ppm = "auto"``, :mod:`gnssacc.prepare.turn_allowance`)."""

import math

import numpy as np
import pytest

import gnssacc
from gnssacc.core.config import FALLBACK_TURN_ERROR_PPM, load_config
from gnssacc.core.errors import InputError
from gnssacc.prepare.turn_allowance import ANCHORS, gyro_density_deg_rth, resolved, turn_error_ppm


def test_the_datasheet_anchors_are_met_and_the_prior_rises_smoothly_between_them():
    for arw, ppm in ANCHORS:
        assert turn_error_ppm(arw) == pytest.approx(ppm, rel=1e-12)
    arw = np.geomspace(0.01, 3.0, 400)
    ppm = np.array([turn_error_ppm(a) for a in arw])
    assert np.all(np.diff(ppm) >= 0.0)
    inside = (arw > ANCHORS[0][0]) & (arw < ANCHORS[-1][0])
    assert np.all(np.diff(ppm[inside]) > 0.0)  # no flat step between the anchors
    # no jump anywhere: neighbouring densities 0.4 % apart give allowances a few % apart
    assert np.max(np.abs(np.diff(np.log(ppm)))) < 0.05
    # held at the end anchors beyond them
    assert turn_error_ppm(0.001) == pytest.approx(ANCHORS[0][1])
    assert turn_error_ppm(50.0) == pytest.approx(ANCHORS[-1][1])
    # half-way in log density between two anchors is half-way in log ppm
    (a0, p0), (a1, p1) = ANCHORS[1], ANCHORS[2]
    assert turn_error_ppm(math.sqrt(a0 * a1)) == pytest.approx(math.sqrt(p0 * p1), rel=1e-12)
    assert turn_error_ppm(float("nan")) == FALLBACK_TURN_ERROR_PPM
    assert turn_error_ppm(0.0) == FALLBACK_TURN_ERROR_PPM


def test_the_three_gyros_give_their_geometric_mean_and_nothing_without_a_finite_value():
    assert gyro_density_deg_rth([0.1, 0.4, 0.2]) == pytest.approx(0.2)
    assert gyro_density_deg_rth([0.2, float("nan"), 0.2]) == pytest.approx(0.2)
    assert math.isnan(gyro_density_deg_rth([float("nan")] * 3))


def test_an_explicit_or_preset_value_is_used_as_given_and_auto_is_the_default():
    assert load_config()["imu"]["gyro_turn_error_ppm"] == "auto"
    assert load_config().gyro_turn_psd == pytest.approx((FALLBACK_TURN_ERROR_PPM * 1e-6) ** 2)
    auto = resolved(load_config(), 0.6, "at rest")
    assert auto["imu"]["gyro_turn_error_ppm"] == pytest.approx(10000.0)
    assert "at rest" in auto.origin[("imu", "gyro_turn_error_ppm")]
    told = load_config(overrides={"imu": {"gyro_turn_error_ppm": 1000.0}})
    assert resolved(told, 0.6, "at rest") is told
    preset = load_config("tactical")
    assert resolved(preset, 0.6, "at rest")["imu"]["gyro_turn_error_ppm"] == 150.0
    assert load_config(overrides={"imu": {"gyro_turn_error_ppm": "auto"}}).explicit
    with pytest.raises(InputError, match="gyro_turn_error_ppm"):
        load_config(overrides={"imu": {"gyro_turn_error_ppm": "big"}})


def _attitude(ppm):
    config = {} if ppm is None else {"config": {"imu": {"gyro_turn_error_ppm": ppm}}}
    res = gnssacc.process(
        "sim:ugv-slow,imu=consumer,duration=300", methods=["ekf"], seed=0, **config
    )
    nees = res.metrics["methods"]["ekf"]["errors"]["nees_attitude"]["value"]
    return res.prepared.cfg, nees, res.metrics["methods"]["ekf"]["prmse_m"]


@pytest.mark.slow
def test_a_simulated_consumer_vehicle_states_its_attitude_truthfully_with_the_auto_allowance():
    """The simulator draws consumer gyro scale-factor (10000 ppm) and cross-axis (7000 ppm)
    errors; the run's stationary spans show its 0.6 deg/sqrt(h) gyros. With the allowance they
    imply the EKF's attitude errors match its stated sigmas; with the industrial 1000 ppm they
    are many times larger."""
    cfg, nees_auto, prmse_auto = _attitude(None)
    assert 5000.0 < cfg["imu"]["gyro_turn_error_ppm"] < 15000.0
    assert "at rest" in cfg.origin[("imu", "gyro_turn_error_ppm")]
    _, nees_1000, prmse_1000 = _attitude(1000.0)
    assert 0.5 <= nees_auto <= 1.5 < 5.0 < nees_1000
    assert prmse_auto <= 1.03 * prmse_1000


@pytest.mark.parametrize("grade", ["consumer", "industrial", "tactical"])
def test_a_run_whose_stops_are_all_short_takes_its_allowance_from_them(grade):
    """The simulated UGV stops for at most 8 s (detected spans of 2.3-7.9 s, none of 10 s): its
    allowance comes from the spans of 4 s or more, near the datasheet pair of the simulator's own
    gyro density (the truth; the anchors' log-log slope turns the density's error of short spans,
    15 % at most, into 30 %), not the 1000 ppm fallback; a run that never stops keeps the
    fallback."""
    from gnssacc import pipeline
    from gnssacc.sources.sim_imu_errors import IMU_GRADES
    from gnssacc.sources.sim_scenarios import Scenario

    run = gnssacc.simulate("ugv", 120.0, imu_grade=grade, seed=1)
    prep = pipeline.prepare(run, load_config(), tune="none")
    assert prep.stationary.spans and max(s.duration_s for s in prep.stationary.spans) < 10.0
    assert not prep.rest_noise.n_spans  # no span for the tuner's starting values
    truth = turn_error_ppm(IMU_GRADES[grade]["gyro_arw_deg_rth"])
    got = prep.cfg["imu"]["gyro_turn_error_ppm"]
    assert truth / 1.3 < got < truth * 1.3, (got, truth)
    assert "spans of 4-10 s" in prep.cfg.origin[("imu", "gyro_turn_error_ppm")]

    path = Scenario("never stops", 10.0).cruise(20.0).turn(90.0, radius_m=40.0).cruise(20.0)
    moving = gnssacc.simulate(path, path.t_end, imu_grade=grade, seed=1, give_init=True)
    prep = pipeline.prepare(moving, load_config(), tune="none")
    assert not prep.stationary.spans
    assert prep.cfg["imu"]["gyro_turn_error_ppm"] == "auto"  # the fallback applies
    assert prep.cfg.gyro_turn_psd == pytest.approx((FALLBACK_TURN_ERROR_PPM * 1e-6) ** 2)


def test_the_accelerometer_turn_on_anchors_are_the_presets_and_rise_smoothly():
    """accel_turn_on_mg at the anchors' gyro densities gives the packaged presets' turn-on sigmas
    (their datasheet classes), rises between them and holds beyond; NaN without a density."""
    from gnssacc.prepare.turn_allowance import TURN_ON_ANCHORS, accel_turn_on_mg

    for (arw, mg), preset in zip(TURN_ON_ANCHORS, ("tactical", "industrial", "consumer")):
        assert accel_turn_on_mg(arw) == pytest.approx(mg, rel=1e-12)
        assert load_config(preset)["imu"]["accel_bias_sigma0_mg"] == pytest.approx(mg)
    mg = np.array([accel_turn_on_mg(a) for a in np.geomspace(0.06, 0.55, 200)])
    assert np.all(np.diff(mg) > 0.0)
    assert accel_turn_on_mg(0.001) == pytest.approx(1.0) and accel_turn_on_mg(9.0) == 40.0
    assert math.isnan(accel_turn_on_mg(float("nan")))
