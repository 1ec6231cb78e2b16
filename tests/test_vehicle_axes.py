"""The attitude a run reports is the vehicle's where the constraint's axes are turned against the
body's (``NavSolution.in_vehicle_axes``, ``pipeline.attitude_axes``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import gnssacc
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.core.solution import NavSolution


def _solution(rpy: np.ndarray) -> NavSolution:
    k = len(rpy)
    z = np.zeros(k)
    return NavSolution(
        "ekf", np.arange(k, dtype=float), z, z, z, np.zeros((k, 3)), rpy, *np.zeros((2, k, 3)),
        np.ones((k, 15)),
    )  # fmt: skip


def _R_vb(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Body to vehicle axes as ``[nhc]`` states them (yaw, then pitch)."""
    return euler_to_dcm(0.0, np.radians(pitch_deg), np.radians(yaw_deg)).T


def test_a_level_body_takes_the_offsets_in_closed_form():
    # Level body at heading psi, vehicle axes turned by yaw y then pitch p: (0, p, psi + y).
    psi = np.radians([-170.0, -30.0, 0.0, 45.0, 120.0])
    sol = _solution(np.column_stack([0 * psi, 0 * psi, psi]))
    out = sol.in_vehicle_axes(_R_vb(0.7, -1.3))
    want = np.column_stack([0 * psi, np.full(5, np.radians(0.7)), psi + np.radians(-1.3)])
    np.testing.assert_allclose(out.rpy, want, atol=1e-12)
    assert out.sigma is sol.sigma and out.b_a is sol.b_a  # the body's sigmas and biases


def test_any_attitude_composes_as_scipy_does():
    # R_nv = R_nb R_bv against scipy's own rotation algebra (intrinsic Z-Y-X Euler angles).
    rng = np.random.default_rng(3)
    rpy = np.column_stack(
        [rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.4, 0.4, 50), rng.uniform(-np.pi, np.pi, 50)]
    )
    out = _solution(rpy).in_vehicle_axes(_R_vb(-2.0, 4.0))
    nb = Rotation.from_euler("ZYX", rpy[:, ::-1])
    bv = Rotation.from_euler("ZYX", [np.radians(4.0), np.radians(-2.0), 0.0])
    want = (nb * bv).as_euler("ZYX")[:, ::-1]
    np.testing.assert_allclose(out.rpy, want, atol=1e-12)


def test_the_body_attitude_comes_back_and_is_turned_once():
    rng = np.random.default_rng(4)
    rpy = rng.uniform(-0.6, 0.6, (20, 3))
    sol = _solution(rpy)
    out = sol.in_vehicle_axes(_R_vb(1.1, -0.6))
    np.testing.assert_allclose(out.body_rpy(), rpy, atol=1e-12)
    assert out.in_vehicle_axes(_R_vb(1.1, -0.6)) is out  # the vehicle's already: not again
    assert sol.body_rpy() is sol.rpy


def test_the_floor_raises_only_the_attitude_sigmas_below_it():
    sol = _solution(np.zeros((4, 3)))
    sol.sigma[:, 6:9] = [[0.003, 0.002, 0.004], [0.001, 0.009, 0.0], [0.2, 0.2, 0.2], [0, 0, 0]]
    out = sol.in_vehicle_axes(None, floor=np.array([0.004, 0.0, 0.005]))
    want = [[0.004, 0.002, 0.005], [0.004, 0.009, 0.005], [0.2, 0.2, 0.2], [0.004, 0.0, 0.005]]
    np.testing.assert_array_equal(out.sigma[:, 6:9], want)
    others = lambda x: np.delete(x.sigma, [6, 7, 8], axis=1)  # noqa: E731
    np.testing.assert_array_equal(others(out), others(sol))
    np.testing.assert_array_equal(out.rpy, sol.rpy)  # the body's axes: not turned
    assert sol.sigma[0, 6] == 0.003  # the estimator's own solution untouched
    assert out.in_vehicle_axes(None, floor=np.full(3, 1.0)) is out  # once


def test_the_triad_rotation_is_the_antisymmetric_part_of_its_cross_axis_errors():
    # Independent truth: draw cross-axis matrices with iid elements of 1-sigma 7000 ppm, take the
    # rotation they turn the triad by (the antisymmetric part); its spread per axis is the floor.
    from gnssacc.core.config import load_config
    from gnssacc.prepare.attitude_axes import attitude_axes

    rng = np.random.default_rng(5)
    M = rng.standard_normal((200_000, 3, 3)) * 7000e-6
    rot = 0.5 * np.stack(
        [M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], axis=1
    )
    floor = attitude_axes(load_config(overrides={"imu": {"accel_misalignment_ppm": 7000}}))
    for axis, spread in zip(("roll", "pitch", "yaw"), np.degrees(rot.std(axis=0))):
        assert floor["sigma_floor_deg"][axis] == pytest.approx(spread, rel=0.01)


def test_the_floor_skips_the_measured_angles_and_takes_the_imus_class():
    from gnssacc.core.config import load_config
    from gnssacc.pipeline import attitude_axes

    class_ = {"imu": {"gyro_turn_error_ppm": 8000.0}}
    triad = np.degrees(8000e-6) / np.sqrt(2)
    none = attitude_axes(load_config(overrides=class_))
    assert none["axes"] == "body" and none["misalignment_from"] == "the gyro turn allowance"
    assert none["sigma_floor_deg"] == pytest.approx({"roll": triad, "pitch": triad, "yaw": triad})
    angles = {"nhc": {"pitch_offset_deg": -0.2, "yaw_offset_deg": 0.3}}  # their scale 0.25 deg
    tuned = attitude_axes(load_config(overrides=class_).with_values(angles, "tuned"))
    assert tuned["axes"] == "vehicle" and tuned["set_by"] == ["tuned"]
    assert tuned["sigma_floor_deg"] == pytest.approx({"roll": triad, "pitch": 0.0, "yaw": 0.0})
    zero = {"nhc": {"pitch_offset_deg": 0.0, "yaw_offset_deg": 0.0}}  # searched, none proven
    searched = attitude_axes(load_config(overrides=class_).with_values(zero, "tuned"))
    assert searched["axes"] == "body"
    assert searched["sigma_floor_deg"] == pytest.approx({"roll": triad, "pitch": 0.0, "yaw": 0.0})
    big = {"nhc": {"pitch_offset_deg": -0.9, "yaw_offset_deg": 1.2}}
    roll = attitude_axes(load_config(overrides=class_).with_values(big, "tuned"))["sigma_floor_deg"]
    assert roll["roll"] == pytest.approx(np.sqrt((0.81 + 1.44) / 2))  # the found pair's scale
    given = attitude_axes(load_config(overrides={**class_, **angles}))  # the case's axes
    assert given["axes"] == "vehicle" and given["sigma_floor_deg"]["pitch"] == pytest.approx(triad)
    calibrated = {"imu": {"accel_misalignment_ppm": 0}}
    floors = attitude_axes(load_config(overrides=calibrated))["sigma_floor_deg"]
    assert set(floors.values()) == {0.0}
    fallback = attitude_axes(load_config())
    assert fallback["misalignment_ppm"] == 1000.0  # "auto" before the recording sets the class


def _bowl(mean_deg: float, sigma_deg: float):
    """A log-likelihood along an angle, Gaussian: its maximum at ``mean_deg``, its 1-sigma
    ``sigma_deg``; and the angles it was read at."""
    seen: list = []

    def loglik(a: float) -> float:
        seen.append(a)
        return -0.5 * ((a - mean_deg) / sigma_deg) ** 2

    return loglik, seen


@pytest.mark.parametrize("found", [-0.34, 0.05, 0.0])
def test_the_likelihoods_resolution_of_an_angle_is_its_gaussians_sigma(found):
    """Closed form: a Gaussian log-likelihood along the angle gives its own sigma, read from zero
    when zero is a sigma or more away (no pass beyond), from a point beyond the angle otherwise."""
    from gnssacc.prepare.attitude_axes import PROBE_DEG, likelihood_sigma

    loglik, seen = _bowl(found, 0.107)
    assert likelihood_sigma(loglik, found) == pytest.approx(0.107, rel=1e-9)
    beyond = abs(found) < 0.107
    assert (len(seen) == 3) == beyond
    if beyond:
        assert seen[-1] == pytest.approx(found + np.copysign(PROBE_DEG, found or 1.0))
    assert likelihood_sigma(lambda a: -3.0, found) == np.inf  # flat: nothing resolved


@pytest.mark.parametrize("found, sigma", [(-0.34, 0.107), (0.05, 0.3), (0.0, None)])
def test_an_angle_left_at_zero_is_off_by_its_posterior_spread_from_the_triads_prior(found, sigma):
    """Closed form: the prior N(0, t^2) (the triad's turn) and the likelihood N(found, s^2) give the
    posterior variance 1 / (1/t^2 + 1/s^2) and mean found / s^2 times it; zero is off by their
    root mean square. A kept angle is off by the likelihood's sigma alone."""
    from gnssacc.prepare.attitude_axes import offset_floor

    t = 0.32
    info = 0.0 if sigma is None else 1.0 / sigma**2
    var = 1.0 / (1.0 / t**2 + info)
    want = np.hypot(found * info * var, np.sqrt(var))
    assert offset_floor(found, sigma, False, t) == pytest.approx(want, rel=1e-12)
    assert offset_floor(found, sigma, False, t) <= np.hypot(t, found)
    if sigma is not None:
        assert offset_floor(found, sigma, True, t) == sigma
    assert offset_floor(found, sigma, False, 0.0) == 0.0  # a calibrated triad: nothing to turn
    if sigma is None:  # kept where the likelihood is flat: the prior's spread about the angle
        assert offset_floor(0.4, None, True, t) == pytest.approx(np.hypot(0.4, t))


def test_a_searched_angles_floor_is_the_tuners_record_of_it():
    """An angle the tuner searched has the floor its record gives (``vehicle_axes``), kept or not;
    one it did not search keeps the triad's."""
    from gnssacc.core.config import load_config
    from gnssacc.pipeline import attitude_axes
    from gnssacc.prepare.attitude_axes import offset_floor

    class_ = {"imu": {"gyro_turn_error_ppm": 8000.0}}
    triad = np.degrees(8000e-6) / np.sqrt(2)
    zero = {"nhc": {"pitch_offset_deg": 0.0, "yaw_offset_deg": 0.0}}
    cfg = load_config(overrides=class_).with_values(zero, "tuned")
    record = {
        "pitch_offset_deg": {"found_deg": -0.34, "sigma_deg": 0.107, "kept": False},
        "yaw_offset_deg": {"found_deg": 0.6, "sigma_deg": 0.1, "kept": True},
    }
    pitch = offset_floor(-0.34, 0.107, False, triad)
    got = attitude_axes(cfg, None, record)
    assert got["sigma_floor_deg"] == pytest.approx({"roll": triad, "pitch": pitch, "yaw": 0.1})
    assert got["resolution_deg"] == pytest.approx({"pitch": pitch, "yaw": 0.1})
    given = load_config(overrides=class_)  # not searched: the record does not apply
    assert attitude_axes(given, None, record)["sigma_floor_deg"]["pitch"] == pytest.approx(triad)


def test_without_offsets_the_solution_is_itself():
    sol = _solution(np.zeros((3, 3)))
    assert sol.in_vehicle_axes(None) is sol


@pytest.mark.slow
def test_the_tuned_axes_make_a_consumer_cars_pitch_and_yaw_consistent():
    """A simulated consumer car whose accelerometer triad is turned against its case by a few
    tenths of a degree (the simulator's cross-axis errors; its truth is the case's attitude,
    which is the vehicle's): the estimators follow the triad, and the tuner finds the
    constraint's axes turned by about as much. Reported in the body's axes the pitch and yaw
    were 0.2-0.4 deg off at a stated 0.05-0.1 (NEES ekf 8.7 / 12.6, smoother 16.2 / 24.4); in
    the vehicle's, within their bands."""
    res = gnssacc.process("sim:car-city,imu=consumer,duration=300", methods=["ekf", "smoother"])
    axes = res.metrics["attitude_axes"]
    assert axes["axes"] == "vehicle" and axes["set_by"] == ["tuned"]
    assert abs(axes["yaw_offset_deg"]) > 0.1
    pitch = axes["pitch_offset_deg"]
    said = f"attitude: of the vehicle's axes, the body's turned by pitch {pitch:+.2f}"
    assert said in res.table()  # the table (and table.txt) says whose axes
    for m in ("ekf", "smoother"):
        nees = res.metrics["methods"][m]["errors"]["nees_attitude"]
        for axis in ("pitch", "yaw"):
            assert 0.2 < nees["per_axis"][axis]["value"] < 1.5, (m, axis, nees["per_axis"][axis])
        # The roll follows the triad too (0.5-0.6 deg RMS off at a stated 0.1-0.2: NEES 3.3 /
        # 3.1 before its floor; one constant error per run: a draw of one degree of freedom).
        assert nees["per_axis"]["roll"]["value"] < 2.0, (m, nees["per_axis"]["roll"])
        assert 0.5 < nees["value"] < 1.5, (m, nees["value"])


@pytest.mark.slow
def test_without_the_constraint_a_consumer_cars_attitude_sigma_has_the_triads_floor():
    """The same car without the non-holonomic constraint: nothing ties the attitude to the case,
    so it stays the triad's, 0.2-0.5 deg off (pitch NEES ekf 5.1, smoother 7.3 with the
    estimators' own sigmas of 0.1-0.2 deg); the triad's rotation by the IMU's class (the gyro
    turn allowance measured at rest) is the sigma's floor on every axis."""
    res = gnssacc.process(
        "sim:car-city,imu=consumer,duration=300",
        methods=["ekf", "smoother"],
        config={"nhc": {"enabled": False}},
    )
    axes = res.metrics["attitude_axes"]
    assert axes["axes"] == "body" and axes["misalignment_from"] == "the gyro turn allowance"
    assert set(axes["sigma_floor_deg"].values()) == {axes["triad_deg"]} and axes["triad_deg"] > 0.2
    assert "attitude: of the body's axes; unmeasured, each sigma at least roll" in res.table()
    for m in ("ekf", "smoother"):
        nees = res.metrics["methods"][m]["errors"]["nees_attitude"]
        for axis in ("roll", "pitch", "yaw"):
            assert nees["per_axis"][axis]["value"] < 2.0, (m, axis, nees["per_axis"][axis])
        assert 0.5 < nees["value"] < 1.5, (m, nees["value"])


def test_a_run_that_never_showed_its_yaw_has_the_tilt_of_its_accelerometer_biases_as_floor():
    """level_floor: on a start whose yaw is undetermined, roll from the body's y bias sigma and
    pitch from its x bias sigma, atan(sigma / g) (the start's sigmas, else the configured turn-on
    sigma); no floor once the motion told the yaw. attitude_axes takes the larger floor."""
    from types import SimpleNamespace

    from gnssacc.core.config import load_config
    from gnssacc.prepare.attitude_axes import attitude_axes, level_floor

    cfg = load_config(overrides={"imu": {"accel_bias_sigma0_mg": [5.0, 40.0, 9.0]}})
    still = SimpleNamespace(yaw_evidence="undetermined", sigma_b_a=None)
    got = level_floor(cfg, still)
    assert got["roll"] == pytest.approx(np.degrees(np.arctan(0.040)))  # y: 40 mg
    assert got["pitch"] == pytest.approx(np.degrees(np.arctan(0.005)))
    assert got["bias_mg"] == pytest.approx([5.0, 40.0])
    measured = SimpleNamespace(yaw_evidence="undetermined", sigma_b_a=np.array([0.1, 0.2, 0.3]))
    assert level_floor(cfg, measured)["pitch"] == pytest.approx(
        np.degrees(np.arctan(0.1 / 9.80665))
    )
    for told in ("bank", "given", "orientation"):
        assert level_floor(cfg, SimpleNamespace(yaw_evidence=told, sigma_b_a=None)) is None
    assert level_floor(cfg, None) is None
    floor = attitude_axes(cfg, still)["sigma_floor_deg"]
    triad = attitude_axes(cfg)["triad_deg"]
    assert floor["roll"] == pytest.approx(max(got["roll"], triad))
    assert floor["pitch"] == pytest.approx(max(got["pitch"], triad))
    assert floor["yaw"] == pytest.approx(triad)
