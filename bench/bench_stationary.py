"""The stationary detector against the simulator's truth, with and without GNSS outages.

A span kept while the vehicle moves drives zero-velocity updates into a moving vehicle (the
worst error the detector can make); a true stop refused only costs information. Over a grid of
simulated runs (ugv, ugv-slow, car, car-city; consumer and industrial IMUs; white and
Gauss-Markov fixes; with and without 20 s outages every 60 s; seeds), the bench counts the spans
kept while moving (number, seconds, worst true speed), the true stops kept, and the true stops
refused and by which step. A span counts as moving when the true horizontal speed exceeds
0.05 m/s anywhere in it.

The simulator's receiver also gives Doppler velocities (0.05 m/s), which the detector uses as
the pipeline does; ``--no-velocity`` withholds them.

``--lever-arm`` puts the antenna off the IMU (told to the detector unless ``--untold``);
``--noises rtk,precise`` gives the precise fixes that see its swing in a pivot.

    python bench/bench_stationary.py [--seeds 2] [--quick] [--no-velocity] [--scenarios LIST]
        [--grades LIST] [--noises LIST] [--outages LIST] [--lever-arm X:Y:Z [--untold]]
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections import Counter

import numpy as np

import gnssacc
from gnssacc.prepare.stationary import detect_stationary

MOVING_MPS = 0.05


def score(run, velocity=None, lever_arm_b=None) -> dict:
    """Counts for one run: ``false``/``false_s``/``false_speed`` (kept while moving), ``true``/
    ``true_s`` (kept at rest), ``refused`` (a Counter of the reasons of true stops refused);
    ``velocity``: the receiver's velocities given to the detector (None: fixes only);
    ``lever_arm_b``: the antenna's lever arm told to the detector [m, body FRD]."""
    t0 = time.perf_counter()
    report = detect_stationary(
        run.imu, run.gnss, run.origin, lever_arm_b=lever_arm_b, velocity=velocity
    )
    seconds = time.perf_counter() - t0
    tt, speed = run.truth.t, np.linalg.norm(run.truth.v_n[:, :2], axis=1)

    def top(a: float, b: float) -> float:
        inside = (tt >= a) & (tt <= b)
        return float(speed[inside].max()) if inside.any() else 0.0

    out = dict(false=0, false_s=0.0, false_speed=0.0, true=0, true_s=0.0, seconds=seconds)
    for s in report.spans:
        v = top(s.t_start, s.t_end)
        if v > MOVING_MPS:
            out["false"] += 1
            out["false_s"] += s.duration_s
            out["false_speed"] = max(out["false_speed"], v)
        else:
            out["true"] += 1
            out["true_s"] += s.duration_s
    out["refused"] = Counter(
        r["why"] for r in report.rejected if top(r["t_start"], r["t_end"]) <= MOVING_MPS
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="ugv and car only, one seed")
    ap.add_argument(
        "--no-velocity", action="store_true", help="fixes only (as for a receiver without them)"
    )
    ap.add_argument("--scenarios", default="ugv,ugv-slow,car,car-city")
    ap.add_argument("--grades", default="consumer,industrial")
    ap.add_argument("--noises", default="white,gm", help="the simulator's fix-noise profiles")
    ap.add_argument("--outages", default="none,60:20", help="'none' or PERIOD:LEN, each a row")
    ap.add_argument("--lever-arm", default="0:0:0", help="the antenna from the IMU, X:Y:Z [m]")
    ap.add_argument("--untold", action="store_true", help="do not tell the detector the lever arm")
    a = ap.parse_args()
    lever = [float(x) for x in a.lever_arm.split(":")]
    scenarios = ("ugv", "car") if a.quick else tuple(a.scenarios.split(","))
    seeds = range(1 if a.quick else a.seeds)
    outages = [None if o == "none" else o for o in a.outages.split(",")]
    grid = itertools.product(scenarios, a.grades.split(","), a.noises.split(","), outages, seeds)
    rows: dict = {}
    times = []
    for sc, grade, noise, outage, seed in grid:
        spec = f"sim:{sc},imu={grade},duration=300,lever_arm={a.lever_arm}"
        run = gnssacc.load(spec, seed=seed, noise=noise, outage_every=outage)
        r = score(run, None if a.no_velocity else run.gnss_vel, None if a.untold else lever)
        times.append(r.pop("seconds"))
        key = (sc, "outages" if outage else "no outage")
        acc = rows.setdefault(
            key,
            dict(
                false=0, false_s=0.0, false_speed=0.0, true=0, true_s=0.0, refused=Counter(), runs=0
            ),
        )
        for k in ("false", "false_s", "true", "true_s"):
            acc[k] += r[k]
        acc["false_speed"] = max(acc["false_speed"], r["false_speed"])
        acc["refused"] += r["refused"]
        acc["runs"] += 1
    print(
        f"{'scenario':<10} {'GNSS':<10} {'runs':>4}  {'kept moving':>11} {'[s]':>6} "
        f"{'max v':>6}  {'stops kept':>10} {'[s]':>7}  stops refused (reason: n)"
    )
    total = Counter()
    for (sc, out), acc in rows.items():
        why = ", ".join(f"{k}: {n}" for k, n in acc["refused"].items()) or "-"
        print(
            f"{sc:<10} {out:<10} {acc['runs']:>4}  {acc['false']:>11} {acc['false_s']:>6.1f} "
            f"{acc['false_speed']:>6.2f}  {acc['true']:>10} {acc['true_s']:>7.1f}  {why}"
        )
        for k in ("false", "false_s", "true", "true_s"):
            total[k] += acc[k]
    print(
        f"{'all':<21} {sum(a['runs'] for a in rows.values()):>4}  {total['false']:>11} "
        f"{total['false_s']:>6.1f} {'':>6}  {total['true']:>10} {total['true_s']:>7.1f}"
    )
    print(
        f"detector time per 300 s run: median {np.median(times):.3f} s "
        f"(max {np.max(times):.3f} s) over {len(times)} runs"
    )


if __name__ == "__main__":
    main()
