"""Hard traits of real recordings, simulated with truth, through ``gnssacc.process`` with defaults.

The cases of ``tests/test_hard_traits.py`` at full length, with their figures printed:

* ``ugv-slow``: a slow skid-steer UGV (consumer IMU) parked 36 s at the start and 75 s at the end,
  pivots on the spot, 1 Hz fixes with 3 m noise (two seeds);
* ``sideways``: a ROS 1 bag from a wheeled robot (30 Hz consumer IMU mounted +y up, 2.5 Hz fixes,
  10 Hz wheel odometry on ``/odom`` in a local frame, an orientation field whose yaw is 110 deg
  off, no ``/tf_static``): with ``--strict`` (``[checks] on_proof = "refuse"``: refused with the
  evidence), with the defaults (the mounting the estimator proves is applied and stated) and the
  same bag with its IMU mounted along the body, for comparison;
* ``rover``: a 0.4 m/s rover with 20 Hz receiver-filtered fixes that state no sigma (367 s).

Per case: refused or not, what the input checks applied, PRMSE of ``ekf`` and ``smoother``
against the truth and of the raw fixes, position NEES, the number of warnings, the smoother's
wall time and real-time factor, the whole call's wall time.

Usage::

    python bench/bench_hard_traits.py [--cases ugv-slow,sideways,rover]
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

import gnssacc
from gnssacc.core.errors import InputError
from gnssacc.sources.bagwrite import write_bag
from gnssacc.sources.sim import simulate

METHODS = ["ekf", "smoother"]


def _row(name: str, res, seconds: float) -> str:
    """One table row of a finished run."""
    m, cons = res.metrics["methods"], res.metrics["consistency"]
    applied = [f.check for f in res.prepared.checks if f.action == "applied"] or ["-"]
    n_warn = sum(len(cons[k]["warnings"]) for k in cons)
    sm = m["smoother"]
    return (
        f"{name:<26} {'no':>7}  {','.join(applied):<14} {m['ekf']['prmse_m']:>6.2f} {sm['prmse_m']:>9.2f} "
        f"{res.metrics['gnss_prmse_m']:>6.2f}  {m['ekf']['nees_pos'] or float('nan'):>5.1f} / "
        f"{sm['nees_pos'] or float('nan'):<5.1f} {n_warn:>5}  {sm['runtime_s']:>6.1f} s ({sm['realtime_factor']:>4.0f}x)"
        f"  {seconds:>5.0f} s"
    )


def ugv_slow(seed: int) -> str:
    t = time.perf_counter()
    res = gnssacc.process("sim:ugv-slow,imu=consumer,duration=235", methods=METHODS, seed=seed)
    return _row(f"ugv-slow seed {seed}", res, time.perf_counter() - t)


def _robot_bag(run, path: Path, mount) -> Path:
    return write_bag(
        run,
        path,
        "ros1-rooad",
        imu_mount_rpy_deg=mount,
        with_orientation=True,
        orientation_yaw_error_deg=110.0,
        orientation_sigma_deg=(1.0, 1.0, 2.0),
        odom_topic="/odom",
        write_tf=False,
    )


def write_sideways_bag(folder: Path, seed: int = 0):
    """The simulated run and the sideways-IMU bag written from it (``folder/sideways.bag``)."""
    run = simulate(
        "ugv",
        240.0,
        imu_grade="consumer",
        imu_rate_hz=30.0,
        gnss_rate_hz=2.5,
        noise="white",
        seed=seed,
        odom_hz=10.0,
    )
    return run, _robot_bag(run, folder / "sideways.bag", (90.0, 0.0, 90.0))


def sideways(folder: Path) -> list[str]:
    run, bag = write_sideways_bag(folder)
    rows = []
    t = time.perf_counter()
    try:
        gnssacc.process(str(bag), methods=METHODS, config={"checks": {"on_proof": "refuse"}})
        rows.append(f"{'sideways bag, --strict':<26} {'no':>7}  (ran without the mounting)")
    except InputError as exc:
        took = time.perf_counter() - t
        rows.append(
            f"{'sideways bag, --strict':<26} {'refused':>7}  {took:.0f} s: {str(exc)[-170:]}"
        )
    for name, path in (
        ("sideways bag, defaults", bag),
        ("same, mounted along body", _robot_bag(run, folder / "mounted.bag", (0.0, 0.0, 0.0))),
    ):
        loaded = gnssacc.load(str(path))
        assert loaded.truth is None, "the bag's /odom must not be taken as truth"
        t = time.perf_counter()
        res = gnssacc.process(replace(loaded, truth=run.truth), methods=METHODS)
        rows.append(_row(name, res, time.perf_counter() - t))
    return rows


def rover_run(seed: int = 0):
    """The slow rover: 20 Hz receiver-filtered fixes that state no sigma (367 s)."""
    run = simulate(
        "rover", 367.0, imu_grade="consumer", gnss_rate_hz=20.0, noise="filtered", seed=seed
    )
    return run.with_gnss(
        replace(
            run.gnss, sigma_ned=np.tile([3.0, 3.0, 5.0], (len(run.gnss), 1)), sigma_stated=False
        )
    )


def rover() -> str:
    run = rover_run()
    t = time.perf_counter()
    res = gnssacc.process(run, methods=METHODS)
    return _row("rover 20 Hz, no sigmas", res, time.perf_counter() - t)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cases", default="ugv-slow,sideways,rover")
    cases = p.parse_args(argv).cases.split(",")
    warnings.simplefilter("ignore")  # the table carries the count; the runs' own lines are long
    print(
        f"{'case':<26} {'refused':>7}  {'applied':<14} {'ekf':>6} {'smoother':>9} {'raw':>6}  NEES pos"
        f"     warn  smoother wall        whole"
    )
    if "ugv-slow" in cases:
        for seed in (3, 4):
            print(ugv_slow(seed), flush=True)
    if "sideways" in cases:
        with tempfile.TemporaryDirectory() as tmp:
            for row in sideways(Path(tmp)):
                print(row, flush=True)
    if "rover" in cases:
        print(rover(), flush=True)


if __name__ == "__main__":
    main()
