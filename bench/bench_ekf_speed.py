"""EKF speed and memory on the KITTI default (and simulated long runs).

Prints, for `ekf`, `ekf-acc` and `ekf-accw`: median wall time over interleaved repeats of the
filter pass itself (from the start, noise and stationary spans that ``gnssacc.pipeline.prepare`` found
once, as the pipeline runs it), real-time factor (data duration / wall time, one core), the wall-time ratio to ``ekf``
(median over rounds of the per-round ratio), the identification time, the
one-off JIT compilation time (cold cache, measured in a fresh process) and peak traced memory
versus run length and number of outputs.

Usage::

    python bench/bench_ekf_speed.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc

import numpy as np

from gnssacc.core.config import load_config
from gnssacc.estimators import mechanization
from gnssacc.prepare.passes import run_ekf
from gnssacc.pipeline import load_source
from gnssacc.pipeline import prepare as identify
from gnssacc.sources.sim import grade_config, simulate


def cold_jit_seconds() -> float:
    """Compile time of the EKF's numba kernels (its groups: the propagation, the update and the
    aids' models) in a fresh process with an empty cache."""
    with tempfile.TemporaryDirectory() as cache:
        code = (
            "import time; from gnssacc.estimators import kernels; t = time.perf_counter(); "
            "kernels.compile_groups(kernels.EKF_GROUPS); print(time.perf_counter() - t)"
        )
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        # The package cache (if any) would hide the compile: point numba at an empty one.
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
        )
        return float(out.stdout.strip())


def peak_mib(fn) -> float:
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    print(f"one-off JIT compilation (cold cache, fresh process): {cold_jit_seconds():.2f} s")
    print(f"kernel load from the on-disk cache: {mechanization.warm_up():.3f} s")

    cfg = load_config("kitti")
    run = load_source("kitti", cfg, noise="white", seed=0)
    t0 = time.perf_counter()
    ident = identify(run, cfg)
    print(
        f"identification (quality, stationary spans, yaw bank, tuning, model check): "
        f"{time.perf_counter() - t0:.2f} s"
    )
    kw = dict(quality=ident.quality, init=ident.init, stationary=ident.stationary)
    print(
        f"\nKITTI: {run.duration_s:.1f} s of data, {len(run.imu)} IMU samples (covariance propagated at each), "
        f"{len(run.gnss)} fixes; median of {args.repeats} runs, one process"
    )
    methods = ("ekf", "ekf-acc", "ekf-accw")
    for method in methods:  # first call per method outside the timing (a lazily compiled kernel)
        run_ekf(ident.run, ident.cfg, method, **kw)
    walls = {m: [] for m in methods}
    for _ in range(args.repeats):  # interleaved: the machine's load hits every method alike
        for method in methods:
            t0 = time.perf_counter()
            run_ekf(ident.run, ident.cfg, method, **kw)
            walls[method].append(time.perf_counter() - t0)
    print(
        f"{'method':10s} {'wall [s]':>9s} {'min [s]':>8s} {'real-time factor':>17s} {'x ekf (median of ratios)':>25s}"
    )
    for method in methods:
        med = float(np.median(walls[method]))
        ratio = float(np.median(np.array(walls[method]) / np.array(walls["ekf"])))
        print(
            f"{method:10s} {med:9.3f} {min(walls[method]):8.3f} {run.duration_s / med:17.0f} {ratio:25.2f}"
        )

    print("\nMemory (peak traced by tracemalloc during run_ekf, inputs excluded):")
    sim_cfg = load_config(overrides={"imu": grade_config("industrial")})
    print(f"{'run length [s]':>15s} {'outputs':>8s} {'peak [MiB]':>11s}")
    peaks = {}
    for duration in (600.0, 6000.0):
        srun = simulate("car", duration_s=duration, imu_grade="industrial", seed=0)
        sid = identify(srun, sim_cfg, "none")
        skw = dict(quality=sid.quality, init=sid.init, stationary=sid.stationary)
        for n_out in (10, "1 Hz"):
            t_out = (
                srun.truth.t[:: max(len(srun.truth.t) // 10, 1)][:10]
                if n_out == 10
                else srun.truth.t
            )
            mib = peak_mib(lambda: run_ekf(srun, sim_cfg, "ekf-acc", output_times=t_out, **skw))  # noqa: B023 (called within the iteration)
            peaks[(duration, len(t_out))] = mib
            print(f"{duration:15.0f} {len(t_out):8d} {mib:11.2f}")
    (d0, n0), (d1, n1) = (600.0, 10), (6000.0, 10)
    print(f"10x longer run, same 10 outputs: {peaks[(d1, n1)] / peaks[(d0, n0)]:.2f}x peak memory")
    big = max(peaks, key=lambda k: k[1])
    per_row = (peaks[big] - peaks[(big[0], 10)]) * 2**20 / (big[1] - 10)
    print(f"cost per stored output epoch: {per_row:.0f} bytes")


if __name__ == "__main__":
    main()
