"""Where the memory goes inside ``pipeline.compare`` after the run is loaded (one process, one run).

Simulates a car run (industrial IMU 100 Hz, GNSS 1 Hz; or reads a CSV run directory with
``--csv DIR``), then runs ``compare`` with the four methods, each stage wrapped from outside:
the preparation's stages (input checks and their verdicts, the start's pieces, the start found
again under the turn allowance, tuning on windows or whole, the model-check EKF pass) and each
method. Per stage it prints the wall time, the peak resident
memory above the resident memory when the stage started (``VmHWM`` reset with
``/proc/self/clear_refs``) and the resident memory after it, both relative to the process after
loading the run. Stages nest (a stage inside ``prepare`` is also inside it); a single run, so
the times are indicative only.

Usage::

    python bench/bench_compare_memory.py [--duration 6000] [--csv DIR]
"""

from __future__ import annotations

import argparse
import functools
import os
import time

import gnssacc.estimators.smoother  # noqa: F401  (gtsam: part of the fixed cost, before the baseline)
from gnssacc import pipeline
from gnssacc.core.config import load_config
from gnssacc.estimators import kernels as jit
from gnssacc.prepare import preparation as prepared_module
from gnssacc.sources.sim import simulate


def _status(key: str) -> float:
    with open("/proc/self/status") as f:
        return int(next(line for line in f if line.startswith(key)).split()[1]) / 1024


ROWS: list[list] = []
OPEN: list[list] = []  # the stages running, outermost first
PEAK = [0.0]  # the highest resident memory seen at the end of any stage [MiB]


def _watch(name: str, fn):
    """``fn`` wrapped: records [name, depth, wall, peak above its start, RSS after] per call.

    A stage resets the peak counter, so each stage passes its own absolute peak to the stage
    around it."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        row = [name, len(OPEN), 0.0, 0.0, 0.0, _status("VmRSS:"), 0.0]  # ..., start, inner peak
        ROWS.append(row)
        OPEN.append(row)
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            OPEN.pop()
            peak = max(_status("VmHWM:"), row[6])
            row[2], row[3], row[4] = time.perf_counter() - t, peak - row[5], _status("VmRSS:")
            PEAK[0] = max(PEAK[0], peak)
            if OPEN:
                OPEN[-1][6] = max(OPEN[-1][6], peak)

    return wrapped


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=6000.0)
    ap.add_argument("--csv", default=None, help="a CSV run directory to load instead of simulating")
    args = ap.parse_args()
    jit.warm_up()
    cfg = load_config("industrial")
    if args.csv:
        from gnssacc.api import load

        run = load(args.csv, config=cfg)
    else:
        run = simulate("car", duration_s=args.duration, imu_grade="industrial", seed=0)
    base = _status("VmRSS:")
    print(
        f"run: {len(run.imu)} IMU samples; RSS after loading it {base:.0f} MiB (peak so far {_status('VmHWM:'):.0f}); "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )
    # The preparation's stages, by the names its module calls them: the input checks and their
    # verdicts, the start (IMU quality, stationary spans, start, yaw bank), the tuning.
    for name in ("settled", "start_pieces", "start_of", "tuned_on_windows", "tune"):
        setattr(prepared_module, name, _watch(f"prepare.{name}", getattr(prepared_module, name)))
    pipeline.prepare_recording = _watch("prepare", pipeline.prepare_recording)
    pipeline.check_model = _watch("model check", pipeline.check_model)
    for m in list(pipeline.METHODS):
        pipeline.METHODS[m] = _watch(f"method {m}", pipeline.METHODS[m])
    for name in ("score", "assess", "gnss_score"):
        setattr(pipeline, name, _watch(name, getattr(pipeline, name)))
    t = time.perf_counter()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    methods = ["ekf", "ekf-acc", "smoother", "smoother-acc"]
    _metrics, sols, _ident = pipeline.compare(run, cfg, methods)
    total, peak = time.perf_counter() - t, max(PEAK[0], _status("VmHWM:"))
    print(
        f"{'stage':34s} {'wall [s]':>9s} {'peak above its start [MiB]':>27s} {'RSS after, above loaded [MiB]':>30s}"
    )
    for name, depth, wall, rise, after, _, _ in ROWS:
        if wall > 0.05 or rise > 2.0:
            print(f"{'  ' * depth + name:34s} {wall:9.2f} {rise:27.0f} {after - base:30.0f}")
    stored = (
        sum(a.nbytes for s in sols.values() for a in vars(s).values() if hasattr(a, "nbytes"))
        / 2**20
    )
    print(
        f"compare: {total:.1f} s, peak RSS {peak:.0f} MiB ({peak - base:.0f} above the loaded run); "
        f"solutions' arrays {stored:.1f} MiB"
    )


if __name__ == "__main__":
    main()
