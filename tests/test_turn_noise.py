"""The gyro noise that grows with the rotation performed (``[imu] gyro_turn_error_ppm``) against
a Monte Carlo of what it stands for: constant gyro cross-axis and scale-factor errors.

A level platform turns about its down axis at a constant rate ``r`` through ``a = r T`` radians.
A gyro with cross-axis errors ``M_xz``, ``M_yz`` and a scale-factor error ``S_z`` (each of 1-sigma
``s``, constant over the run) then reads ``(M_xz r, M_yz r, (1 + S_z) r)``, and the attitude it
integrates ends tilted by ``2 sin(a / 2)`` times ``(M_xz, M_yz)`` turned with the body, and yawed by
``S_z a``: per-axis variance ``s^2 (2 - 2 cos a)`` for roll and pitch, ``s^2 a^2`` for yaw. The
model's random walk in the angle turned gives ``s^2 a`` (one radian of decorrelation), which the
Monte Carlo must match at ``a = 1`` rad (0.92 s^2 and s^2 in truth) -- and which the white noise
alone misses by orders of magnitude.
"""

from __future__ import annotations

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gnssacc.core.config import load_config
from gnssacc.estimators.layout import ATT, N_NAV
from gnssacc.estimators.mechanization import Propagator, turn_rates
from gnssacc.estimators.settings import EkfSettings, SmootherSettings
from gnssacc.estimators.smoother_graph import ImuModel, preintegrate

PPM = 5000.0  # 1-sigma of each cross-axis and scale-factor error [ppm]
RATE = 0.5  # yaw rate [rad/s]
T = 2.0  # turn time [s]: one radian
HZ = 100.0
G = 9.80665


def _turning_imu():
    n = int(round(T * HZ)) + 1
    t = np.linspace(0.0, T, n)
    f_b = np.tile([0.0, 0.0, -G], (n, 1))
    w_b = np.tile([0.0, 0.0, RATE], (n, 1))
    return SimpleNamespace(t=t, f_b=f_b, omega_ib_b=w_b)


def _monte_carlo(n_draws: int = 4000, seed: int = 3) -> np.ndarray:
    """Sample covariance of the attitude error [rad^2] (level start frame: roll, pitch, yaw axes)
    that constant cross-axis and scale-factor errors of 1-sigma :data:`PPM` leave after the turn,
    from the exact rotations (no small-angle model)."""
    rng = np.random.default_rng(seed)
    s = PPM * 1e-6
    steps = int(round(T * HZ))
    dt = T / steps
    true_end = Rotation.from_rotvec([0.0, 0.0, RATE * T])
    # One draw of (M_xz, M_yz, S_z) a row, in the generator's order; all draws integrated at once
    # (a stack of rotations), step by step as one draw would be.
    m_xz, m_yz, s_z = (rng.standard_normal((n_draws, 3)) * s).T
    w_meas = np.column_stack([m_xz * RATE, m_yz * RATE, (1.0 + s_z) * RATE])
    step = Rotation.from_rotvec(w_meas * dt)
    R = Rotation.from_quat(np.tile([0.0, 0.0, 0.0, 1.0], (n_draws, 1)))
    for _ in range(steps):
        R = R * step
    errors = (R * true_end.inv()).as_rotvec()  # estimate minus truth, nav frame
    return np.cov(errors.T)


@pytest.fixture(scope="module")
def mc() -> np.ndarray:
    return _monte_carlo()


def test_monte_carlo_matches_the_closed_form(mc):
    s2, a = (PPM * 1e-6) ** 2, RATE * T
    # 4000 draws: a variance is known to sqrt(2 / 4000) = 2.2 %.
    np.testing.assert_allclose(np.diag(mc)[:2], s2 * (2.0 - 2.0 * np.cos(a)), rtol=0.08)
    np.testing.assert_allclose(mc[2, 2], s2 * a**2, rtol=0.08)


def _settings(ppm: float):
    """Defaults with a small white gyro noise and no gyro bias walk, and ``ppm``."""
    imu = {"gyro_turn_error_ppm": ppm, "gyro_arw_deg_rth": 0.01, "gyro_bias_instability_deg_h": 0.0}
    return load_config(overrides={"imu": imu})


def _ekf_attitude_cov(ppm: float) -> np.ndarray:
    imu = EkfSettings.from_config(_settings(ppm)).imu
    d = _turning_imu()
    z3, seg = np.zeros(3), np.zeros(0, np.int64)
    prop = Propagator(
        d.t,
        d.f_b,
        d.omega_ib_b,
        imu.accel_psd,
        imu.gyro_psd,
        imu.accel_bias_rw_psd,
        imu.gyro_bias_rw_psd,
        (seg, seg, np.zeros((0, 3)), np.zeros((0, 3))),
        q_turn=imu.gyro_turn_psd,
    )
    s = SimpleNamespace(
        pos=np.array([0.0, 0.0, 0.0]),
        v_n=z3.copy(),
        R_nb=np.eye(3),
        b_a=z3.copy(),
        b_g=z3.copy(),
        P=np.zeros((N_NAV, N_NAV)),
    )
    prop.advance(s, 1, 0.0, T)
    return s.P[ATT, ATT]


def _smoother_rotation_cov(ppm: float) -> np.ndarray:
    settings = SmootherSettings.from_config(_settings(ppm))
    model = ImuModel(settings, G, np.zeros(3))
    d = _turning_imu()
    dt_all = np.diff(d.t, prepend=d.t[0])
    bias = gtsam.imuBias.ConstantBias()
    w_turn = turn_rates(d.t, d.omega_ib_b)
    pim = preintegrate(d, model, bias, 0.0, T, 1, len(d.t), (None, None), dt_all, w_turn)
    return _right_perturbation(np.asarray(pim.preintMeasCov())[:3, :3], RATE * T)


def _right_perturbation(cov_tangent: np.ndarray, angle: float) -> np.ndarray:
    """GTSAM's tangent-space preintegration states the covariance of the rotation vector
    ``theta``; a rotation error ``R Exp(d)`` is ``d = Jr(theta) d_theta``, with the right Jacobian
    of SO(3) ``Jr = I - (1 - cos a) / a^2 [theta]x + (a - sin a) / a^3 [theta]x^2`` (``theta`` =
    ``a`` about down here)."""
    K = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) * angle
    a = angle
    Jr = np.eye(3) - (1.0 - np.cos(a)) / a**2 * K + (a - np.sin(a)) / a**3 * K @ K
    return Jr @ cov_tangent @ Jr.T


@pytest.mark.parametrize("estimator", ["ekf", "smoother"])
def test_turn_noise_covers_constant_cross_axis_errors(mc, estimator):
    cov = _ekf_attitude_cov if estimator == "ekf" else _smoother_rotation_cov
    with_turn, without = np.diag(cov(PPM)), np.diag(cov(0.0))
    truth = np.diag(mc)
    # Within 15 % of the Monte Carlo per axis (the model's s^2 a against 0.92 s^2 for roll and
    # pitch at one radian, the smoother's rate rounded to 5 %, 2.2 % sampling error) ...
    np.testing.assert_allclose(with_turn, truth, rtol=0.15)
    # ... where the white noise alone states a variance hundreds of times too small (a NEES of
    # hundreds: the overconfident attitude of the consumer runs).
    assert np.all(truth / without > 100.0), truth / without


def test_no_turn_no_extra_noise():
    """A platform that does not turn gets the white noise only (the term grows with the angle
    turned, not with time): ``q_g T`` [rad^2] per axis, up to the smoother's bias walk floor."""
    d = _turning_imu()
    d.omega_ib_b[:] = 0.0
    imu = EkfSettings.from_config(_settings(PPM)).imu
    model = ImuModel(SmootherSettings.from_config(_settings(PPM)), G, np.zeros(3))
    dt_all = np.diff(d.t, prepend=d.t[0])
    bias = gtsam.imuBias.ConstantBias()
    w_turn = turn_rates(d.t, d.omega_ib_b)
    pim = preintegrate(d, model, bias, 0.0, T, 1, len(d.t), (None, None), dt_all, w_turn)
    cov = np.diag(np.asarray(pim.preintMeasCov())[:3, :3])
    np.testing.assert_allclose(cov, imu.gyro_psd * T, rtol=1e-4)


def test_turn_rates_are_the_window_means_and_follow_the_arrays_they_are_given():
    """Each sample's rate averaged over the samples within half the window (by hand, in a loop);
    reused for the same arrays (the tuner's passes), computed again for other ones or for the
    same array changed in place."""
    rng = np.random.default_rng(3)
    t = np.arange(400) * 0.125  # exact in binary: the window's edges fall on samples
    w = rng.normal(size=(len(t), 3))
    by_hand = np.array([w[np.abs(t - tk) <= 0.25].mean(axis=0) for tk in t])
    first = turn_rates(t, w, 0.5)
    np.testing.assert_allclose(first, by_hand, rtol=1e-9, atol=1e-12)
    assert turn_rates(t, w, 0.5) is first
    other = w.copy()
    other[100, 2] += 5.0
    by_hand[np.abs(t - t[100]) <= 0.25, 2] += 5.0 / 5  # the five samples around it
    np.testing.assert_allclose(turn_rates(t, other, 0.5), by_hand, rtol=1e-9, atol=1e-12)
    w[100, 2] += 5.0  # the first array, changed in place
    np.testing.assert_allclose(turn_rates(t, w, 0.5), by_hand, rtol=1e-9, atol=1e-12)
