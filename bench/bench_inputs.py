"""Speed and memory of reading and checking inputs: a 100k-row CSV table, the IMU check on
KITTI, a 300 s simulation, and the peak memory of loading CSV runs of 600 and 6000 s.

Prints medians of ``--repeats`` runs (time) and, per run length, the peak resident memory of a
fresh process that only loads the run (``VmHWM`` after the imports and after loading).

Usage::

    python bench/bench_inputs.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gnssacc.checks.quality import check_imu
from gnssacc.core.config import load_config
from gnssacc.pipeline import load_source
from gnssacc.sources.common import read_table
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate

CHILD = r"""
import json, sys
# VmHWM (peak resident set of this process image; ru_maxrss would carry the parent's from the fork)
rss = lambda: int(next(l for l in open("/proc/self/status") if l.startswith("VmHWM")).split()[1]) / 1024
from gnssacc.api import load
base = rss()
run = load(sys.argv[1])
print(json.dumps({"base_mib": base, "peak_mib": rss(), "arrays_mib": (run.imu.t.nbytes + run.imu.f_b.nbytes
                  + run.imu.omega_ib_b.nbytes) / 2**20}))
"""


def timed(fn, repeats: int) -> float:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return statistics.median(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        n = 100_000
        table = np.column_stack(
            [np.arange(n) * 0.01, np.random.default_rng(3).standard_normal((n, 6))]
        )
        p = Path(tmp) / "imu.csv"
        np.savetxt(p, table, fmt="%.10g", delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
        cols = ["t", "ax", "ay", "az", "gx", "gy", "gz"]
        print(
            f"read_table, {n} rows x 7: {1e3 * timed(lambda: read_table(p, cols), args.repeats):.0f} ms"
        )
        cfg = load_config("kitti")
        imu = load_source("kitti", cfg).imu
        print(
            f"check_imu, KITTI ({len(imu)} samples): {1e3 * timed(lambda: check_imu(imu, cfg), args.repeats):.1f} ms"
        )
        print(
            f"simulate car 300 s at 100 Hz: {timed(lambda: simulate('car', 300.0), args.repeats):.2f} s"
        )
        for d in (600.0, 6000.0):
            folder = write_csv_run(
                simulate("car", d, imu_grade="industrial", seed=0), Path(tmp) / f"car{d:.0f}"
            )
            r = json.loads(
                subprocess.run(
                    [sys.executable, "-c", CHILD, str(folder)],
                    capture_output=True,
                    text=True,
                    check=True,
                )
                .stdout.strip()
                .splitlines()[-1]
            )
            print(
                f"load CSV run of {d:.0f} s: peak {r['peak_mib']:.0f} MiB, {r['peak_mib'] - r['base_mib']:.0f} MiB "
                f"above the imports; the IMU arrays kept: {r['arrays_mib']:.0f} MiB"
            )


if __name__ == "__main__":
    main()
