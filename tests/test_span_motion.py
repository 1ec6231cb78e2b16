"""The IMU-linked GNSS test of a stationary span (:mod:`gnssacc.prepare.span_motion`).

Truth is built here from closed forms: a level vehicle on a straight line or a circle at known
speeds, its IMU readings (specific force, body FRD, and angular rate) written from the motion,
its fixes the true positions plus Gaussian noise at a stated sigma.
"""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.core.recording import GnssFixes, GnssVelocity, ImuData
from gnssacc.core.stationary_params import StationaryParams
from gnssacc.prepare.span_motion import level_path, linked_motion, outward_samples

G = 9.81
DT = 0.01


class _Span:
    """The fields of a stationary span the test reads (sample range and mean readings)."""

    def __init__(self, imu: ImuData, t0: float, t1: float):
        self.i_start = int(np.searchsorted(imu.t, t0))
        self.i_end = int(np.searchsorted(imu.t, t1, side="right"))
        self.t_start, self.t_end = float(imu.t[self.i_start]), float(imu.t[self.i_end - 1])
        self.f_mean_b = imu.f_b[self.i_start : self.i_end].mean(axis=0)
        self.omega_mean_b = imu.omega_ib_b[self.i_start : self.i_end].mean(axis=0)


def _velocities(t, v, yaw: float, rng, sigma=0.05, rate_hz=5.0) -> GnssVelocity:
    """Receiver velocities (north, east; down not measured) at ``rate_hz`` of a level straight
    drive with speed ``v`` [m/s] at times ``t``, heading ``yaw`` [rad], 1-sigma ``sigma``."""
    t_v = np.arange(t[0], t[-1] + 1e-9, 1.0 / rate_hz)
    speed = np.interp(t_v, t, v)
    v_ned = np.column_stack([speed * np.cos(yaw), speed * np.sin(yaw), np.full_like(t_v, np.nan)])
    v_ned[:, :2] += rng.normal(0.0, sigma, (len(t_v), 2))
    sig = np.column_stack([np.full((len(t_v), 2), sigma), np.full(len(t_v), np.nan)])
    return GnssVelocity(t_v, v_ned, sig)


def _straight(speed_of_t, duration: float, yaw: float, rng, sigma=3.0, bias=(0.05, -0.08)):
    """A level straight drive along heading ``yaw`` [rad]: the IMU (with accelerometer biases
    [m/s^2]) and 1 Hz fixes [m, north/east as lat/lon-free NED]."""
    t = np.arange(0.0, duration + DT / 2, DT)
    v = speed_of_t(t)
    a = np.gradient(v, DT)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT)])
    f_b = np.column_stack([a + bias[0], np.full_like(t, bias[1]), np.full_like(t, -G)])
    imu = ImuData(t, f_b, np.zeros((len(t), 3)))
    t_fix = np.arange(0.0, duration + 1e-9, 1.0)
    s_fix = np.interp(t_fix, t, s)
    p_n = np.column_stack([s_fix * np.cos(yaw), s_fix * np.sin(yaw), np.zeros_like(s_fix)])
    p_n[:, :2] += rng.normal(0.0, sigma, (len(t_fix), 2))
    zeros = np.zeros(len(t_fix))
    fixes = GnssFixes(t_fix, zeros, zeros, zeros, np.full((len(t_fix), 3), sigma))
    return imu, fixes, p_n, t, v


def test_level_path_closed_form_both_sides():
    # Constant acceleration a before and after the edge, and a constant turn: P is the path
    # minus the edge's straight extrapolation, in the span's level axes.
    t = np.arange(0.0, 10.0 + DT / 2, DT)
    a, w = 0.4, 0.05  # [m/s^2] along body x; yaw rate [rad/s] outside the span
    f_b = np.column_stack([np.full_like(t, a), np.zeros_like(t), np.full_like(t, -G)])
    imu = ImuData(t, f_b, np.zeros((len(t), 3)))
    p = StationaryParams()
    f_ref, w_ref = np.array([0.0, 0.0, -G]), np.zeros(3)
    i_edge = 500
    for before in (True, False):
        idx = outward_samples(t, i_edge, before, 4.0, 3 * DT)
        path = level_path(imu, idx, i_edge, f_ref, w_ref, p)
        tt, P, bound = path.t, path.P, path.bound
        tau = tt - t[i_edge]
        assert np.allclose(P[:, 0], 0.5 * a * tau**2, rtol=2e-2, atol=1e-3)
        outward = np.argsort(np.abs(tau))  # the bound grows away from the edge
        assert np.allclose(P[:, 1], 0.0) and np.all(np.diff(bound[outward]) > 0.0)
        assert np.all(np.diff(tt) > 0.0)  # the path is in time order
    # Turning at speed u with no specific force along x: a circle, P = circle - tangent line.
    u = 5.0
    f_turn = np.column_stack([np.zeros_like(t), np.full_like(t, u * w), np.full_like(t, -G)])
    imu = ImuData(t, f_turn, np.tile([0.0, 0.0, w], (len(t), 1)))
    idx = outward_samples(t, i_edge, False, 4.0, 3 * DT)
    path = level_path(imu, idx, i_edge, f_ref, w_ref, p)
    tt, P = path.t, path.P
    tau = tt - t[i_edge]
    circle = np.column_stack([u / w * np.sin(w * tau) - u * tau, u / w * (1 - np.cos(w * tau))])
    assert np.max(np.abs(P - circle)) < 0.01 * np.max(np.abs(circle)) + 1e-3


def test_level_path_of_an_antenna_swinging_in_a_pivot():
    # A pivot on the spot at yaw rate w with the IMU at the centre: the IMU does not move, the
    # antenna at lever arm l swings on a circle, P = R_z(w tau) l_xy - l_xy.
    t = np.arange(0.0, 10.0 + DT / 2, DT)
    w, lever = 0.3, np.array([1.0, -0.5, -0.8])
    f_b = np.tile([0.0, 0.0, -G], (len(t), 1))
    imu = ImuData(t, f_b, np.tile([0.0, 0.0, w], (len(t), 1)))
    p, i_edge = StationaryParams(), 200
    for before in (True, False):
        idx = outward_samples(t, i_edge, before, 5.0, 3 * DT)
        path = level_path(imu, idx, i_edge, f_b[0], np.zeros(3), p, lever)
        tt, P = path.t, path.P
        a = w * (tt - t[i_edge])
        swing = np.column_stack(
            [
                np.cos(a) * lever[0] - np.sin(a) * lever[1],
                np.sin(a) * lever[0] + np.cos(a) * lever[1],
            ]
        )
        assert np.max(np.abs(P - (swing - lever[:2]))) < 0.01


def test_outward_samples_stop_at_an_imu_gap():
    t = np.concatenate([np.arange(0.0, 5.0, DT), np.arange(5.5, 10.0, DT)])
    idx = outward_samples(t, 100, False, 8.0, 3 * DT)
    assert t[idx[-1]] < 5.0 and idx[0] == 101
    assert len(outward_samples(t, 100, True, 8.0, 3 * DT)) == 100


def test_cruise_through_an_outage_is_refuted_and_speed_found():
    # 4 m/s IMU-still cruise; the "span" 30-36 s lies in a 20-45 s outage (fixes removed).
    rng = np.random.default_rng(1)
    imu, fixes, p_n, t, _ = _straight(lambda t: np.full_like(t, 4.0), 60.0, 0.7, rng)
    keep = (fixes.t < 20.0) | (fixes.t > 45.0)
    fixes, p_n = fixes.select(keep), p_n[keep]
    p = StationaryParams()
    linked = linked_motion(imu, _Span(imu, 30.0, 36.0), fixes, p_n, p, DT)
    assert linked is not None and linked.shows_motion(p)
    assert abs(linked.speed_mps - 4.0) < 0.8


def test_stop_after_braking_in_an_outage_is_kept_at_the_stated_false_alarm_rate():
    # Brake from 6 m/s to rest over 4 s, rest 8 s, pull away; the rest is inside a 6 s outage.
    # At rest the ratio is chi-square with 2 dof: the refusal rate over many noise draws stays
    # near the 2-D 3.44-sigma probability (0.27 %), far below what motion would give.
    def speed(t):
        return np.clip(6.0 - 1.5 * (t - 20.0), 0.0, 6.0) * (t < 30.0) + np.clip(
            1.5 * (t - 32.0), 0.0, 6.0
        ) * (t >= 30.0)

    p = StationaryParams()
    refused, glr = 0, []
    for seed in range(300):
        rng = np.random.default_rng(seed)
        imu, fixes, p_n, _, _ = _straight(speed, 50.0, rng.uniform(0, 2 * np.pi), rng, sigma=2.0)
        keep = (fixes.t < 23.0) | (fixes.t > 29.0)
        linked = linked_motion(imu, _Span(imu, 24.5, 29.5), fixes.select(keep), p_n[keep], p, DT)
        assert linked is not None and linked.n_fixes >= 8
        refused += linked.shows_motion(p)
        glr.append(linked.glr)
    assert refused <= 4  # binomial(300, 0.0027) exceeds 4 with probability < 1 %
    # The ratio's distribution: mean about 2 (chi-square 2 dof) or below (widened sigmas).
    assert 0.3 < np.mean(glr) < 2.6


@pytest.mark.parametrize("speed", [1.5, 3.0])
def test_slow_cruise_refuted_with_fixes_on_one_side_only(speed):
    # The span ends the record's fixes: only those before it (and none inside) can tell.
    rng = np.random.default_rng(7)
    imu, fixes, p_n, _, _ = _straight(lambda t: np.full_like(t, speed), 40.0, -1.2, rng, sigma=1.5)
    keep = fixes.t < 25.0
    p = StationaryParams()
    linked = linked_motion(imu, _Span(imu, 27.0, 33.0), fixes.select(keep), p_n[keep], p, DT)
    assert linked is not None and linked.shows_motion(p)


def test_crawl_refuted_by_gnss_velocities_alone():
    # A 0.5 m/s IMU-still crawl with no fixes at all, only the receiver's velocities up to 20 s
    # before the span: carried by the IMU they show the crawl; without them there is no verdict.
    rng = np.random.default_rng(3)
    imu, _, _, t, v = _straight(lambda t: np.full_like(t, 0.5), 60.0, 2.0, rng)
    vel = _velocities(t, v, 2.0, rng)
    vel = vel.select(vel.t < 20.0)
    none = GnssFixes(np.zeros(0), *(np.zeros(0),) * 3, np.zeros((0, 3)))
    p, span = StationaryParams(), _Span(imu, 30.0, 36.0)
    linked = linked_motion(imu, span, none, np.zeros((0, 3)), p, DT, velocity=vel)
    assert linked is not None and linked.shows_motion(p)
    assert abs(linked.speed_mps - 0.5) < 0.1
    assert linked_motion(imu, span, none, np.zeros((0, 3)), p, DT) is None


def test_stop_with_gnss_velocities_kept_at_the_stated_false_alarm_rate():
    # As the braking test above, with 5 Hz velocities (0.05 m/s) as well, outside a 6 s outage.
    def speed(t):
        return np.clip(6.0 - 1.5 * (t - 20.0), 0.0, 6.0) * (t < 30.0) + np.clip(
            1.5 * (t - 32.0), 0.0, 6.0
        ) * (t >= 30.0)

    p, refused = StationaryParams(), 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        yaw = rng.uniform(0, 2 * np.pi)
        imu, fixes, p_n, t, v = _straight(speed, 50.0, yaw, rng, sigma=2.0)
        vel = _velocities(t, v, yaw, rng)
        keep, keep_v = (fixes.t < 23.0) | (fixes.t > 29.0), (vel.t < 23.0) | (vel.t > 29.0)
        span = _Span(imu, 24.5, 29.5)
        linked = linked_motion(
            imu, span, fixes.select(keep), p_n[keep], p, DT, velocity=vel.select(keep_v)
        )
        assert linked is not None and linked.n_fixes > 100
        refused += linked.shows_motion(p)
    assert refused <= 3  # binomial(200, 0.0027) exceeds 3 with probability < 2 %
