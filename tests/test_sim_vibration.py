"""Tests of the simulated vibration (gnssacc.sources.sim_vibration) against independent truth.

The IMU is integrating (sample k = mean over (t[k-1], t[k]]), so the expected values are interval
means of the continuous vibration, computed here by numerical quadrature.
"""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.sources import sim, sim_vibration
from gnssacc.core.units import DEG

DT = 0.01

#: Every error source off; tests switch on the one they look at.
ALL_OFF = {
    **{k: 0.0 for k in sim.GRADE_KEYS if k != "bias_correlation_time_s"},
    **{k: 0.0 for k in sim.UNMODELLED_KEYS},
}


def _simpson_means(phase_a, phase_b, fn, m=2000):
    """Mean of fn(phi) over each interval with phi linear from phase_a to phase_b (Simpson, m even)."""
    u = np.linspace(0.0, 1.0, m + 1)
    w = np.ones(m + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    w /= 3.0 * m
    phi = phase_a[:, None] + (phase_b - phase_a)[:, None] * u[None, :]
    return fn(phi) @ w


def _boxcar_autocov(lag, dt, lo, hi):
    """Autocovariance at ``lag`` samples of interval means of unit-variance flat-band noise (quadrature)."""
    f = np.linspace(lo, hi, 400_001)
    s = 1.0 / (2.0 * (hi - lo))  # two-sided PSD
    return 2.0 * np.trapezoid(s * np.sinc(f * dt) ** 2 * np.cos(2.0 * np.pi * f * lag * dt), f)


def _residual(scenario, duration, overrides, seed=2):
    run = sim.simulate(
        scenario, duration, imu_grade="consumer", imu_overrides=overrides, noise="none", seed=seed
    )
    perfect = sim.simulate(scenario, duration, imu_grade="perfect", noise="none")
    return run, run.imu.f_b - perfect.imu.f_b, run.imu.omega_ib_b - perfect.imu.omega_ib_b


def test_harmonic_interval_mean_matches_numerical_integration():
    rng = np.random.default_rng(0)
    f = rng.uniform(20.0, 80.0, 40)  # fundamental per interval [Hz]
    edges = 1.3 + 2.0 * np.pi * DT * np.concatenate([[0.0], np.cumsum(f)])
    offsets = np.array([0.0, 1.0, -2.5])
    for order in (1, 2, 3):
        got = sim_vibration.harmonic_interval_mean(edges, order, offsets)
        for j, off in enumerate(offsets):
            ref = _simpson_means(edges[:-1], edges[1:], lambda p: np.sin(order * p + off))  # noqa: B023 (called within the iteration)
            np.testing.assert_allclose(got[:, j], ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(
            sim_vibration.harmonic_interval_mean(edges, order, 1.0), got[:, 1], atol=1e-15
        )
    # A harmonic at exactly the sample rate averages to zero in every interval.
    edges = 0.7 + 2.0 * np.pi * np.arange(11) * (100.0 * DT)
    np.testing.assert_allclose(sim_vibration.harmonic_interval_mean(edges, 1, 0.3), 0.0, atol=1e-12)


@pytest.mark.parametrize("band", [(5.0, 100.0), (20.0, 230.0)])
def test_band_limited_interval_means_have_boxcar_statistics(band):
    # Variance and autocovariances of the synthesised interval means equal those of the continuous
    # band-limited process averaged over each interval (including aliasing above 50 Hz).
    z = sim_vibration.band_limited_interval_means(
        2**17, DT, band, np.random.default_rng(1), channels=4
    )
    r0 = _boxcar_autocov(0, DT, *band)
    assert r0 < 1.0
    np.testing.assert_allclose(z.var(axis=0), r0, rtol=0.03)
    for lag in (1, 2, 5):
        cov = np.mean(z[lag:] * z[:-lag])
        assert cov == pytest.approx(_boxcar_autocov(lag, DT, *band), abs=0.02 * r0)
    assert np.all(np.abs(z.mean(axis=0)) < 0.01 * np.sqrt(r0))


def test_engine_vibration_frequency_follows_speed_and_idles_at_rest():
    env = sim.VIBRATION_ENVIRONMENT
    rel = np.asarray(env["vib_engine_harmonics"])
    amp = np.asarray(sim.imu_error_model("consumer")["vib_engine_gyro_dps"]) * DEG
    over = {**ALL_OFF, "vib_engine_gyro_dps": amp / DEG, "vib_engine_accel_mps2": 0.5}
    for speed in (0.0, 10.0):
        scen = sim.Scenario(f"v{speed}", speed).cruise(70.0)
        _, _, dg = _residual(scen, 60.0, over)
        f0 = env["vib_engine_idle_hz"] + env["vib_engine_hz_per_mps"] * speed
        alias = abs(f0 - 100.0 * round(f0 / 100.0))
        spec = np.abs(np.fft.rfft(dg[:, 0])) ** 2
        peak = np.fft.rfftfreq(len(dg), DT)[np.argmax(spec)]
        assert abs(peak - alias) < 0.05 * f0, (speed, peak, alias)
        # Sampled sines: variance sum of (A r_h sinc(h f0 dt))^2 / 2 (the wander changes f0 by ~3 %).
        expected = np.sqrt(
            0.5 * np.sum((rel[:, None] * amp * np.sinc(np.arange(1, 4)[:, None] * f0 * DT)) ** 2, 0)
        )
        np.testing.assert_allclose(dg.std(axis=0), expected, rtol=0.08)


def test_road_vibration_level_grows_with_speed():
    model = sim.imu_error_model("consumer")
    rms_g = np.asarray(model["vib_road_gyro_dps"]) * DEG
    rms_a = np.asarray(model["vib_road_accel_mps2"])
    over = {
        **ALL_OFF,
        "vib_road_gyro_dps": model["vib_road_gyro_dps"],
        "vib_road_accel_mps2": rms_a,
    }
    atten = np.sqrt(_boxcar_autocov(0, DT, *model["vib_road_band_hz"]))
    _, da, dg = _residual("static", 20.0, over)
    assert not np.any(da) and not np.any(dg)  # no road vibration at rest
    for speed in (5.0, 15.0):
        _, da, dg = _residual(sim.Scenario(f"v{speed}", speed).cruise(70.0), 60.0, over)
        gain = speed / model["vib_road_ref_speed_mps"]
        np.testing.assert_allclose(dg.std(axis=0), gain * rms_g * atten, rtol=0.05)
        np.testing.assert_allclose(da.std(axis=0), gain * rms_a * atten, rtol=0.05)


def test_fast_fft_length():
    for n in (1, 2, 7, 97, 1000, 180_001, 3_600_001):
        m = sim_vibration._fast_len(n)
        assert m >= n and m < 1.25 * n + 2
        k = m
        for p in (2, 3, 5):
            while k % p == 0:
                k //= p
        assert k == 1
