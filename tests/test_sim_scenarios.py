"""Tests of the simulator's realistic scenarios (ugv-slow, car-city) and of reversing.

Expected timings are those of the real vehicles the scenarios imitate (a slow UGV: 235 s, parked
~36 s at the start and ~75 s at the end, 30 s backwards, at most 2.2 m/s; a city car: parked
~35 s, 10-15 m/s, corners of 15-60 m radius, stops of 10-30 s, a few seconds backwards at 1-2 m/s).
"""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.core.errors import InputError
from gnssacc.sources import sim
from gnssacc.core.units import DEG


def _spans(mask: np.ndarray, t: np.ndarray) -> list[tuple[float, float]]:
    """(first, last) times of each run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(t[a], t[b - 1]) for a, b in zip(edges[::2], edges[1::2])]


def _circle_radius(p: np.ndarray) -> float:
    """Least-squares (Kasa) circle fit to 2-D points."""
    A = np.column_stack([2.0 * p[:, 0], 2.0 * p[:, 1], np.ones(len(p))])
    cx, cy, c = np.linalg.lstsq(A, (p**2).sum(axis=1), rcond=None)[0]
    return float(np.sqrt(c + cx * cx + cy * cy))


def test_ugv_slow_timeline():
    rate = 20.0
    tr = sim.dense_truth("ugv-slow", 235.0, rate)
    t, v = tr.t, tr.speed
    stopped = _spans(v == 0.0, t)
    assert stopped[0][0] == 0.0 and stopped[0][1] == pytest.approx(36.0, abs=0.1)  # parked start
    assert stopped[-1][1] == 235.0 and stopped[-1][1] - stopped[-1][0] == pytest.approx(
        75.0, abs=0.1
    )
    still = _spans(
        (v == 0.0) & (np.abs(tr.omega_ib_b[:, 2] - tr.omega_ib_b[0, 2]) < 1e-6), t
    )  # no pivot
    short = [b - a for a, b in still[1:-1]]
    assert len(short) >= 3 and all(2.5 <= d <= 10.5 for d in short)  # short stops
    assert 2.19 < v.max() <= 2.2 + 1e-9
    back = _spans(v < 0.0, t)
    assert len(back) == 1 and back[0][1] - back[0][0] == pytest.approx(30.0, abs=0.1)
    # A pivot on the spot: yaw rate while stationary.
    assert np.any((v == 0.0) & (np.abs(tr.omega_ib_b[:, 2]) > 20.0 * DEG))
    # Radius turns forwards and backwards.
    moving = np.abs(v) > 0.5
    radius = np.abs(v[moving]) / np.maximum(np.abs(tr.omega_ib_b[moving, 2]), 1e-9)
    assert radius.min() == pytest.approx(4.0, rel=1e-3)


def test_car_city_timeline():
    rate = 10.0
    cycle = sim.make_scenario("car-city", 1.0).t_end
    assert 120.0 <= cycle <= 400.0  # a few minutes
    tr = sim.dense_truth("car-city", cycle, rate)
    t, v = tr.t, tr.speed
    stopped = _spans(v == 0.0, t)
    assert stopped[0][0] == 0.0 and stopped[0][1] == pytest.approx(35.0, abs=0.2)
    lights = [b - a for a, b in stopped[1:-1] if b - a > 5.0]
    assert len(lights) >= 2 and all(10.0 - 0.2 <= d <= 30.0 + 0.2 for d in lights)
    assert 10.0 <= v.max() <= 15.0 + 1e-9
    turning = (v > 1.0) & (np.abs(tr.omega_ib_b[:, 2]) > 0.02)  # forward turns (parking aside)
    radius = v[turning] / np.abs(tr.omega_ib_b[turning, 2])
    assert 15.0 * 0.999 <= radius.min() <= 15.0 * 1.01 and np.any(np.abs(radius - 60.0) < 0.5)
    back = _spans(v < 0.0, t)
    assert len(back) == 1 and 5.0 <= back[0][1] - back[0][0] <= 10.0
    assert -2.0 <= v.min() <= -1.0


@pytest.mark.parametrize("name", ["ugv-slow", "car-city"])
def test_cycles_repeat_up_to_30_min(name):
    scen = sim.make_scenario(name, 1800.0)
    cycle = sim.make_scenario(name, 1.0).t_end
    assert scen.t_end >= 1800.0
    t = np.arange(0.0, cycle, 0.5)
    yaw0 = 0.3
    first, later = scen.kinematics(t, yaw0), scen.kinematics(t + 3.0 * cycle, yaw0)
    np.testing.assert_allclose(later.speed, first.speed, atol=1e-9)
    np.testing.assert_allclose(later.yaw_rate, first.yaw_rate, atol=1e-12)
    assert len(sim.reversing_spans(scen.segments)) == len(
        sim.reversing_spans(sim.make_scenario(name, 1.0).segments)
    ) * (int(np.ceil(1800.0 / cycle)))


@pytest.mark.parametrize("name, radius", [("ugv-slow", 5.0), ("car-city", 6.0)])
def test_reversing_geometry(name, radius):
    run = sim.simulate(
        name, 280.0, imu_grade="perfect", imu_rate_hz=20.0, gnss_rate_hz=20.0, noise="none"
    )
    spans = sim.reversing_spans(run.sim.segments)
    assert len(spans) == 1
    a, b = spans[0]
    tr = sim.build_trajectory(name, 280.0, 20.0).at(run.truth.t)
    inside = (tr.t > a) & (tr.t < b)
    # The truth speed is negative exactly over the logged span.
    assert np.all(tr.speed[inside] < 0.0) and np.all(tr.speed[~inside] >= 0.0)
    # Body x points against the velocity: no side slip, negative forward velocity.
    v_b = np.einsum("kji,kj->ki", tr.R_nb[inside], tr.v_n[inside])
    assert np.all(v_b[:, 0] < 0.0)
    np.testing.assert_allclose(v_b[:, 1:], 0.0, atol=1e-12)
    # The turn made while reversing is an arc of the requested radius (fitted to positions).
    turn = [s for s in run.sim.segments if s["reverse"] and s["kind"] == "turn"][0]
    plateau = (run.truth.t > turn["t0"] + 1.05) & (run.truth.t < turn["t1"] - 1.05)
    p = run.origin.to_ned(run.truth.lat[plateau], run.truth.lon[plateau], run.truth.h[plateau])
    assert _circle_radius(p[:, :2]) == pytest.approx(radius, rel=1e-3)


def test_custom_scenario_reversing_segments():
    s = sim.Scenario("back").hold(2.0).speed_to(-2.0, 3.0).cruise(4.0).turn(-90.0, radius_m=8.0)
    s.hill(1.0, slope_deg=5.0).speed_to(0.0, 3.0).hold(1.0)
    kinds = [(g["kind"], g["reverse"]) for g in s.segments]
    assert kinds == [
        ("hold", False),
        ("speed", True),
        ("cruise", True),
        ("turn", True),
        ("hill", True),
        ("speed", True),
        ("hold", False),
    ]
    traj = sim.build_trajectory(
        s, s.t_end, 50.0, initial_yaw_deg=0.0, origin_llh_deg=(10.0, 20.0, 100.0)
    )
    tr = traj.at(np.arange(0.0, s.t_end, 0.1))
    # Reversing over the hill: back at the starting height, and the nose points downhill on the
    # way up (height rises while pitch < 0).
    assert tr.h[-1] == pytest.approx(100.0, abs=1e-6)
    hill = [g for g in s.segments if g["kind"] == "hill"][0]
    climb = (tr.t > hill["t0"] + 2.0) & (tr.t < hill["t0"] + 4.0)
    assert np.all(tr.rpy[climb, 1] < 0.0) and np.all(np.diff(tr.h[climb]) > 0.0)
    end = traj.at([s.t_end])
    assert end.rpy[0, 2] == pytest.approx(-np.pi / 2)
    assert sim.reversing_spans(s.segments) == [(2.0, s.segments[-1]["t0"])]
    with pytest.raises(InputError):
        sim.Scenario("x").turn(90.0, radius_m=10.0)  # a radius needs speed
