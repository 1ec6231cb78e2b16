"""Time and peak memory versus run length: simulated car runs of 600 s, 6000 s (and 36000 s).

Each run is a fresh process: simulate (industrial IMU at 100 Hz, GNSS at 1 Hz), then the
pipeline's ``compare`` with all four methods (noise tuning on, outputs at every GNSS epoch).
With ``--csv`` the runs are first written as CSV run directories (by this process) and each
child process reads one with ``gnssacc.load`` instead of simulating: a user's recording, from
the file to the scores, without the simulator's own memory.
Prints the median over the repeats of the wall time of each stage, the peak resident memory
(``VmHWM``) after the imports and at the end, and the ratio to the shortest run. The stored
outputs (the solutions' arrays) are reported too: the goal is a peak that grows by no more than
them beyond 1.3x the 600 s run's.

Usage::

    python bench/bench_scaling.py [--repeats 3] [--long] [--csv]   # --long adds the 10-hour run (36000 s)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

CHILD = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from gnssacc.estimators import kernels as jit
from gnssacc.core.config import load_config
from gnssacc.pipeline import compare
from gnssacc.sources.sim import grade_config, simulate
import gnssacc.estimators.smoother  # gtsam: part of the fixed cost
jit.warm_up()
# VmHWM: the peak resident set of this process image (ru_maxrss would carry the parent's from the fork)
rss = lambda: int(next(l for l in open("/proc/self/status") if l.startswith("VmHWM")).split()[1]) / 1024
base = rss()
t1 = time.perf_counter()
if len(sys.argv) > 2:   # a CSV run directory written by the parent
    from gnssacc.api import load
    run = load(sys.argv[2], config=load_config("industrial"))
else:
    run = simulate("car", duration_s=float(sys.argv[1]), imu_grade="industrial", seed=0)
sim_peak = rss()
t2 = time.perf_counter()
cfg = load_config("industrial")
metrics, sols, ident = compare(run, cfg, ["ekf", "ekf-acc", "smoother", "smoother-acc"])
t3 = time.perf_counter()
stored = sum(a.nbytes for s in sols.values() for a in vars(s).values() if hasattr(a, "nbytes"))
print(json.dumps({"imports_s": t1 - t0, "simulate_s": t2 - t1, "compare_s": t3 - t2, "base_mib": base,
                  "sim_peak_mib": sim_peak, "peak_mib": rss(), "stored_mib": stored / 2**20,
                  "prmse": {m: metrics["methods"][m].get("prmse_m") for m in metrics["methods"]}}))
"""


def one(duration: float, csv_dir: str | None = None) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(duration)] + ([csv_dir] if csv_dir else []),
        capture_output=True,
        text=True,
        env=env,
    )
    if out.returncode:
        raise SystemExit(f"{duration} s run failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _write_csv(duration: float, tmp: str) -> str:
    from gnssacc.sources.csvdir import write_csv_run
    from gnssacc.sources.sim import simulate

    path = os.path.join(tmp, f"car{duration:.0f}")
    write_csv_run(simulate("car", duration_s=duration, imu_grade="industrial", seed=0), path)
    return path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--long", action="store_true", help="also the 10-hour run (36000 s), once")
    ap.add_argument(
        "--csv",
        action="store_true",
        help="read the runs from CSV run directories instead of simulating",
    )
    args = ap.parse_args()
    durations = [600.0, 6000.0] + ([36000.0] if args.long else [])
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {d: _write_csv(d, tmp) if args.csv else None for d in durations}
        res: dict[float, list] = {d: [] for d in durations}
        for _ in range(args.repeats):  # interleaved
            for d in durations[:2]:
                res[d].append(one(d, dirs[d]))
        if args.long:
            res[36000.0] = [one(36000.0, dirs[36000.0])]
    load = os.getloadavg()
    what = "CSV run directories of simulated car runs" if args.csv else "simulated car"
    print(
        f"{what}, industrial IMU 100 Hz, GNSS 1 Hz, all four methods, fresh process per run; median of "
        f"{args.repeats} (36000 s: 1); load average {load[0]:.1f} {load[1]:.1f} on {os.cpu_count()} cores"
    )
    keys = ("simulate_s", "compare_s", "base_mib", "sim_peak_mib", "peak_mib", "stored_mib")
    print(
        f"{'run [s]':>8s} {'load/sim [s]':>13s} {'compare [s]':>12s} {'after imports [MiB]':>20s} "
        f"{'after load [MiB]':>16s} {'peak [MiB]':>11s} {'stored outputs [MiB]':>21s} {'peak ratio':>11s}"
    )
    med = {d: {k: float(np.median([r[k] for r in v])) for k in keys} for d, v in res.items()}
    for d, m in med.items():
        print(
            f"{d:8.0f} {m['simulate_s']:13.2f} {m['compare_s']:12.2f} {m['base_mib']:20.0f} {m['sim_peak_mib']:16.0f} "
            f"{m['peak_mib']:11.0f} {m['stored_mib']:21.1f} {m['peak_mib'] / med[600.0]['peak_mib']:11.2f}"
        )
    for d, m in med.items():
        if d > 600.0:
            goal = 1.3 * med[600.0]["peak_mib"] + m["stored_mib"] - med[600.0]["stored_mib"]
            print(
                f"{d:.0f} s: peak {m['peak_mib']:.0f} MiB vs goal {goal:.0f} MiB (1.3 x 600 s peak + extra outputs)"
            )
    print("PRMSE [m]:", {d: res[d][0]["prmse"] for d in res})


if __name__ == "__main__":
    main()
