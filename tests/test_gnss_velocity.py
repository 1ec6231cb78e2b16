"""GNSS (Doppler) velocity: the simulator's velocities against the truth, the factors' Jacobians
against central differences, the velocity fit in closed form, and both estimators on simulated
runs with known truth (with and without the velocities, horizontal-only velocities too)."""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest

from gnssacc.core.config import load_config
from gnssacc.core.gnss_fit import velocity_accelerations
from gnssacc.core.recording import GnssVelocity
from gnssacc.estimators.ekf import estimate
from gnssacc.estimators.settings import EkfSettings
from gnssacc.factors import (
    gnss_accel_factor,
    gnss_velocity_factor,
    preintegrated_velocity_factor,
)
from gnssacc.core.errors import InputError
from gnssacc.pipeline import check_velocity_methods, prepare
from gnssacc.prepare.tuning import measurement_stage
from gnssacc.sources.gnss_noise import apply_outages
from gnssacc.sources.sim import grade_config, simulate

LEVER = np.array([1.0, -0.5, -1.2])


def test_simulated_velocity_is_the_antennas_and_leaves_every_other_draw_alone():
    kw = dict(lever_arm_b=tuple(LEVER), noise="none", seed=3, gnss_rate_hz=100)
    run = simulate("car", 120.0, "consumer", velocity=True, **kw)
    bare = simulate("car", 120.0, "consumer", **kw)
    assert bare.gnss_vel is None
    np.testing.assert_array_equal(run.gnss.lat, bare.gnss.lat)
    np.testing.assert_array_equal(run.imu.f_b, bare.imu.f_b)
    # The antenna's velocity is the derivative of its (noise-free) fixes; the IMU's is not.
    p = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
    t = run.gnss.t
    v_fd = (p[2:] - p[:-2]) / (t[2:, None] - t[:-2, None])
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(v_fd - run.gnss_vel.v_ned[1:-1]) < 2e-3
    assert rms(v_fd - run.truth.v_n[1:-1]) > 0.03


def test_simulated_velocity_errors_have_the_stated_size_and_outages_remove_them():
    run = simulate("car", 300.0, "industrial", seed=4, velocity=True)
    vel = run.gnss_vel
    err = vel.v_ned - run.truth.v_n
    np.testing.assert_allclose(err.std(axis=0), vel.sigma_ned[0], rtol=0.2)
    assert np.all(np.abs(err.mean(axis=0)) < 0.3 * vel.sigma_ned[0])
    other = simulate("car", 300.0, "industrial", seed=5, velocity=True).gnss_vel.v_ned
    other = other - run.truth.v_n
    assert abs(np.corrcoef(err[:, 0], other[:, 0])[0, 1]) < 0.2  # seeds draw other errors
    cut = apply_outages(run, [(100.0, 130.0)])
    rel = cut.gnss_vel.t - cut.t_start
    assert not np.any((rel >= 100.0) & (rel < 130.0))
    assert len(cut.gnss_vel) == len(vel) - 30 and len(cut.gnss) == len(run.gnss) - 30


def test_velocity_fit_is_the_slope_of_the_velocities():
    t = np.arange(10.0)
    a = np.array([0.3, -0.2, 0.05])
    v = np.array([5.0, 1.0, 0.0]) + t[:, None] * a
    v[:, 2][4] = np.nan  # an unmeasured axis
    sig = np.full((10, 3), 0.05)
    full, a_n, var = velocity_accelerations(t, v, sig, 3, 2.5)
    assert not full[:2].any() and full[2:].all()
    np.testing.assert_allclose(a_n[2:, :2], np.tile(a[:2], (8, 1)), atol=1e-12)
    np.testing.assert_allclose(var[2:, 0], 0.05**2 / 2.0)  # (v2 - v0) / (2 dt)
    assert np.isnan(a_n[4:7, 2]).all() and np.isfinite(a_n[7:, 2]).all()
    gap = np.concatenate([t[:5], t[5:] + 10.0])
    full, _, _ = velocity_accelerations(gap, v, sig, 3, 2.5)
    assert full.tolist() == [False, False, True, True, True, False, False, True, True, True]


def _fd_check(factor, values: gtsam.Values) -> None:
    """Every key's whitened Jacobian of ``factor`` at ``values`` against central differences."""
    A, _ = factor.linearize(values).jacobian()
    col = 0
    for key in factor.keys():
        c = chr(gtsam.Symbol(key).chr())
        value = {"x": values.atPose3, "b": values.atConstantBias}.get(c, values.atVector)(key)
        dim = 6 if c in "xb" else 3
        for d in range(dim):
            step = np.zeros(dim)
            step[d] = 1e-6
            errs = []
            for s in (1.0, -1.0):
                moved = gtsam.Values(values)
                moved.update(key, value + s * step if c == "v" else value.retract(s * step))
                errs.append(factor.whitenedError(moved))
            num = (errs[0] - errs[1]) / 2e-6
            np.testing.assert_allclose(
                A[:, col + d], num, rtol=1e-4, atol=1e-5 * (1 + abs(A).max())
            )
        col += dim


def _values(rng):
    X, V, B = gtsam.symbol("x", 1), gtsam.symbol("v", 1), gtsam.symbol("b", 1)
    values = gtsam.Values()
    values.insert(X, gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 0.5, 3)), rng.normal(0, 50, 3)))
    values.insert(V, rng.normal(0, 5.0, 3))
    values.insert(B, gtsam.imuBias.ConstantBias(rng.normal(0, 0.05, 3), rng.normal(0, 1e-2, 3)))
    return (X, V, B), values


@pytest.mark.parametrize("axes", [[True, True, True], [True, True, False]])
def test_velocity_factor_jacobians_match_central_differences(axes):
    rng = np.random.default_rng(1)
    keys, values = _values(rng)
    axes = np.array(axes)
    w_ie = np.array([6e-5, 0.0, -4e-5])
    cov = np.diag([0.05, 0.06, 0.08]) ** 2
    omega = rng.normal(0, 0.3, 3)
    v = rng.normal(0, 5, 3)
    _fd_check(gnss_velocity_factor(keys, v, axes, omega, LEVER, w_ie, cov), values)
    # Folded: the earlier node carried by the preintegrated IMU to the velocity's time.
    params = gtsam.PreintegrationCombinedParams.MakeSharedD(9.8)
    params.setAccelerometerCovariance(np.eye(3) * 1e-3)
    params.setGyroscopeCovariance(np.eye(3) * 1e-5)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    params.setOmegaCoriolis(w_ie)
    pim = gtsam.PreintegratedCombinedMeasurements(params, gtsam.imuBias.ConstantBias())
    for _ in range(30):
        pim.integrateMeasurement(rng.normal([0, 0, -9.8], 0.5), rng.normal(0, 0.2, 3), 0.01)
    R_f = values.atPose3(keys[0]).rotation().matrix()
    f = preintegrated_velocity_factor(keys, pim, v, axes, omega, LEVER, w_ie, cov, R_f)
    _fd_check(f, values)
    # The acceleration factor on the measured axes only (horizontal velocities).
    acc = gnss_accel_factor(
        keys[0], keys[2], rng.normal(0, 1, 3), rng.normal(0, 1, 3), [0, 0, 9.8], cov, axes
    )
    _fd_check(acc, values)


def _ekf(run, velocity: bool, method: str = "ekf"):
    cfg = load_config(
        overrides={
            "imu": grade_config("industrial"),
            "gnss": {"lever_arm_b_m": LEVER.tolist()},
            "velocity": {"enabled": velocity},
            "nhc": {"enabled": False},
        }
    )
    prep = prepare(run, cfg, "none")
    sol = estimate(prep, EkfSettings.from_config(prep.cfg), method, output_times=run.truth.t)
    tr = run.truth
    e = run.origin.to_ned(sol.lat, sol.lon, sol.h) - run.origin.to_ned(tr.lat, tr.lon, tr.h)
    return sol, float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))


@pytest.fixture(scope="module")
def car():
    return simulate(
        "car", 200.0, "industrial", seed=2, lever_arm_b=tuple(LEVER), give_init=True, velocity=True
    )


def test_ekf_velocity_updates_shrink_the_horizontal_error_and_are_consistent(car):
    _, h_off = _ekf(car, False)
    sol, h_on = _ekf(car, True)
    st = sol.stats
    assert st["n_vel_updates"] == len(car.gnss_vel)  # the start's epoch too
    assert h_on < 0.6 * h_off, (h_on, h_off)
    assert 0.7 < st["nis_vel_mean"] < 1.3
    # NMEA-like velocities: north and east only (2 dof each), still most of the gain.
    vel = car.gnss_vel
    v = vel.v_ned.copy()
    s = vel.sigma_ned.copy()
    v[:, 2] = s[:, 2] = np.nan
    horizontal = replace(car, gnss_vel=GnssVelocity(vel.t, v, s))
    sol2, h2 = _ekf(horizontal, True)
    assert h2 < 0.7 * h_off and 0.7 < sol2.stats["nis_vel_mean"] < 1.3


def test_velocity_acceleration_needs_velocities_and_runs_with_them(car):
    sol, _ = _ekf(car, False, "ekf-vacc")
    assert sol.stats["n_acc_updates"] > 0.9 * len(car.gnss_vel)
    bare = replace(car, gnss_vel=None)
    with pytest.raises(InputError, match="GNSS velocities"):
        _ekf(bare, True, "ekf-vacc")
    # The tool refuses such a method before computing anything, naming the option.
    with pytest.raises(InputError, match="--methods.*smoother-vaccw fits"):
        check_velocity_methods(bare, ["ekf", "smoother-vaccw"])
    check_velocity_methods(car, ["ekf-vacc", "smoother-vaccw"])


def test_tuner_identifies_the_velocity_scale_only_where_there_are_velocities(car):
    cfg = load_config()
    params, kinds = measurement_stage(car, cfg)
    assert ("velocity", "sigma_scale") in params and kinds == ("vel",)
    params, kinds = measurement_stage(replace(car, gnss_vel=None), cfg)
    assert ("velocity", "sigma_scale") not in params and kinds == ()
    off = cfg.with_values({"velocity": {"enabled": False}}, "test")
    assert measurement_stage(car, off)[1] == ()


def test_window_consistent_velocity_acceleration_has_no_model_error_where_the_papers_has():
    from types import SimpleNamespace

    from gnssacc.core.earth import earth_rate_n, gravity_n
    from gnssacc.core.rotations import euler_to_dcm
    from gnssacc.estimators.aids.accel_model import window_samples
    from gnssacc.estimators.aids.gnss_velocity import VelocityEpochs
    from gnssacc.estimators.aids.velocity_window import (
        lever_term,
        slope_weights,
        velocity_window_acceleration,
    )
    from gnssacc.estimators.mechanization import kernel_force_integrals

    run = simulate(
        "car", 120.0, "perfect", noise="none", lever_arm_b=tuple(LEVER), seed=1, velocity=True
    )
    ep, tr, imu, z = VelocityEpochs(run, run.gnss_vel), run.truth, run.imu, np.zeros(3)
    full, a_n, _ = velocity_accelerations(ep.t, ep.v, ep.vel.sigma_ned, 3, 2.5)
    window, paper = [], []
    for j in np.flatnonzero(full)[::3]:
        t_win = ep.t[j - 2 : j + 1]
        k0, k1, h, w = window_samples(imu.t, t_win, slope_weights)
        F, M, G = kernel_force_integrals(imu.f_b[k0:k1], imu.omega_ib_b[k0:k1], h, w, z, z)
        lever = lever_term(imu.t, imu.omega_ib_b, t_win, ep.omega_b[j - 2 : j + 1], LEVER, z)
        R, g_n = euler_to_dcm(*tr.rpy[j]), gravity_n(tr.lat[j], tr.h[j])
        s = SimpleNamespace(R_nb=R, v_n=tr.v_n[j], P=np.zeros((15, 15)))
        m = velocity_window_acceleration(
            s, a_n[j], np.eye(3), F, M, G, g_n, earth_rate_n(tr.lat[j]), lever
        )
        window.append(m.dz)
        paper.append(R @ imu.f_b[np.searchsorted(imu.t, ep.t[j])] + g_n - a_n[j])
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    # Noise-free velocities and IMU: the window-consistent prediction (with the lever arm's term)
    # to a fraction of a mm/s^2; the paper's one-epoch specific force off by the window's change.
    assert rms(window) < 2e-3 and rms(paper) > 100 * rms(window), (rms(window), rms(paper))


def _smoother(run, velocity: bool, method: str = "smoother"):
    from gnssacc.estimators.settings import SmootherSettings
    from gnssacc.estimators.smoother import estimate as smooth

    cfg = load_config(
        overrides={
            "imu": grade_config("industrial"),
            "gnss": {"lever_arm_b_m": LEVER.tolist()},
            "velocity": {"enabled": velocity},
            "nhc": {"enabled": False},
        }
    )
    prep = prepare(run, cfg, "none")
    sol = smooth(prep, SmootherSettings.from_config(prep.cfg), method)[method]
    tr = run.truth
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    p_est = np.column_stack([np.interp(tr.t, sol.t, p[:, i]) for i in range(3)])
    e = p_est - run.origin.to_ned(tr.lat, tr.lon, tr.h)
    return sol, float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))


def test_smoother_velocity_factors_shrink_the_horizontal_error_and_are_consistent(car):
    _, h_off = _smoother(car, False)
    sol, h_on = _smoother(car, True)
    assert h_on < 0.7 * h_off, (h_on, h_off)
    assert sol.stats["n_vel_factors"] > 0.9 * len(car.gnss_vel)
    assert 0.6 < sol.stats["nis_vel_mean"] < 1.4
    # 5 Hz velocities, nodes at 2 Hz: the velocities between nodes are folded.
    fast = simulate(
        "car",
        60.0,
        "industrial",
        seed=3,
        gnss_rate_hz=5,
        lever_arm_b=tuple(LEVER),
        give_init=True,
        velocity=True,
    )
    sol5, _ = _smoother(fast, True)
    assert sol5.stats["n_vel_folded"] > 0 and sol5.stats["n_vel_factors"] > 0
    assert 0.6 < sol5.stats["nis_vel_mean"] < 1.4
