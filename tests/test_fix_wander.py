"""The fixes' slow wander learned from the fixes (``gnssacc.prepare.fix_wander``) and the
stationary check that allows for it.

Truth: synthetic fixes with a known random walk (or Gauss-Markov error) and white scatter; the
least-squares slope of a random walk checked by Monte Carlo; the simulated slow rover, whose
holds and drives the simulator knows.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gnssacc.prepare import fix_wander as fw
from gnssacc.prepare import stationary
from gnssacc.prepare.fix_noise import with_measured_sigmas
from gnssacc.prepare.stationary import detect_stationary, gnss_speed
from gnssacc.sources import sim

#: IMU-still stretches of a slow rover's run (holds and constant-speed straights) [s].
STRETCHES = [(0, 4), (6, 20), (22, 30), (35, 46), (77, 103), (104, 109), (150, 166), (185, 191)]
STRETCHES += [(196, 207), (212, 219), (268, 298), (300, 310), (323, 340), (352, 361)]


def _fixes(rng, rate_hz: float, white_m: float, q: float = 0.0, tau_s: float | None = None):
    """367 s of horizontal fixes of a vehicle at 0.4 m/s: white scatter plus a random walk of
    rate ``q`` [m^2/s] (or, with ``tau_s``, the Gauss-Markov error of the same short-term rate)."""
    t = np.arange(0.0, 367.0, 1.0 / rate_hz)
    if tau_s is None:
        slow = np.cumsum(rng.normal(0.0, np.sqrt(q / rate_hz), (len(t), 2)), axis=0)
    else:
        phi = np.exp(-1.0 / (rate_hz * tau_s))
        drive = rng.normal(0.0, np.sqrt(q * tau_s / 2.0 * (1.0 - phi**2)), (len(t), 2))
        slow = np.zeros_like(drive)
        for k in range(1, len(t)):
            slow[k] = phi * slow[k - 1] + drive[k]
    return t, slow + rng.normal(0.0, white_m, (len(t), 2)) + np.c_[0.4 * t, 0.1 * t]


@pytest.mark.parametrize("tau_s", [None, 30.0])
def test_the_wander_rate_is_read_from_the_fixes_in_still_stretches(tau_s):
    rng = np.random.default_rng(3)
    q = 2.0 * 0.6**2 / 30.0  # a receiver-filtered 0.6 m error of 30 s: 0.024 m^2/s
    est = [fw.fix_wander(*_fixes(rng, 20.0, 0.02, q, tau_s), STRETCHES) for _ in range(20)]
    assert 0.75 * q < np.median(est) < 1.25 * q
    assert min(est) > 0.5 * q


@pytest.mark.parametrize("rate_hz, white_m", [(20.0, 0.02), (1.0, 3.0), (10.0, 0.5)])
def test_white_fixes_show_no_wander(rate_hz, white_m):
    rng = np.random.default_rng(4)
    est = [fw.fix_wander(*_fixes(rng, rate_hz, white_m), STRETCHES) for _ in range(30)]
    assert sum(e > 0.0 for e in est) <= 1  # a 3-sigma test: rarely a false wander


def test_too_few_fixes_say_nothing():
    rng = np.random.default_rng(5)
    t, p = _fixes(rng, 1.0, 0.5, q=0.2)
    assert fw.fix_wander(t, p, [(0.0, 5.0), (50.0, 56.0)]) == 0.0
    assert fw.fix_wander(t, p, []) == 0.0


def test_the_speed_sigma_holds_a_random_walks_slope():
    """The fitted speed's variance grows by the least-squares slope of a random walk, 6 q / (5 T):
    Monte Carlo of the fit's spread against the stated sigma."""
    rng = np.random.default_rng(6)
    q, t = 0.024, np.arange(0.0, 6.0, 0.05)
    sigma = np.full((len(t), 3), 0.02)
    slopes = []
    for _ in range(3000):
        walk = np.cumsum(rng.normal(0.0, np.sqrt(q * 0.05), (len(t), 2)), axis=0)
        p = np.column_stack([walk + rng.normal(0.0, 0.02, (len(t), 2)), np.zeros(len(t))])
        slopes.append(np.polyfit(t, p[:, :2], 1)[0])
    _, sig_v = gnss_speed(t, p, sigma, corr_s=0.05, wander=q)
    measured = np.sqrt(np.mean(np.var(np.array(slopes), axis=0)))
    assert abs(sig_v / measured - 1.0) < 0.08
    _, white_only = gnss_speed(t, p, sigma, corr_s=0.05)
    assert white_only < 0.2 * measured  # what the check used to allow


def _rover(seed: int = 0):
    """The simulated slow rover's 20 Hz receiver-filtered fixes, their sigma measured from their
    scatter as the preparation does (the log states none)."""
    run = sim.simulate(
        "rover", 367.0, imu_grade="consumer", gnss_rate_hz=20.0, noise="filtered", seed=seed
    )
    g = replace(run.gnss, sigma_ned=np.tile([3.0, 3.0, 5.0], (len(run.gnss), 1)))
    return with_measured_sigmas(run.with_gnss(replace(g, sigma_stated=False)))[0]


def _holds_and_moves(run, report):
    """The share of each hold the report finds (those the IMU's still test finds: what the GNSS
    check decides), and the seconds it finds still while the rover moves."""
    truth = sim.dense_truth("rover", 367.0)
    m = report.mask(truth.t)
    still = [(run.imu.t[a], run.imu.t[b - 1]) for a, b in stationary.imu_still_stretches(run.imu)]
    holds = [
        s
        for s in run.sim.segments
        if s["kind"] == "hold" and any(a <= s["t0"] + 1.0 and s["t1"] - 1.0 <= b for a, b in still)
    ]
    assert len(holds) >= 3
    found = [np.mean(m[(truth.t > s["t0"] + 1.0) & (truth.t < s["t1"] - 1.0)]) for s in holds]
    return found, float(np.sum(m & (truth.speed > 0.02)) * np.median(np.diff(truth.t)))


@pytest.mark.slow
def test_a_slow_rovers_stops_are_found_through_its_fixes_wander(monkeypatch):
    """The rover's fixes wander 0.6 m over 30 s around a 3 cm scatter: the check that knows only the
    scatter refuses its stops as creeps; knowing the wander it finds them, and still refuses every
    0.4 m/s straight that the IMU cannot tell from rest."""
    run = _rover(0)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    found, moving_s = _holds_and_moves(run, report)
    assert 0.01 < report.fix_wander_m2ps < 0.05  # the simulator's 2 * 0.6^2 / 30 = 0.024
    assert min(found) > 0.9, found
    assert moving_s == 0.0
    monkeypatch.setattr(stationary, "fix_wander", lambda *a: 0.0)
    blind = detect_stationary(run.imu, run.gnss, run.origin)
    assert max(_holds_and_moves(run, blind)[0]) < 0.1  # the case is real
