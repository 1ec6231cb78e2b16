"""The simulator's own peak memory and time versus run length (``gnssacc.sources.sim.simulate``).

Each run is a fresh process: the imports and a 10 s warm-up run, then one simulated run (a car by
default, industrial IMU at 100 Hz, GNSS at 1 Hz, every error source on). Prints the medians over the
repeats (run lengths interleaved) of the wall time, of the peak resident memory above the
process before the run (``VmHWM`` minus ``VmRSS``, reset with ``/proc/self/clear_refs``) and of
what the run holds (its arrays), and that peak per IMU sample.

Usage::

    python bench/bench_sim_memory.py [--repeats 3] [--durations 600,6000,36000] [--grade industrial]
                                     [--scenario car]

Thirty minutes of a city car with a consumer IMU (the simulator's speed figure formerly asserted
in the tests, under 6 s): ``--durations 1800 --grade consumer --scenario car-city``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

CHILD = r"""
import json, sys, time
import numpy as np
from gnssacc.sources.sim import simulate
status = lambda key: int(next(l for l in open("/proc/self/status") if l.startswith(key)).split()[1]) / 1024
simulate(sys.argv[3], 10.0, imu_grade=sys.argv[2])
base = status("VmRSS:")
open("/proc/self/clear_refs", "w").write("5")   # VmHWM := VmRSS
t0 = time.perf_counter()
run = simulate(sys.argv[3], float(sys.argv[1]), imu_grade=sys.argv[2], seed=0)
wall = time.perf_counter() - t0
peak, after = status("VmHWM:") - base, status("VmRSS:") - base
# The true biases are not held per sample (run.sim.bias draws them again when asked): its own arrays.
arrays = [run.imu.t, run.imu.f_b, run.imu.omega_ib_b,
          *vars(run.gnss).values(), *[v for v in vars(run.truth).values() if hasattr(v, "nbytes")]]
held = (sum(a.nbytes for a in arrays) + run.sim.bias.nbytes) / 2**20
print(json.dumps({"wall_s": wall, "peak_mib": peak, "after_mib": after, "held_mib": held, "n": len(run.imu)}))
"""


def one(duration: float, grade: str, scenario: str = "car") -> dict:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(duration), grade, scenario],
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    if out.returncode:
        raise SystemExit(f"{duration} s run failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--durations", default="600,6000")
    ap.add_argument("--grade", default="industrial")
    ap.add_argument("--scenario", default="car")
    args = ap.parse_args()
    durations = [float(d) for d in args.durations.split(",")]
    res: dict[float, list] = {d: [] for d in durations}
    for _ in range(args.repeats):  # interleaved
        for d in durations:
            res[d].append(one(d, args.grade, args.scenario))
    load = os.getloadavg()
    print(
        f"simulate({args.scenario!r}, D, imu_grade={args.grade!r}), 100 Hz IMU, 1 Hz GNSS, fresh process per run; median of "
        f"{args.repeats}; load average {load[0]:.1f} {load[1]:.1f} on {os.cpu_count()} cores"
    )
    print(
        f"{'run [s]':>8s} {'wall [s]':>9s} {'peak above start [MiB]':>23s} {'held after [MiB]':>17s} "
        f"{'run arrays [MiB]':>17s} {'peak [B/sample]':>16s}"
    )
    for d, rows in res.items():
        m = {
            k: float(np.median([r[k] for r in rows]))
            for k in ("wall_s", "peak_mib", "after_mib", "held_mib")
        }
        print(
            f"{d:8.0f} {m['wall_s']:9.2f} {m['peak_mib']:23.0f} {m['after_mib']:17.0f} {m['held_mib']:17.1f} "
            f"{m['peak_mib'] * 2**20 / rows[0]['n']:16.0f}"
        )


if __name__ == "__main__":
    main()
