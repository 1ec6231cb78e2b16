"""Clean simulated recordings for the input checks' false-alarm rate: correct units, clocks, axes
and coordinates, with the traits that fooled single heuristics on real data (long parks, slow
vehicles, skid-steer pivots, high-rate fixes with correlated errors and no sigmas, Gauss-Markov
fix errors, consumer-grade vibration and turn-on biases). Shared by
``tests/test_false_alarms.py`` and ``bench/bench_false_alarms.py``.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

from gnssacc.sources.sim import simulate

#: (scenario, duration [s], GNSS rate [Hz], noise profiles): short enough for a CI run.
SCENARIOS = (
    ("car", 90.0, 1.0, ("white", "gm", "precise")),
    ("car-city", 120.0, 1.0, ("white", "gm")),
    ("ugv", 120.0, 1.0, ("white", "precise")),
    ("ugv-slow", 240.0, 1.0, ("white", "gm")),
    ("rover", 120.0, 10.0, ("filtered",)),
    ("turns", 60.0, 5.0, ("white",)),
    ("straight", 60.0, 1.0, ("white",)),
    ("static", 60.0, 1.0, ("white",)),
)
GRADES = ("consumer", "industrial", "tactical")


#: The cases of issue 32 (one clock for every stream, proven corrections applied): stamps on the
#: UNIX clock (2024), where the GPS - UTC leap seconds are a known clock relation, a truth on the
#: IMU's clock (as a CSV run's), RTK-grade fixes that hold a truth to centimetres, and wheel
#: odometry on the IMU's clock.
UNIX_2024 = 1709294400.0
ISSUE32 = (
    ("car", 90.0, "white", {"t_start_s": UNIX_2024}),
    ("car-city", 120.0, "rtk", {}),
    ("ugv", 120.0, "precise", {"t_start_s": UNIX_2024, "odom_hz": 10.0}),
)


def issue32_cases(n_seeds: int = 2):
    """``(name, run)`` of :data:`ISSUE32` for every grade and seed (truth on the IMU's clock)."""
    for (scenario, duration, noise, kw), grade, seed in itertools.product(
        ISSUE32, GRADES, range(n_seeds)
    ):
        run = simulate(scenario, duration, imu_grade=grade, noise=noise, seed=2000 + seed, **kw)
        yield (
            f"{scenario}/{grade}/{noise}/{2000 + seed}/issue32",
            replace(run, truth_on_imu_clock=True),
        )


def cases(n_seeds: int = 4):
    """``(name, run)`` for every scenario, noise, grade and seed; the rover's fixes state no sigmas."""
    for (scenario, duration, rate, noises), grade, seed in itertools.product(
        SCENARIOS, GRADES, range(n_seeds)
    ):
        for noise in noises:
            run = simulate(
                scenario,
                duration,
                imu_grade=grade,
                gnss_rate_hz=rate,
                noise=noise,
                seed=1000 + seed,
            )
            if noise == "filtered":
                run = run.with_gnss(replace(run.gnss, sigma_stated=False))
            yield f"{scenario}/{grade}/{noise}/{1000 + seed}", run
