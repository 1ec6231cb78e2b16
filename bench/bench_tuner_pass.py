"""One likelihood pass of the preparation, the unit its cost is made of (issue 35).

The input checks, the start's yaw bank and the noise tuner run some 90-120 EKF passes over a
recording (the tuner's with the covariance every ``[tune] cov_every`` samples, no outputs). This
prints the CPU time of one such pass (min and median of ``--repeats``), the events of the pass
by kind, and the same pass in the EKF's Python loop (``ekf.COMPILED_LOOP = False``, the
reference the compiled event loop stands in for), interleaved in the same process, with their
ratio, for recordings of three kinds:

* ``kitti``: fixes and the non-holonomic constraint (471 s, 100 Hz IMU);
* ``car-city``: a simulated consumer car with Doppler velocities and six stops (300 s);
* ``ugv-odometry``: a simulated consumer UGV with 10 Hz wheel odometry, velocities and stops
  (300 s).

Each is prepared once (tuned, as ``gnssacc run`` does), then its tuned configuration's pass is
timed.

    python bench/bench_tuner_pass.py [--repeats 15] [--only NAME]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

os.environ.setdefault("GNSSACC_CACHE_DIR", "none")

from gnssacc import pipeline  # noqa: E402
from gnssacc.estimators import ekf  # noqa: E402

CASES = {
    "kitti": "kitti",
    "car-city": "sim:car-city,imu=consumer,duration=300",
    "ugv-odometry": "sim:ugv,imu=consumer,duration=300,odom_hz=10",
}
KINDS = ("pos", "vel", "nhc", "zupt", "odo")


def prepared(source: str):
    """The recording as ``gnssacc run`` prepares it (checks, start, tuned noise)."""
    cfg = pipeline.configure(source)
    run = pipeline.load_configured(source, cfg, None, 0, None, None, "frd", None, {})
    return pipeline.prepare(run, cfg, methods=["ekf"])


def one_pass(prep):
    """A tuner's pass: the tuned noise, the covariance every ``[tune] cov_every`` samples, no
    outputs; its CPU seconds and its statistics."""
    t0 = time.process_time()
    every = int(prep.cfg["tune"]["cov_every"])
    sol = ekf.estimate(prep, prep.cfg, "ekf", output_times=np.empty(0), cov_every=every)
    return time.process_time() - t0, sol.stats


def timed(prep, repeats: int) -> dict:
    """``repeats`` passes each way, interleaved: CPU seconds per loop, and the pass's counts."""
    out: dict = {True: [], False: []}
    stats: dict = {}
    for _ in range(repeats):
        for compiled in (True, False):
            ekf.COMPILED_LOOP = compiled
            s, stats = one_pass(prep)
            out[compiled].append(s)
    ekf.COMPILED_LOOP = None
    return {"compiled": out[True], "python": out[False], "stats": stats}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--only", default=None, help="one case: " + ", ".join(CASES))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    for name, source in CASES.items():
        if args.only and args.only != name:
            continue
        prep = prepared(source)
        one_pass(prep)  # the kernels loaded, both ways
        ekf.COMPILED_LOOP = False
        one_pass(prep)
        r = timed(prep, args.repeats)
        st = r["stats"]
        events = ", ".join(
            f"{k} {st.get(f'n_{k}_updates', 0)}" for k in KINDS if st.get(f"n_{k}_updates")
        )
        rows.append((name, prep.run.t_end - prep.run.t_start, r, events))
    print(
        f"\none tuner pass, CPU ms (min / median of {args.repeats}, the two loops interleaved; "
        f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )
    head = f"{'recording':14s} {'[s]':>5s} {'compiled':>15s} {'python loop':>15s}"
    print(f"{head} {'ratio':>6s}  updates")
    for name, dur, r, events in rows:
        c, p = np.array(r["compiled"]) * 1e3, np.array(r["python"]) * 1e3
        print(
            f"{name:14s} {dur:5.0f} {c.min():6.1f} / {np.median(c):6.1f} "
            f"{p.min():6.1f} / {np.median(p):6.1f} {np.median(c) / np.median(p):6.2f}  {events}"
        )


if __name__ == "__main__":
    main()
