"""Choose the KITTI preset's IMU noise from innovation statistics alone (never from truth).

Criterion: the EKF's normalised innovation squared per degree of freedom (NIS/3) of the GNSS
position updates should be ~1, both
  * over all updates (overall consistency), and
  * at the first fix after a GNSS gap (``--outage-every 45:15``), where the innovation
    includes 15 s of free-inertial drift, so it tests the IMU noise model directly.
The score of a candidate is ``mean over seeds of ln(NIS_all)^2 + ln(NIS_gap)^2``; the
candidate with the smallest score wins. Truth is not read anywhere in this script.

Usage::

    python bench/tune_kitti_nis.py [--seeds 0-2] [--jobs 2]

Prints the ranked candidates; the winner's values go into ``src/gnssacc/presets/kitti.toml``.
"""

from __future__ import annotations

import argparse
import itertools
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

GRID = {
    "gyro_arw_xy": [0.3, 1.0, 3.0, 10.0],  # deg/sqrt(h), roll/pitch-rate channels
    "gyro_arw_z": [0.1, 0.3, 1.0, 3.0],  # deg/sqrt(h), yaw-rate channel
    "accel_vrw": [0.03, 0.1, 0.3],  # m/s/sqrt(h)
    "gyro_bi": [3.0, 10.0, 30.0],  # deg/h
    "accel_bi": [0.1, 0.5, 2.0],  # mg
}
#: GNSS gaps used for the predictive test: 15 s without fixes every 45 s, long enough for the
#: free-inertial drift to be comparable to the GNSS noise.
GAPS = "45:15"


def _overrides(c):
    return {
        "imu": {
            "gyro_arw_deg_rth": [c["gyro_arw_xy"], c["gyro_arw_xy"], c["gyro_arw_z"]],
            "accel_vrw_mps_rth": c["accel_vrw"],
            "gyro_bias_instability_deg_h": c["gyro_bi"],
            "accel_bias_instability_mg": c["accel_bi"],
        }
    }


def _evaluate(args):
    cand, seeds = args
    from gnssacc.core.config import load_config
    from gnssacc.prepare.passes import run_ekf
    from gnssacc.pipeline import load_source, with_outages

    cfg = load_config(overrides=_overrides(cand))
    nis_all, nis_gap = [], []
    for seed in seeds:
        run = with_outages(load_source("kitti", cfg, noise="white", seed=seed), None, GAPS)
        sol = run_ekf(run, cfg, "ekf", record_innovations=True)
        t, nis = sol.stats["nis_pos_t"], sol.stats["nis_pos"]
        after_gap = np.r_[False, np.diff(t) > 10.0]
        nis_all.append(nis.mean())
        nis_gap.append(nis[after_gap].mean())
    a, g = float(np.mean(nis_all)), float(np.mean(nis_gap))
    return cand, a, g, np.log(a) ** 2 + np.log(g) ** 2


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split("-"))
    seeds = list(range(lo, hi + 1))
    cands = [dict(zip(GRID, v)) for v in itertools.product(*GRID.values())]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as ex:
        results = list(ex.map(_evaluate, [(c, seeds) for c in cands]))
    results.sort(key=lambda r: r[3])
    print(f"{len(cands)} candidates x {len(seeds)} seeds in {time.perf_counter() - t0:.0f} s")
    print(
        "gyro_xy gyro_z [deg/rt h]  accel_vrw [m/s/rt h]  gyro_bi [deg/h]  accel_bi [mg]  NIS_all  NIS_gap  score"
    )
    for c, a, g, s in results[:15]:
        print(
            f"{c['gyro_arw_xy']:7.1f} {c['gyro_arw_z']:6.1f}  {c['accel_vrw']:20.2f}  {c['gyro_bi']:15.0f}  "
            f"{c['accel_bi']:13.1f}  {a:7.3f}  {g:7.3f}  {s:.4f}"
        )


if __name__ == "__main__":
    main()
